"""The closed loop on the small wake instance (truth: M0 + wake on tail), end to end through the CLI.

Split from test_close_loop.py (same instances, same helpers) so that `pytest -n 2 --dist loadfile` can run
these two long loops on one worker while the other runs the attribution tests.
"""
import json
from pathlib import Path

import pytest

from pyomo_heli.cli import main
from pyomo_heli.dataset import load_flight_test
from pyomo_heli.nlp.identification import prepare_data
from pyomo_heli.studies.small_instances import WAKE_MANEUVERS, make_case
from test_close_loop import _pooled_trim

ROOT = Path(__file__).resolve().parents[1]


def _truth_replay_errors(cfg, doc):
    """Validation RMS of each iteration's model minus the truth replay, and the truth model's own RMS."""
    from pyomo_heli.report.loop import truth_replay_errors

    val = list(prepare_data(load_flight_test(cfg.dataset), cfg.validation,
                            input_reference_s=cfg.input_reference_s).maneuvers)
    return truth_replay_errors(cfg, doc, val)


def test_wake_on_tail_is_picked_first_and_the_errors_fall(tmp_path, capsys, request, flight_test_cache):
    """The acceptance of issue 5 on a small instance of the synthetic flight test (truth: M0 + wake on tail)."""
    cfg = make_case(tmp_path, "[truth.effects.wake_on_tail]\nK_lamT = 1.5\nd_t = 1.8\ns_w = 0.5\n", seed=25,
                    loop="\n[loop]\nmax_iterations = 1\n", maneuvers=WAKE_MANEUVERS, input_reference_s=1.9,
                    data_cache=flight_test_cache)
    assert main(["close-loop", str(cfg.path), "--out", str(tmp_path / "loop")]) == 0
    doc = json.loads((tmp_path / "loop" / "loop.json").read_text())
    it0, it1 = doc["iterations"][0], doc["iterations"][-1]
    import contextlib

    # under `pytest -s`, show what docs/close_loop.md quotes ("What the tests show"); capsys holds it otherwise
    shown = capsys.disabled() if request.config.getoption("capture") == "no" else contextlib.nullcontext()
    with shown:
        print("\n" + it0["attribution"]["message"] + "\n" + it1["attribution"]["message"])
        print("shape:", it1["shape_selection"]["decision"], it1["shape_parameters"])
        print(json.dumps({k: (it0[k], it1[k]) for k in ("trim_rms", "validation_rms", "parameters")}, indent=1))
    # the wake is picked first, and after it nothing else is significant (no false positive on the second round)
    assert it0["attribution"]["decision"] == "accepted"
    assert it0["attribution"]["accepted"] == "rotor_wake_on_tail"
    assert it1["extensions"] == ["rotor_wake_on_tail"] and it1["parameters"]["k_wt"] > 0
    assert it1["attribution"]["decision"] == "none"
    # the new model dominates the old one at the diagnosed (Eq. 11) point: both objectives fall
    assert it1["J_time"] < it0["J_time"] and it1["J_trim"] < it0["J_trim"]
    # the RMS trim error (col, lon, theta pooled) falls by at least 50 %
    assert _pooled_trim(it1["trim_rms"]) <= 0.5 * _pooled_trim(it0["trim_rms"])
    # the validation error does not rise on any output: the model's error against the truth replayed the same way
    # (the sensor noise removed) falls on every output, q, theta, n_x, n_z, TAS and beta_0
    model_err, _ = _truth_replay_errors(cfg, doc)
    print("validation RMS of model minus truth replay:", model_err)
    for o, e0 in model_err[0].items():
        assert model_err[-1][o] < e0, o
    # with the data minus model (no truth needed): no output's validation error rises significantly (paired test)
    from pyomo_heli.report.loop import JOINT, iteration_model, validation_change_table
    from pyomo_heli.report.identification import predict

    val = list(prepare_data(load_flight_test(cfg.dataset), cfg.validation,
                            input_reference_s=cfg.input_reference_s).maneuvers)
    p0, p1 = (predict(str(k), iteration_model(cfg.model, it), it["parameters"], [], val)
              for k, it in enumerate((it0, it1)))
    change = validation_change_table(p0, p1, val)
    print(change.to_string())
    assert len(change) == 7 and change["output"].iloc[-1] == JOINT and not change["significant rise"].any()
    # the held-out study's column of the same joint test (kept model against iteration 0)
    from test_held_out_effects import _study

    assert _study().validation_joint_p(doc, cfg.path) == pytest.approx(float(change["p (rise)"].iloc[-1]), rel=1e-12)
    # the shape rule fitted the profile order at anchor A (the wake's edge is not E1's) and held it for the front
    assert it1["shape_selection"]["decision"].startswith("fitted") and it1["shape_selection"]["p"] < 0.01
    assert it1["shape_parameters"]["n_wt"] == it1["shape_selection"]["values"]["n_wt"] != 6.0
    assert "n_wt" not in it1["parameters"]
    # the errors of twist, tail lift slope and Iyy against truth fall at the diagnosed point, all within 5 %
    truth = json.loads((cfg.dataset / "truth.json").read_text())["parameters"]
    for n in ("theta_twist", "CL_alpha_HT", "Iyy"):
        assert abs(it1["parameters"][n] - truth[n]) < abs(it0["parameters"][n] - truth[n]), n
        assert it1["parameters"][n] == pytest.approx(truth[n], rel=0.05), n
    report = (tmp_path / "loop" / "loop_report.md").read_text()
    assert "## Error before and after" in report and "## Parameters vs truth" in report
    assert "minus the truth simulator replayed the same way" in report
    # the kept model's trims are as close to the data as the truth model's (the trim noise floor the report shows)
    from pyomo_heli.report.identification import truth_model_errors

    floor = truth_model_errors(cfg.dataset)["trim_rms"]["all"]
    print("trim RMS floor:", floor, "kept:", it1["trim_rms"])
    assert _pooled_trim(it1["trim_rms"]) <= 1.2 * _pooled_trim(floor)
    assert "Trim RMS of the truth model at the truth parameters" in report
    assert "Diebold-Mariano" in report and "Shape of rotor_wake_on_tail" in report
    assert (tmp_path / "loop" / "loop_trim_vs_speed.png").is_file()
    assert (tmp_path / "loop" / "loop_validation.png").is_file()
    # a rerun on the same folder reuses both finished identifications and the shape decision, same numbers; with
    # --figure-format none it writes the report's text and tables and no figure
    first = (tmp_path / "loop" / "loop_report.md").read_text()
    figures = sorted(f.name for f in (tmp_path / "loop").glob("loop_*.png"))
    assert "loop_trim_forces.png" in figures
    for f in figures:
        (tmp_path / "loop" / f).unlink()
    capsys.readouterr()
    assert main(["close-loop", str(cfg.path), "--out", str(tmp_path / "loop"), "--figure-format", "none"]) == 0
    out = capsys.readouterr().out
    assert out.count("reusing the finished identification") == 2 and "shape of rotor_wake_on_tail: reusing" in out
    again = json.loads((tmp_path / "loop" / "loop.json").read_text())
    assert again["iterations"][-1]["parameters"] == it1["parameters"]
    bare = (tmp_path / "loop" / "loop_report.md").read_text()
    assert not list((tmp_path / "loop").glob("loop_*.png")) and "![" not in bare
    assert f"`pyomo-heli report-loop {tmp_path / 'loop'}` draws them" in bare
    # the text is the full report's without its figure lines (blank lines aside)
    assert [ln for ln in bare.splitlines() if ln and not ln.startswith("- figures:")] == \
        [ln for ln in first.splitlines() if ln and not ln.startswith("![")]
    # the report alone, rewritten from loop.json with no solve (`report-loop`): the same report and figures, its
    # validation tables (per output, joint, by speed) included
    assert main(["report-loop", str(tmp_path / "loop")]) == 0
    assert "solve" not in capsys.readouterr().out
    assert (tmp_path / "loop" / "loop_report.md").read_text() == first
    assert sorted(f.name for f in (tmp_path / "loop").glob("loop_*.png")) == figures
    assert JOINT in first and "by trim speed" in first
    # another setting (the inputs resampled the other way) is not taken for the finished front: refused, named
    text = cfg.path.read_text()
    other = "sample" if cfg.resample_inputs == "project" else "project"
    cfg.path.write_text(text.replace("resample_hz = 25\n", f'resample_hz = 25\nresample_inputs = "{other}"\n'))
    assert main(["close-loop", str(cfg.path), "--out", str(tmp_path / "loop")]) == 2
    err = capsys.readouterr().err
    assert "iter_0" in err and "fingerprint" in err
    cfg.path.write_text(text)  # back to the config the loop ran with
    # an iteration's folder is usable with its config alone: the rebuilt model (candidate, shape held) replays to the
    # same trim errors as the loop recorded, and `pyomo-heli uncertainty` gives the added strength a standard error
    from pyomo_heli.workflows.close_loop import config_of_result, errors_of
    from pyomo_heli.pareto.result import IdentificationResult

    res1 = IdentificationResult.load(tmp_path / "loop" / "iter_1")
    cfg1 = config_of_result(cfg, res1)
    assert [f.name for f in cfg1.free] == ["theta_twist", "CL_alpha_HT", "Iyy", "k_wt"]
    assert cfg1.model.parameters["n_wt"] == it1["shape_parameters"]["n_wt"]
    trims = load_flight_test(cfg.dataset).trims.reset_index(drop=True)
    again = errors_of(cfg1.model, it1["parameters"], [], [], trims, "again")["trim_rms"]
    assert again == pytest.approx(it1["trim_rms"], rel=1e-9)
    assert main(["uncertainty", str(cfg.path), "--results", str(tmp_path / "loop" / "iter_1"),
                 "--out", str(tmp_path / "se1"), "--points", "chosen"]) == 0
    se = json.loads((tmp_path / "se1" / "chosen.json").read_text())["direct"]["uncertainty"]["se"]
    assert set(se) == {"theta_twist", "CL_alpha_HT", "Iyy", "k_wt"} and se["k_wt"] > 0
    # ... the same standard errors as the loop computed itself at the diagnosed point (its own model, not rebuilt)
    assert it1["standard_errors"] == pytest.approx(se, rel=1e-9)
    assert "iter 1 error / SE" in report


