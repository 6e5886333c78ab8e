"""Trim-only flight tests: format (missing channels, conventions), identification and the trim loop."""
from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pyomo_heli.diagnosis.candidates import CANDIDATES
from pyomo_heli.dataset import load_flight_test, validate_flight_test, write_flight_test
from pyomo_heli.dataset.schema import KT, TrimConventions
from pyomo_heli.nlp.parameters import FreeParameter
from pyomo_heli.physics.conventions import THETA_DATUM, TrimOutputDatum, recorded_trim
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.simulation.trim import trim_float, trim_sweep
from pyomo_heli.workflows.trim_loop import (
    TrimLoopConfig,
    TrimLoopError,
    load_trim_loop_config,
    predict,
    run_trim_loop,
    trim_points,
    write_trim_report,
)

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "data" / "bo105_flight_trims_padfield1996"
DEG = math.pi / 180.0
SPEEDS = {"col": [0, 15, 30, 45, 60, 75, 90, 105], "lon": [5, 20, 35, 50, 65, 80, 95],
          "theta": [10, 25, 40, 55, 70, 85, 100]}
TRUTH = {"f_e": 1.4, "x_h": 0.02, "a": 6.4, THETA_DATUM: 0.8 * DEG}


def _generated(folder: Path, conventions=TrimConventions(collective_station=0.0, theta_datum=None)) -> Path:
    """A trim-only flight test from a known truth: each channel at its own speeds, recorded with ``conventions``
    (root collective; the datum TRUTH[theta_datum] that the manifest leaves to estimate)."""
    truth = HelicopterModel(extensions=(TrimOutputDatum(),)).with_parameters(**TRUTH)
    rows = []
    for ch, kts in SPEEDS.items():
        y = predict(truth, conventions, [v * KT for v in kts], [ch] * len(kts))
        for v, val in zip(kts, y):
            rows.append({"V": v * KT, "gamma_fp": 0.0, "col": np.nan, "lon": np.nan, "theta": np.nan, ch: val})
    manifest = {"aircraft": "Bo-105 (synthetic trims)", "atmosphere": {"rho_kg_m3": 1.225, "g_m_s2": 9.81},
                "mass_kg": 2200.0, "maneuvers": [], "conventions": conventions.to_manifest()}
    write_flight_test(folder, manifest, {}, pd.DataFrame(rows))
    return folder


def test_recorded_collective_is_the_root_pitch():
    """col at r_ref = 0.7 plus the twist to the root: theta_0 = col - 0.7 theta_tw (docs/model.md 3.2: +5.615 deg)."""
    m = HelicopterModel()
    (tp,) = trim_sweep(m, [30.0])
    rec = recorded_trim(tp.col, tp.lon, tp.theta, m.parameters, TrimConventions(collective_station=0.0, lon_sign=-1,
                                                                                 theta_datum=2 * DEG))
    assert (rec["col"] - tp.col) / DEG == pytest.approx(5.615, abs=5e-4)
    assert rec["lon"] == -tp.lon
    assert rec["theta"] == pytest.approx(tp.theta + 2 * DEG, abs=1e-15)


