"""A rerun reuses finished work only when it was made from the same inputs (docs/robustness.md, "Resuming"): a
finished loop by its config text and flight test, an interrupted loop never taken for a finished one, a finished
identification solved by other code said and marked, the seeded studies' folders by their configs, the envelope
study's saved rows by the flight test's content, the Monte Carlo realizations by the flight test."""
import importlib.util
import json
import shutil
import sys
from pathlib import Path

import pytest

from pyomo_heli.workflows.close_loop import LoopMismatchError, finished_loop, loop_inputs

ROOT = Path(__file__).resolve().parents[1]
TESTS = Path(__file__).resolve().parent
BUNDLED = ROOT / "pyomo_heli" / "data" / "bo105_synthetic"


def _flight_test(tmp_path, name="ft") -> Path:
    """A copy of the bundled flight test (its files hashed by content)."""
    d = tmp_path / name
    shutil.copytree(BUNDLED, d)
    return d


def _loop(folder: Path, config: Path, dataset: Path, stopped="nothing accepted", **records) -> Path:
    """A loop folder whose loop.json says what a close-loop run writes (inputs recorded unless overridden)."""
    folder.mkdir(parents=True, exist_ok=True)
    doc = {"config": str(config), "dataset": str(dataset), **loop_inputs(config, dataset), "iterations": [],
           "stopped": stopped, **records}
    (folder / "loop.json").write_text(json.dumps({k: v for k, v in doc.items() if v != "drop"}))
    return folder


def test_a_finished_loop_is_reused_only_from_the_same_config_and_flight_test(tmp_path, caplog):
    config, data = tmp_path / "loop.toml", _flight_test(tmp_path)
    config.write_text("# the loop's config\n")
    loop = _loop(tmp_path / "loop", config, data)
    assert finished_loop(loop, config, data)
    assert not finished_loop(tmp_path / "none", config, data)  # nothing there: run it
    # another config text at the same path: another study's loop, refused by name
    config.write_text("# another config\n[loop]\ndiscovery = false\n")
    with pytest.raises(LoopMismatchError, match=r"loop: its finished loop was made from another config .*loop.toml"):
        finished_loop(loop, config, data)
    config.write_text("# the loop's config\n")
    # the same flight test files elsewhere: the same; one file changed: refused
    moved = _flight_test(tmp_path, "moved")
    assert finished_loop(loop, config, moved)
    trims = moved / "trims.csv"
    trims.write_text(trims.read_text().replace("\n", "\n", 1) + "\n")
    with pytest.raises(LoopMismatchError, match="another flight test"):
        finished_loop(loop, config, moved)
    # other package sources: reused, with a warning
    _loop(loop, config, data, source_sha256="0" * 64)
    with caplog.at_level("WARNING"):
        assert finished_loop(loop, config, data)
    assert "made by other package sources" in caplog.text


def test_an_interrupted_loop_is_not_taken_for_a_finished_one(tmp_path, caplog):
    """close-loop writes ``"stopped": null`` after every iteration: only a stop message says it finished; a loop
    written before loops recorded their inputs is reused with a warning that nothing was checked."""
    config, data = tmp_path / "loop.toml", _flight_test(tmp_path)
    config.write_text("# the loop's config\n")
    assert not finished_loop(_loop(tmp_path / "a", config, data, stopped=None), config, data)
    old = _loop(tmp_path / "b", config, data, config_sha256="drop", dataset_sha256="drop", source_sha256="drop")
    with caplog.at_level("WARNING"):
        assert finished_loop(old, config, data)
    assert "written before loops recorded their inputs" in caplog.text


def test_the_seeds_study_resumes_an_interrupted_loop(tmp_path, monkeypatch):
    """close_loop_seeds.run_seed ran close-loop only when loop.json lacked the ``stopped`` key, which close-loop
    always writes: an interrupted loop was evaluated as if finished."""
    from pyomo_heli.studies import close_loop_seeds as S

    data, config = tmp_path / "data_7", tmp_path / "loop.toml"
    shutil.copytree(BUNDLED, data)
    config.write_text("# the loop's config\n")
    _loop(tmp_path / "loop_7", config, data, stopped=None)
    calls = []
    monkeypatch.setattr(S, "run_command", lambda args: calls.append(args))
    S.run_seed(7, tmp_path, config, tmp_path / "gen.toml")
    assert [c[0] for c in calls] == ["close-loop"]
    _loop(tmp_path / "loop_7", config, data)  # finished: not run again
    S.run_seed(7, tmp_path, config, tmp_path / "gen.toml")
    assert len(calls) == 1
    config.write_text("# another config\n")  # finished from another config: refused, one line, status 2
    assert S.seed_task((7, tmp_path, config, tmp_path / "gen.toml")) == (None, 2)
    assert len(calls) == 1