@pytest.mark.slow
def test_wake_loop_with_input_errors(tmp_path, capsys, flight_test_cache):
    """The same small wake instance with the measured inputs' errors estimated ([objectives] input_errors):
    the loop runs with the known-noise likelihood, picks the wake first, and the trim error, the parameter
    errors against truth and the model's validation error against the truth replay all fall.

    A rerun with another setting and ``--restart`` identifies afresh instead of reusing iteration 0.

    Slow (70 s; CI time): the default run has loops with input errors in tests/test_discovery.py and
    tests/test_close_loop.py (M0 + noise), the innovations' whiteness in tests/test_innovations.py, the refusal of a
    finished front made with another setting in test_wake_on_tail_is_picked_first_and_the_errors_fall, and the
    front store's --restart in tests/test_pareto_store.py."""
    loop = '\n[objectives]\ninput_errors = ["col", "lon"]\n\n[loop]\nmax_iterations = 1\n'
    cfg = make_case(tmp_path, "[truth.effects.wake_on_tail]\nK_lamT = 1.5\nd_t = 1.8\ns_w = 0.5\n", seed=25,
                    loop=loop, maneuvers=WAKE_MANEUVERS, input_reference_s=1.9, data_cache=flight_test_cache)
    assert cfg.nlp.input_errors == ("col", "lon")
    assert main(["close-loop", str(cfg.path), "--out", str(tmp_path / "loop")]) == 0
    doc = json.loads((tmp_path / "loop" / "loop.json").read_text())
    it0, it1 = doc["iterations"][0], doc["iterations"][-1]
    assert it0["attribution"]["accepted"] == "rotor_wake_on_tail"
    assert it1["extensions"] == ["rotor_wake_on_tail"]
    assert _pooled_trim(it1["trim_rms"]) <= 0.5 * _pooled_trim(it0["trim_rms"])
    model_err, _ = _truth_replay_errors(cfg, doc)
    for o, e0 in model_err[0].items():
        assert model_err[-1][o] < e0, o
    truth = json.loads((cfg.dataset / "truth.json").read_text())["parameters"]
    print({n: [f"{100 * (it['parameters'][n] / truth[n] - 1):+.2f} %" for it in (it0, it1)]
           for n in ("theta_twist", "CL_alpha_HT", "Iyy")})
    for n in ("theta_twist", "CL_alpha_HT", "Iyy"):
        assert abs(it1["parameters"][n] - truth[n]) < abs(it0["parameters"][n] - truth[n]), n
    # a loop iteration's folder can be diagnosed from the command line (its added effect included), and
    # with the input errors the whiteness is tested on the innovations
    assert main(["diagnose", str(tmp_path / "loop" / "iter_1"), "--out", str(tmp_path / "diag")]) == 0
    diag = json.loads((tmp_path / "diag" / "diagnosis.json").read_text())
    assert diag["info"]["extensions"] == ["rotor_wake_on_tail"]
    assert {w["series"] for w in diag["whiteness"]} == {"innovation"}
    # another setting (the inputs resampled the other way) is refused for the finished front (checked in the default
    # run, test_wake_on_tail_is_picked_first_and_the_errors_fall); --restart identifies afresh (iteration 0 only: what
    # --restart decides is whether iter_0 is reused, and a second iteration would only repeat the loop checked above)
    text = cfg.path.read_text()
    other = "sample" if cfg.resample_inputs == "project" else "project"
    cfg.path.write_text(text.replace("resample_hz = 25\n", f'resample_hz = 25\nresample_inputs = "{other}"\n')
                        .replace("max_iterations = 1\n", "max_iterations = 0\n"))
    capsys.readouterr()
    assert main(["close-loop", str(cfg.path), "--out", str(tmp_path / "loop"), "--restart",
                 "--figure-format", "none"]) == 0
    out = capsys.readouterr().out
    assert "reusing" not in out
    fresh = json.loads((tmp_path / "loop" / "loop.json").read_text())
    assert len(fresh["iterations"]) == 1 and fresh["stopped"].startswith("iteration limit 0 reached")
    assert fresh["iterations"][0]["attribution"]["accepted"] == "rotor_wake_on_tail"
    assert fresh["iterations"][0]["parameters"] != it0["parameters"]  # the other inputs, another fit