def test_missing_channels_load_and_count(tmp_path):
    ft = load_flight_test(BUNDLED)
    assert ft.trim_only and not ft.maneuvers
    assert ft.trim_counts() == {"col": 11, "lon": 12, "theta": 12}
    assert len(ft.trims) == 35 and int(ft.trims[["col", "lon", "theta"]].notna().sum(axis=1).max()) == 1
    assert ft.conventions == TrimConventions(collective_station=0.0, lon_sign=1, theta_datum=None)
    pts = trim_points(ft, 3)
    counts = pts.groupby(["channel", "role"]).size().to_dict()
    assert counts == {("col", "identification"): 8, ("col", "validation"): 3, ("lon", "identification"): 8,
                      ("lon", "validation"): 4, ("theta", "identification"): 8, ("theta", "validation"): 4}
    # every third point of each channel in speed order is held out
    lon = pts[pts.channel == "lon"].sort_values("V")
    assert list(lon.role == "validation") == [k % 3 == 2 for k in range(12)]
    out = subprocess.run([sys.executable, "-m", "pyomo_heli.cli", "check-data", str(BUNDLED)], capture_output=True,
                         text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert "trim-only flight test" in out.stdout and "measured per channel: col 11, lon 12, theta 12" in out.stdout
    # written and read back: same values, same empty cells, same conventions
    copy = write_flight_test(tmp_path / "copy", ft)
    ft2 = load_flight_test(copy)
    pd.testing.assert_frame_equal(ft.trims, ft2.trims, rtol=1e-9)
    assert ft2.conventions == ft.conventions and ft2.assumptions == ft.assumptions


BAD = [
    ("all-empty-row", lambda f: _cell(f, 3, {"col_deg": "", "lon_deg": "", "theta_deg": ""}),
     "trims.csv: 1 trim row with no measured channel (row 3)"),
    ("non-numeric", lambda f: _cell(f, 2, {"lon_deg": "abc"}),
     "trims.csv: column 'lon_deg': 1 non-numeric value (row 2"),
    ("nan-token", lambda f: _cell(f, 4, {"theta_deg": "nan"}), "trims.csv: column 'theta_deg': 1 NaN value (row 4)"),
    ("source-names-a-maneuver", lambda f: _cell(f, 5, {"source": "lon3211"}),
     "trims.csv: column 'source': 1 value neither 'level' nor a maneuver name (row 5 ('lon3211'))"),
    ("speed-negative", lambda f: _cell(f, 6, {"speed_kt": "-5"}),
     "trims.csv: column 'speed_kt': 1 negative speed (row 6)"),
    ("lon-sign", lambda f: _manifest(f, lambda m: m["conventions"].update(lon_sign=2)),
     "manifest.json: field 'conventions.lon_sign': must be 1"),
    ("datum-word", lambda f: _manifest(f, lambda m: m["conventions"].update(theta_datum_deg="unknown")),
     "manifest.json: field 'conventions.theta_datum_deg'"),
    ("station", lambda f: _manifest(f, lambda m: m["conventions"].update(collective_station=70)),
     "manifest.json: field 'conventions.collective_station': must be a number in 0..1"),
]


def _cell(folder, row, values):
    p = folder / "trims.csv"
    df = pd.read_csv(p, dtype=str, keep_default_na=False)
    if "source" in values and "source" not in df:
        df["source"] = "level"
    for k, v in values.items():
        df.loc[row - 1, k] = v
    df.to_csv(p, index=False)


def _manifest(folder, edit):
    p = folder / "manifest.json"
    m = json.loads(p.read_text())
    edit(m)
    p.write_text(json.dumps(m))


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    return _generated(tmp_path_factory.mktemp("trim_only") / "ds")


@pytest.mark.parametrize("mutate, expected", [pytest.param(f, e, id=i) for i, f, e in BAD])
def test_malformed_trim_only_dataset_one_line_error(generated, tmp_path, capsys, mutate, expected):
    from pyomo_heli.cli import main

    folder = tmp_path / "ds"
    shutil.copytree(generated, folder)
    assert validate_flight_test(folder) == []
    mutate(folder)
    assert main(["check-data", str(folder)]) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: ") and expected in lines[0], lines[0]
    assert "Traceback" not in err
    cfg = tmp_path / "c.toml"  # the trim loop names the same problem in one line
    cfg.write_text(f'[data]\ndataset = "{folder}"\n[parameters.f_e]\n')
    assert main(["trim-loop", str(cfg), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and expected in err, err


def _config(tmp_path, dataset, **kw) -> TrimLoopConfig:
    p = HelicopterModel().parameters
    free = [FreeParameter("f_e", p["f_e"], 0.3, 3.0, 1.0), FreeParameter("x_h", p["x_h"], -0.3, 0.3, 0.1),
            FreeParameter("a", p["a"], 4.0, 7.0, 6.0)]
    return TrimLoopConfig(path=tmp_path / "cfg.toml", dataset=dataset, free=free, **kw)


def test_generated_trim_only_flight_test_identified_exactly(tmp_path):
    """Clean trims from a known truth, each channel at its own speeds, root collective and an unknown datum:
    the trim-only identification (Pyomo NLP) recovers the truth, the datum included."""
    folder = _generated(tmp_path / "ds")
    cfg = _config(tmp_path, folder, holdout_every=3, max_iterations=0)
    doc = run_trim_loop(cfg, tmp_path / "out", progress=lambda *_: None)
    it = doc["iterations"][0]
    assert it["solve"]["status"] == "Solve_Succeeded"
    for name, value in TRUTH.items():
        assert it["parameters"][name]["value"] == pytest.approx(value, rel=1e-5, abs=1e-8), name
    for role in ("identification", "validation"):  # held-out points predicted exactly too
        assert max(it["rms_deg"][role].values()) < 1e-4
    assert doc["initial"]["rms_deg"]["identification"]["col"] > 0.1  # the start was off
    assert "degenerate" in doc["front"] and doc["trim_only"]
    assert doc["conventions"]["theta_datum_estimated"]


def test_bundled_real_data_study_writes_report(tmp_path):
    """The real-data study (a copy of its config) runs from the repository and writes report, figures and JSON;
    the NLP's J_trim equals the float model's at the estimate (two routes)."""
    out = tmp_path / "bo105"
    run = subprocess.run([sys.executable, "-m", "pyomo_heli.cli", "trim-loop", "tests/configs/bo105_flight_trims.toml",
                          "--out", str(out)], capture_output=True, text=True, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    for f in ("report.md", "trim_loop.json", "trim_curves.png", "trim_residuals.png"):
        assert (out / f).is_file(), f
    doc = json.loads((out / "trim_loop.json").read_text())
    last = doc["iterations"][-1]
    assert last["J_trim_float"] == pytest.approx(last["solve"]["J_trim"], rel=1e-6)
    assert THETA_DATUM in last["parameters"] and last["parameters"][THETA_DATUM]["se"] > 0
    for ch in ("col", "lon", "theta"):
        assert last["rms_deg"]["identification"][ch] < doc["initial"]["rms_deg"]["identification"][ch]
    text = (out / "report.md").read_text()
    assert "degenerate" in text and "theta_datum (convention offset)" in text
    # a channel with a single point has no step: the report says "-" where the step's speeds go
    for k in ("step_deg", "step_between_kt", "mean_below_step_deg", "mean_above_step_deg"):
        last["residual_shape"]["col"].pop(k, None)
    write_trim_report(load_trim_loop_config(ROOT / "tests" / "configs" / "bo105_flight_trims.toml"), doc, out)
    assert "| col | " in (out / "report.md").read_text() and " | - | " in (out / "report.md").read_text()


def test_trim_loop_config_errors(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[data]\ndataset = "{BUNDLED}"\n[parameters.theta_datum]\nunit = "rad"\n')
    with pytest.raises(TrimLoopError, match=r"\[parameters.theta_datum\]: the pitch-attitude datum is freed by"):
        load_trim_loop_config(cfg)
    cfg.write_text(f'[data]\ndataset = "{BUNDLED}"\nholdout_every = 1\n[parameters.f_e]\n')
    out = subprocess.run([sys.executable, "-m", "pyomo_heli.cli", "trim-loop", str(cfg), "--out", str(tmp_path / "o")],
                         capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 2 and "field 'holdout_every'" in out.stderr and len(out.stderr.strip().splitlines()) == 1
    for loop, message in (('generic_family = "big"', "[loop]: field 'generic_family' must be \"standard\", "
                                                     "\"extended\" or \"control\", got 'big'"),
                          ('generic = ["dM_bump99"]', "[loop]: field 'generic': unknown discrepancy term 'dM_bump99'")):
        cfg.write_text(f'[data]\ndataset = "{BUNDLED}"\n[parameters.f_e]\n[loop]\ndiscovery = true\n{loop}\n')
        with pytest.raises(TrimLoopError) as err:
            load_trim_loop_config(cfg)
        assert message in str(err.value) and len(str(err.value).splitlines()) == 1, str(err.value)
    cfg.write_text(f'[data]\ndataset = "{BUNDLED}"\n[parameters.f_e]\n[loop]\ndiscovery = true\n'
                   'generic_family = "extended"\n')
    c = load_trim_loop_config(cfg)
    assert c.discovery and c.generic_family == "extended" and c.generic is None
    # a field nothing reads (found by a review: accepted and dropped)
    for loop, message in (('generic_family = "extended"', "field 'generic_family' is not read here: it is read with "
                                                          "discovery = true only"),
                          ('discovery = true\ngeneric = ["dM_mu"]\ngeneric_family = "extended"',
                           "field 'generic_family' is not read here: 'generic' names the terms")):
        cfg.write_text(f'[data]\ndataset = "{BUNDLED}"\n[parameters.f_e]\n[loop]\n{loop}\n')
        with pytest.raises(TrimLoopError) as err:
            load_trim_loop_config(cfg)
        assert f"[loop]: {message}" in str(err.value) and len(str(err.value).splitlines()) == 1, str(err.value)


def test_maneuver_identification_refuses_trim_only_data(tmp_path):
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.nlp.identification import identification_data

    src = (ROOT / "tests" / "configs" / "case1.toml").read_text()
    cfg_path = tmp_path / "c.toml"
    cfg_path.write_text(src.replace('dataset = "../../data/bo105_synthetic"', f'dataset = "{BUNDLED}"'))
    cfg = load_identification_config(cfg_path)
    with pytest.raises(ValueError, match="trim-only flight test .*pyomo-heli trim-loop"):
        identification_data(cfg)


def _noisy_trims(folder: Path, effect, **strengths) -> Path:
    """Trims from M0 + ``effect`` (a truth effect the candidate library does not import), f_e 1.4, x_h 0.02, every
    channel every 10 kt at its own speeds, 0.1 deg seeded noise, root collective and a datum of 0.8 deg."""
    conv = TrimConventions(collective_station=0.0, theta_datum=None)
    truth = HelicopterModel(extensions=(TrimOutputDatum(), effect)).with_parameters(
        f_e=1.4, x_h=0.02, theta_datum=0.8 * DEG, **strengths)
    speeds = {"col": range(0, 106, 10), "lon": range(3, 106, 10), "theta": range(6, 106, 10)}
    rng = np.random.default_rng(1)
    rows = []
    for ch, kts in speeds.items():
        y = predict(truth, conv, [v * KT for v in kts], [ch] * len(kts))
        for v, val in zip(kts, y):
            rows.append({"V": v * KT, "gamma_fp": 0.0, "col": np.nan, "lon": np.nan, "theta": np.nan,
                         ch: val + rng.normal(0.0, 0.1 * DEG)})
    manifest = {"aircraft": f"Bo-105 (synthetic trims, {effect.name})",
                "atmosphere": {"rho_kg_m3": 1.225, "g_m_s2": 9.81},
                "mass_kg": 2200.0, "maneuvers": [], "conventions": conv.to_manifest()}
    return write_flight_test(folder, manifest, {}, pd.DataFrame(rows))


def test_trim_loop_names_an_independent_wake_effect(tmp_path):
    """Trims from M0 + the truth simulator's wake-on-tail effect E1 (flighttest.truth_effects, written
    independently of the candidate library), 0.1 deg seeded noise, root collective and unknown datum: the
    score test on the trim residuals accepts rotor_wake_on_tail, the second identification fits to the noise
    level and accepts nothing more, and the datum is recovered within its standard errors."""
    from pyomo_heli.flighttest.truth_effects import make_effect

    folder = _noisy_trims(tmp_path / "ds", make_effect("wake_on_tail"), K_lamT=1.5)
    doc = run_trim_loop(_config(tmp_path, folder, max_iterations=2), tmp_path / "out", progress=lambda *_: None)
    first, second = doc["iterations"][0], doc["iterations"][-1]
    assert first["score_test"]["decision"] == "accepted"
    assert first["score_test"]["accepted"] == "rotor_wake_on_tail"
    assert len(doc["iterations"]) == 2 and second["score_test"]["decision"] == "none"
    assert second["residual_sigma_deg"] < 0.15 < first["residual_sigma_deg"]  # noise 0.1 deg
    datum = second["parameters"][THETA_DATUM]
    assert abs(datum["value"] - 0.8 * DEG) < 3 * datum["se"]


def test_trim_loop_discovery_names_the_wake_by_encompassing_and_describes_a_held_out_download(tmp_path):
    """[loop] discovery on trims: the candidates and the generic family scored together (Bonferroni over all).
    The wake's trims: rotor_wake_on_tail is named because, with it fitted, the best generic term adds nothing; then
    nothing is left. A held-out fuselage download (not in the library): no physical candidate is added, and the
    best generic description of what is left is a download or nose-up moment (the truth's signs)."""
    from pyomo_heli.flighttest.held_out_effects import HELD_OUT_EFFECTS
    from pyomo_heli.flighttest.truth_effects import make_effect

    folder = _noisy_trims(tmp_path / "wake", make_effect("wake_on_tail"), K_lamT=1.5)
    doc = run_trim_loop(_config(tmp_path, folder, max_iterations=2, discovery=True), tmp_path / "o1",
                        progress=lambda *_: None)
    d0 = doc["iterations"][0]["score_test"]["discovery"]
    assert d0["decision"] == "named" and d0["added"] == "rotor_wake_on_tail", d0["message"]
    assert d0["encompassing"]["encompasses"] and d0["encompassing"]["p_generic_given_candidate"] >= 0.01
    assert len(doc["iterations"]) == 2 and doc["stopped"] == "discovery: none"
    assert doc["iterations"][0]["score_test"]["n_testable"] > 40  # the generic family was offered
    write_trim_report(_config(tmp_path, folder, discovery=True), doc, tmp_path / "o1")
    assert "structure determination over the candidates and the generic discrepancy family: **named**" in \
        (tmp_path / "o1" / "report.md").read_text()

    folder = _noisy_trims(tmp_path / "fd", HELD_OUT_EFFECTS["fuselage_download"](), k_fd=0.03)
    doc = run_trim_loop(_config(tmp_path, folder, max_iterations=1, discovery=True), tmp_path / "o2",
                        progress=lambda *_: None)
    d = doc["iterations"][-1]["score_test"]["discovery"]
    assert not [e for e in doc["iterations"][-1]["extensions"] if e in CANDIDATES]  # no wrong acceptance
    g = d["best_generic"]
    assert g["name"][:2] in ("dZ", "dM") and g["kappa_hat"] > 0, d["message"]  # down / nose-up


def test_trim_loop_name_check_withdraws_a_named_candidate_that_leaves_a_generic_term(tmp_path, monkeypatch):
    """The name check on trims. The wake's trims: the wake is named at iteration 0, and at iteration 1 (M0 + wake)
    the real decision finds no generic term significant, so the name would stand. The test's stand-in then marks a
    generic term significant there: iteration 1 is rejected, and iteration 2 starts again from M0 without the wake
    on offer; the report's "after" is the model kept."""
    import pyomo_heli.workflows.trim_loop as tl
    from pyomo_heli.flighttest.truth_effects import make_effect

    real, seen = tl.discovery_decision, []

    def decide(score, generic_p_given, alpha):
        out = real(score, generic_p_given, alpha)
        if any(r["name"] == "rotor_wake_on_tail" for r in score["scores"]):
            return out
        seen.append(out["generic_significant"])
        return {**out, "generic_significant": True}  # the stand-in, at the model holding the wake

    monkeypatch.setattr(tl, "discovery_decision", decide)
    folder = _noisy_trims(tmp_path / "wake", make_effect("wake_on_tail"), K_lamT=1.5)
    cfg = _config(tmp_path, folder, max_iterations=2, discovery=True)
    doc = run_trim_loop(cfg, tmp_path / "o", progress=lambda *_: None)
    its = doc["iterations"]
    assert its[0]["score_test"]["discovery"]["added"] == "rotor_wake_on_tail"
    assert seen[0] is False  # the real decision at M0 + wake: nothing generic left
    assert its[1]["extensions"] == ["rotor_wake_on_tail"] and "name check" in its[1]["rejected"]
    assert its[2]["extensions"] == [] and not its[2].get("rejected")
    assert "rotor_wake_on_tail" not in [r["name"] for r in its[2]["score_test"]["scores"]]
    assert its[2]["J_trim_float"] == pytest.approx(its[0]["J_trim_float"], rel=1e-6)  # M0 again
    assert doc["final_iteration"] == 2
    write_trim_report(cfg, doc, tmp_path / "o")
    assert "**Rejected**: name check" in (tmp_path / "o" / "report.md").read_text()


def test_maneuver_identification_refuses_trim_rows_with_empty_channels(tmp_path):
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.nlp.identification import identification_data

    ds = tmp_path / "ds"
    shutil.copytree(ROOT / "data" / "bo105_clean", ds)
    _cell(ds, 2, {"lon_deg": ""})
    assert load_flight_test(ds).trim_counts()["lon"] == len(load_flight_test(ds).trims) - 1
    cfg_path = tmp_path / "c.toml"
    cfg_path.write_text((ROOT / "tests" / "configs" / "case1.toml").read_text().replace(
        'dataset = "../../data/bo105_synthetic"', f'dataset = "{ds}"'))
    with pytest.raises(ValueError, match=r"trims.csv: rows \[2\] leave a trim channel empty"):
        identification_data(load_identification_config(cfg_path))


def test_a_parameter_the_trims_do_not_see_has_an_infinite_standard_error(tmp_path):
    """The trim-only standard errors with a free parameter no trim depends on (the inflow time constant): its
    standard error is infinite and the condition number too, and the others' are those of the fit without it (a
    least-squares inverse would drop the blind direction and report a standard error of about zero)."""
    from pyomo_heli.nlp.trim_identification import standard_errors

    ft = load_flight_test(_generated(tmp_path / "ds"))
    pts = trim_points(ft)
    model = HelicopterModel(extensions=(TrimOutputDatum(),)).with_parameters(**TRUTH)
    alone = standard_errors(model, ft.conventions, pts, ["a", "f_e"])
    blind = standard_errors(model, ft.conventions, pts, ["a", "f_e", "tau_lambda"])
    assert blind["se"]["tau_lambda"] == math.inf and blind["cond"] == math.inf
    for n in ("a", "f_e"):  # the same inverse; the residual variance counts one parameter more
        scale = math.sqrt(alone["dof"] / blind["dof"])
        assert blind["se"][n] == pytest.approx(alone["se"][n] * scale, rel=1e-6), n
    assert math.isfinite(alone["cond"]) and all(math.isfinite(v) for v in alone["se"].values())


def test_the_rms_without_conventions_leaves_out_a_datum_the_manifest_gives(tmp_path):
    """A manifest that gives the pitch datum as a number (2 deg) makes it a model parameter, which the recorded trim
    adds whatever the conventions say: the 'without conventions' RMS kept it. It is now the data against the start
    model's body-axis theta, recomputed here from single float trims at the theta points' speeds."""
    folder = _generated(tmp_path / "ds", TrimConventions(collective_station=0.0, theta_datum=2 * DEG))
    doc = run_trim_loop(_config(tmp_path, folder, holdout_every=3, max_iterations=0), tmp_path / "out",
                        progress=lambda *_: None)
    pts = pd.DataFrame(doc["points"])
    m0 = HelicopterModel()
    for role in ("identification", "validation"):
        sel = pts[(pts.channel == "theta") & (pts.role == role)]
        body = np.array([trim_float(m0, v * KT).theta / DEG for v in sel.speed_kt])
        expected = float(np.sqrt(np.mean((sel.value_deg.to_numpy() - body) ** 2)))
        got = doc["initial"]["rms_deg_without_conventions"][role]["theta"]
        assert got == pytest.approx(expected, rel=1e-6), role
        assert abs(got - doc["initial"]["rms_deg"][role]["theta"]) > 0.5  # the datum's 2 deg is what differs


def test_the_report_shows_a_missing_shape_value_as_a_dash(tmp_path):
    """A channel with a single trim point has no step, no means around it and no trend: the report's remaining-
    residual row shows "-" there, not +0.00 (a review: a missing value read as zero); the score table's estimate is
    labelled SI."""
    import numpy as np
    import pandas as pd

    from pyomo_heli.diagnosis.trim_attribution import residual_shape
    from pyomo_heli.report.trim_loop import write_trim_loop_report
    from pyomo_heli.units import KT

    pts = pd.DataFrame({"channel": ["col", "lon", "lon", "theta", "theta"], "V": np.array([40, 20, 60, 20, 60]) * KT,
                        "role": ["identification"] * 5})
    e = np.array([0.5, 0.1, -0.3, 0.2, 0.4])
    shape = residual_shape(pts, e)
    rms = {"identification": {"col": 0.5, "lon": 0.2, "theta": 0.3}, "validation": {}}
    it = {"iteration": 0, "extensions": [], "solve": {"J_trim": 1.0, "status": "ok", "iterations": 3},
          "J_trim_float": 1.0, "residual_sigma_deg": 0.5, "dof": 2, "parameters": {},
          "score_test": {"n_testable": 0, "level": 0.01, "decision": "none", "message": "-", "scores": []},
          "rms_deg": rms, "residual_shape": shape, "model_deg": [0.0] * 5}
    flat = {"speed_kt": [0, 80], "col": [0, 0], "lon": [0, 0], "theta": [0, 0]}
    doc = {"points": {"channel": list(pts.channel), "role": list(pts.role), "speed_kt": list(pts.V / KT),
                      "value_deg": list(e)},
           "curves": {"before": flat, "after": flat},
           "initial": {"model_deg": [0.0] * 5, "rms_deg": rms, "rms_deg_without_conventions": rms},
           "iterations": [it], "final_iteration": 0, "aircraft": "x", "dataset": "d", "front": "f",
           "conventions": {"collective_station": None, "model_r_ref": 0.7, "lon_sign": 1,
                           "theta_datum_estimated": False, "theta_datum_deg": 0.0}, "mass_kg": 2200,
           "rho_kg_m3": 1.225,
           "counts": {"identification": {"col": 1, "lon": 2, "theta": 2}, "validation": {"col": 0, "lon": 0,
                                                                                         "theta": 0}},
           "holdout_every": 0, "stopped": "x"}
    text = write_trim_loop_report(doc, "c.toml", tmp_path).read_text()
    col = next(ln for ln in text.splitlines() if ln.startswith("| col | 0.500"))
    assert col == "| col | 0.500 | - | - | - / - | - |", col
    lon = next(ln for ln in text.split("## Remaining residual", 1)[1].splitlines() if ln.startswith("| lon |"))
    assert "- / -" not in lon  # two points: a step and its means
    assert "| estimate [SI] |" in text