def _held_out_study():
    spec = importlib.util.spec_from_file_location("held_out_effects_study", ROOT / "studies" / "held_out_effects.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def test_the_held_out_study_refuses_a_finished_loop_of_another_config(tmp_path, monkeypatch):
    """run_case reused any stopped loop in OUT, so --set, --generic-family or another --config into an existing OUT
    rebuilt its rows from the old loops; now the loop's config text and flight test must be the case's."""
    study = _held_out_study()
    template = (ROOT / "data" / "bo105_synthetic.toml").read_text()
    case = tmp_path / "none_20261122"
    (case).mkdir()
    (case / "gen.toml").write_text(study.data_config(template, "none", 20261122))
    shutil.copytree(BUNDLED, case / "data")
    config = tmp_path / "config_set.toml"
    config.write_text("# discovery ranked by p\n")
    _loop(case / "loop", config, case / "data")
    calls = []
    monkeypatch.setattr(study, "run_command", lambda args: calls.append(args))
    assert study.run_case("none", 20261122, tmp_path, config, template) == case / "loop"
    assert calls == []
    config.write_text("# discovery ranked by raw LR\n")
    with pytest.raises(study.StudyFolderError, match="made from another config"):
        study.run_case("none", 20261122, tmp_path, config, template)
    assert calls == []


def test_the_bundled_cost_run_times_a_whole_loop(tmp_path, monkeypatch):
    """A loop without a recorded time (interrupted before its cost entry) is run again from the start
    (``--restart``), so its time is that of the whole loop, not of the iterations a resumed run had left; a timed
    loop is not run again; one timed from another config is refused."""
    study = _held_out_study()
    truth = json.loads((BUNDLED / "truth.json").read_text())["parameters"]
    calls = []

    def fake_close_loop(args):
        calls.append(args)
        _loop(Path(args[args.index("--out") + 1]), Path(args[1]), Path(args[args.index("--dataset") + 1]),
              iterations=[{"iteration": 0, "extensions": [], "trim_rms": {"col": 1.0, "lon": 1.0, "theta": 1.0},
                           "parameters": {n: truth[n] for n in study.PARAMETERS},
                           "discovery": {"decision": "none", "added": None}}])

    monkeypatch.setattr(study, "run_command", fake_close_loop)
    config, out = tmp_path / "loop.toml", tmp_path / "out"
    config.write_text("[loop]\nmax_iterations = 1\n")
    _loop(out / "bundled" / "on" / "loop", config, BUNDLED, stopped=None)  # interrupted, no time recorded
    cost = study.run_bundled(out, config, BUNDLED, modes=("on",))
    assert [c[0] for c in calls] == ["close-loop"] and calls[0][-1] == "--restart"
    assert cost["on"]["wall_s"] >= 0 and cost["on"]["kept"] == []
    study.run_bundled(out, config, BUNDLED, modes=("on",))
    assert len(calls) == 1  # timed and finished: read back
    config.write_text("[loop]\nmax_iterations = 2\n")
    with pytest.raises(study.StudyFolderError, match="its timed loop was made from another config"):
        study.run_bundled(out, config, BUNDLED, modes=("on",))
    assert len(calls) == 1


def test_a_finished_identification_solved_by_other_code_is_said_and_marked(tmp_path, caplog):
    """close_loop._finished compared the checkpoint's fingerprint only: an iteration solved by other package
    sources was reused silently; now with a warning and ``resumed_from_other_code`` in its result (and loop
    record), as identify does for resumed points."""
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.provenance import source_sha256
    from pyomo_heli.workflows.close_loop import _finished
    from pyomo_heli.workflows.identify import identification_fingerprint

    cfg = load_identification_config(TESTS / "configs" / "m0_noise_small.toml")
    folder = tmp_path / "iter_0"
    shutil.copytree(TESTS / "results" / "m0_noise_small", folder)
    fp = identification_fingerprint(cfg)
    (folder / "checkpoint.json").write_text(json.dumps({"fingerprint": fp, "source": source_sha256()}))
    with caplog.at_level("WARNING"):
        res = _finished(cfg, folder)
    assert res is not None and not res.info.get("resumed_from_other_code") and "other code" not in caplog.text
    for source in ("0" * 64, "mixed"):
        (folder / "checkpoint.json").write_text(json.dumps({"fingerprint": fp, "source": source}))
        with caplog.at_level("WARNING"):
            res = _finished(cfg, folder)
        assert res is not None and res.info["resumed_from_other_code"] is True
        assert "solved by other code" in caplog.text


def test_the_seeded_studies_refuse_an_out_made_from_other_configs(tmp_path):
    """validation_test_level (and the other seeded studies) read back OUT/seed_<s>.json and OUT/data/<s> keyed on
    the seed alone: a rerun with another --config or --data-config summarised the old seeds. The folder now
    records its inputs by content and a rerun with others is one error line naming the option (exit 2)."""
    import subprocess

    out = tmp_path / "vt"
    args = [sys.executable, "-m", "pyomo_heli.studies.validation_test_level", "--seeds", "5", "--config",
            str(TESTS / "configs" / "m0_noise_small.toml"), "--data-config",
            str(TESTS / "configs" / "gen_m0_noise_small.toml"), "--out", str(out)]
    out.mkdir()
    (out / "study_inputs.json").write_text(json.dumps({"config": "0" * 64, "data_config": "1" * 64}))
    (out / "seed_5.json").write_text("{}")  # a stale seed: never summarised
    r = subprocess.run(args, capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines()[-1].endswith(
        f"--out {out}: its finished results were made from other inputs than the content of --config "
        f"{TESTS / 'configs' / 'm0_noise_small.toml'}; give another --out or remove it")


def test_claim_inputs_records_on_the_first_run_and_compares_on_a_rerun(tmp_path):
    import argparse

    from pyomo_heli.studies.args import claim_inputs

    ap = argparse.ArgumentParser(prog="study")
    cfg = tmp_path / "a.toml"
    cfg.write_text("x = 1\n")
    claim_inputs(ap, tmp_path / "out", config=cfg, resample_inputs="sample")
    claim_inputs(ap, tmp_path / "out", config=cfg, resample_inputs="sample")  # the same: resumes
    with pytest.raises(SystemExit):
        claim_inputs(ap, tmp_path / "out", config=cfg, resample_inputs="project")
    cfg.write_text("x = 2\n")
    with pytest.raises(SystemExit):
        claim_inputs(ap, tmp_path / "out", config=cfg, resample_inputs="sample")


def test_a_seeded_study_refuses_the_out_folder_of_another_study(tmp_path, capsys):
    """Two seeded studies with the same configs keep other things under the same names (OUT/data/<seed>,
    seed_<n>.json): the folder records which study made it."""
    from pyomo_heli.studies.seeded import seeded_study_main

    def one_seed(seed, config, data_config, out):
        return {"seed": seed}

    def summary(docs):
        import pandas as pd
        return pd.DataFrame(docs), "seeds"

    out = tmp_path / "out"
    args = ["--seeds", "1", "--config", str(TESTS / "configs" / "m0_noise_small.toml"), "--out", str(out)]
    one_seed.__module__ = "pyomo_heli.studies.one"
    assert seeded_study_main("a", args, one_seed, summary) == 0
    assert seeded_study_main("a", args, one_seed, summary) == 0  # the same study resumes
    one_seed.__module__ = "pyomo_heli.studies.other"
    with pytest.raises(SystemExit) as exc:
        seeded_study_main("b", args, one_seed, summary)
    assert exc.value.code == 2
    assert f"--out {out}: its finished results are another study's (pyomo_heli.studies.one)" in \
        capsys.readouterr().err


def test_the_envelope_study_keys_saved_rows_on_the_flight_test_content(tmp_path, monkeypatch):
    """Its saved rows were keyed on manifest.json, which is the same for every seed of a generator config: a
    loop evaluated on one realisation was read back for another."""
    import pandas as pd

    from pyomo_heli.studies import envelope_validation as E

    config, a = tmp_path / "loop.toml", _flight_test(tmp_path, "a")
    config.write_text("# loop\n")
    loop = _loop(tmp_path / "loop", config, a)
    b = _flight_test(tmp_path, "b")
    (b / "trims.csv").write_text((b / "trims.csv").read_text() + "\n")  # same manifest, other content
    assert (a / "manifest.json").read_bytes() == (b / "manifest.json").read_bytes()
    seen = []
    monkeypatch.setattr(E, "evaluate", lambda lp, data: seen.append(data) or pd.DataFrame({"data": [str(data)]}))
    assert E.evaluate_saved(loop, a, tmp_path / "rows")["data"].tolist() == [str(a)]
    assert E.evaluate_saved(loop, b, tmp_path / "rows")["data"].tolist() == [str(b)]
    assert E.evaluate_saved(loop, a, tmp_path / "rows")["data"].tolist() == [str(a)]
    assert seen == [a, b]


def test_the_monte_carlo_resumes_only_on_the_same_flight_test(tmp_path):
    """Realizations perturb the config's flight test: stored ones of another flight test are refused (its content
    was not recorded, so regenerating the data in place mixed old and new realizations)."""
    from pyomo_heli.provenance import ResultsMismatchError
    from pyomo_heli.uncertainty.monte_carlo import ProblemSpec, run_monte_carlo

    out = tmp_path / "mc"
    out.mkdir()
    (out / "realizations.csv").write_text("realization,estimator\n")
    (out / "monte_carlo.json").write_text(json.dumps({"parameters": [], "info": {"dataset_sha256": "0" * 64}}))
    spec = ProblemSpec.make(TESTS / "configs" / "mc_time_small.toml")
    with pytest.raises(ResultsMismatchError, match=r"another run \(it differs in: dataset_sha256\)"):
        run_monte_carlo(spec, 1, seed=11, sigma={}, trim_sigma={}, truth={}, out=out, workers=0,
                        progress=lambda *_: None)


def test_the_held_out_signature_cache_is_named_by_the_config_and_the_code(monkeypatch):
    """The reference flight test of a generator config is kept in a temporary folder across runs: named by the
    config's text alone, it outlived a change of the generator's code."""
    import pyomo_heli.provenance as provenance

    study = _held_out_study()
    a = study.signature_cache("[sensors]\n")
    assert study.signature_cache("[sensors]\n") == a and study.signature_cache("[sensors]\nx = 1\n") != a
    monkeypatch.setattr(provenance, "source_sha256", lambda: "0" * 64)
    assert study.signature_cache("[sensors]\n") != a