def test_report_loop_bad_folders_are_one_line_exit_2(tmp_path, capsys):
    """``report-loop`` on a folder that is not a finished close-loop: one line naming the folder or file."""
    assert main(["report-loop", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{tmp_path}: no loop.json" in err[0], err
    (tmp_path / "loop.json").write_text('{"config": "gone.toml", "dataset": ".", "iterations": []}')
    assert main(["report-loop", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a loop record" in err[0], err
    (tmp_path / "loop.json").write_text('{"config": "gone.toml", "dataset": ".", "iterations": [{"results_dir": "i"}]}')
    assert main(["report-loop", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "config gone.toml" in err[0] and "--config" in err[0], err
    (tmp_path / "loop.json").write_text("[1, 2")
    assert main(["report-loop", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a loop record" in err[0], err


def test_report_loop_on_a_folder_made_elsewhere(tmp_path, monkeypatch):
    """The committed loop folder gives its committed report again, on any machine (the report's dataset line names
    the flight test found here, so it is left out of the comparison). A copy that names the flight test where it
    was made (not on this machine): ``report-loop`` reads the config's own, whose content the loop recorded, and
    writes the same report with its figures; a flight test of other content is refused in one line."""
    import shutil

    def without_dataset(text):
        return [ln for ln in text.splitlines() if not ln.startswith("- dataset:")]

    monkeypatch.chdir(ROOT)  # the folder names its config relative to the checkout
    committed = without_dataset((ROOT / "docs" / "results" / "close_loop" / "loop_report.md").read_text())
    here = tmp_path / "here"
    shutil.copytree(ROOT / "docs" / "results" / "close_loop", here)
    assert main(["report-loop", str(here)]) == 0
    assert without_dataset((here / "loop_report.md").read_text()) == committed
    folder = tmp_path / "close_loop"
    shutil.copytree(ROOT / "docs" / "results" / "close_loop", folder)
    doc = json.loads((folder / "loop.json").read_text())
    doc["dataset"] = str(tmp_path / "elsewhere" / "bo105_synthetic")  # made elsewhere
    (folder / "loop.json").write_text(json.dumps(doc, indent=2))
    assert main(["report-loop", str(folder)]) == 0
    assert without_dataset((folder / "loop_report.md").read_text()) == committed
    for name in ("loop_trim_vs_speed.png", "loop_trim_forces.png", "loop_validation.png"):
        assert (folder / name).stat().st_size > 10_000, name
    # a config that is not the loop's (another model: a fixed parameter changed) is refused, not replayed
    other = tmp_path / "other.toml"
    other.write_text((ROOT / "studies" / "close_loop.toml").read_text().replace(
        '"../data/bo105_synthetic"', f'"{ROOT / "data" / "bo105_synthetic"}"').replace(
        "[objectives]", "[model]\nparameters = { f_e = 1.2 }\n\n[objectives]", 1))
    assert main(["report-loop", str(folder), "--config", str(other)]) == 2
    chosen = folder / doc["iterations"][0]["results_dir"] / "chosen.json"
    rec = json.loads(chosen.read_text())
    rec["info"]["dataset_sha256"] = "0" * 64
    chosen.write_text(json.dumps(rec))
    assert main(["report-loop", str(folder)]) == 2
