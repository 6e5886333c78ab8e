"""The residual diagnosis on identification results with a known truth.

Independent reference: the data generator's truth.

- tests/results/case1 (a copy of the committed Case 1 run, docs/results/case1) was identified with M0 on
  data/bo105_synthetic, whose truth is
  M0 + the rotor wake on the tail (E1): a trim signature over 10-50 kt of lon lower and theta
  higher than M0 (model_spec.md section 4, E1), i.e. a model-minus-data residual that is a
  positive lon bump and a negative theta bump at low speed, absent in hover and above ~55 kt,
  and a time-series signature at 20 kt (q, theta). The diagnosis must name a low-speed bump.
- tests/results/m0_noise_small (committed, made by the command in tests/configs/m0_noise_small.toml)
  was identified on tests/data/m0_noise_small, generated from M0 itself with sensor noise only
  (tests/configs/gen_m0_noise_small.toml): nothing is missing, so the diagnosis must say noise only
  and the identification residuals must pass the whiteness test.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from pyomo_heli.cli import main
from pyomo_heli.config import load_identification_config
from pyomo_heli.diagnosis.analysis import Diagnosis, diagnose
from pyomo_heli.diagnosis.residuals import Residuals, compute_residuals, find_config
from pyomo_heli.pareto.result import IdentificationResult
from pyomo_heli.units import KT

ROOT = Path(__file__).resolve().parents[1]
CASE1 = ROOT / "tests" / "results" / "case1"
M0_NOISE = ROOT / "tests" / "results" / "m0_noise_small"


@pytest.fixture(scope="module")
def case1():
    res = IdentificationResult.load(CASE1)
    return res, load_identification_config(find_config(CASE1, res))


def test_wake_on_tail_trim_residual_is_named_a_low_speed_bump(case1):
    res, cfg = case1
    r = compute_residuals(cfg, res.chosen["parameters"], "C", roles=(), input_offsets=False)
    d = diagnose(r, n_mc=2000)
    assert not d.verdict["noise_only"]
    lon, theta = d.shape("lon"), d.shape("theta")
    # lon: a bump beyond what twist and CL_alpha_HT can absorb, centred where E1 acts (10-50 kt),
    # model above data (the truth's lon is lower than M0 there)
    assert lon.structured and "bump" in lon.shape and lon.nuisance == ["CL_alpha_HT", "theta_twist"]
    assert 10 <= lon.fit["centre"] / KT <= 50 and lon.fit["amplitude"] > 0
    # theta: structured and containing a bump; the residual beyond the parameter shift is negative
    # (model below data) over 15-50 kt, where the truth's theta is higher than M0
    assert theta.structured and "bump" in theta.shape
    low = [a for v, a in zip(theta.V, theta.adjusted) if 15 * KT <= v <= 50 * KT]
    assert sum(low) / len(low) < -0.3 * 3.14159 / 180
    assert d.shape("lon").runs["z"] < -2.5  # few sign runs along speed: neighbouring speeds agree


def test_wake_on_tail_time_signature_at_20kt_is_not_white(case1):
    res, cfg = case1
    cfg20 = load_identification_config(cfg.path, {"data": {"maneuvers": ["londoublet_20kt_a"]}})
    r = compute_residuals(cfg20, res.chosen["parameters"], "C", roles=("identification",), trim_sensitivities=False)
    d = diagnose(r, n_mc=200)
    w = d.table("whiteness").set_index("output")
    assert not w.loc["q", "white"] and not w.loc["theta", "white"]
    assert d.verdict["white_identification"] is False


def test_m0_noise_only_result_is_diagnosed_noise_only_via_the_cli(tmp_path, capsys):
    assert main(["diagnose", str(M0_NOISE), "--out", str(tmp_path)]) == 0
    for f in ("diagnosis.json", "diagnosis.md", "diagnosis_trim.png", "diagnosis_spectra.png",
              "diagnosis_coherence.png", "diagnosis_time.png"):
        assert (tmp_path / f).is_file(), f
    d = Diagnosis.load(tmp_path / "diagnosis.json")
    assert d.verdict["noise_only"] is True
    assert d.verdict["trim_shape"] == {"col": "noise", "lon": "noise", "theta": "noise"}
    assert d.verdict["white_identification"] is True
    # the saved residuals reload and give the same RMS as the diagnosis recorded
    r = Residuals.load(tmp_path / "residuals_chosen")
    # time.csv.gz keeps 10 digits
    assert r.rms()["rms"].tolist() == pytest.approx([row["rms"] for row in d.rms], rel=1e-6)
    md = (tmp_path / "diagnosis.md").read_text()
    assert "noise only" in md and "![trim residuals](diagnosis_trim.png)" in md
    assert "residuals look like noise only" in capsys.readouterr().out


def test_diagnose_bad_input_is_one_line_exit_2(tmp_path, capsys):
    assert main(["diagnose", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "front.csv" in err and len(err.strip().splitlines()) == 1
    assert main(["diagnose", str(M0_NOISE), "--alpha", "2"]) == 2
    assert "--alpha" in capsys.readouterr().err
    res = IdentificationResult.load(M0_NOISE)
    res.info = {**res.info, "config": "nowhere.toml"}
    res.save(tmp_path / "r")
    assert main(["diagnose", str(tmp_path / "r")]) == 2
    assert "info.config" in capsys.readouterr().err


@pytest.mark.slow
def test_committed_case1_diagnosis_regenerates(tmp_path):
    """docs/results/case1_diagnosis is what its command produces (about 40 s: a slow regeneration check), with the
    committed study config (its residuals against the resampled inputs' replay, as the committed diagnosis was
    made; the test fixture's copy of it takes the default record-rate replay)."""
    assert main(["diagnose", str(CASE1), "--config", str(ROOT / "studies" / "case1.toml"), "--out", str(tmp_path),
                 "--no-residuals"]) == 0
    new = Diagnosis.load(tmp_path / "diagnosis.json")
    old = Diagnosis.load(ROOT / "docs" / "results" / "case1_diagnosis" / "diagnosis.json")
    assert new.verdict == old.verdict
    for c, t in old.trim_shapes.items():
        assert new.trim_shapes[c]["p_values"] == t["p_values"]
        for k, v in t["fit"].items():
            assert new.trim_shapes[c]["fit"][k] == pytest.approx(v, rel=1e-6, abs=1e-12)
    assert [w["p"] for w in new.whiteness] == pytest.approx([w["p"] for w in old.whiteness], rel=1e-4, abs=1e-30)


GEN_TRIMS_ONLY = """[dataset]
name = "{name}"
aircraft = "Bo-105 (synthetic: M0 + {name})"
seed = 7
[truth]
parameters = {{}}
[truth.effects.{name}]
{param} = {value}
[sensors]
noise = true
[trims]
speeds_kt = [10, 15, 20, 25, 30, 40, 50, 60, 70, 80, 90, 100, 110, 120]
[[maneuvers]]
name = "lon_step_80kt"
role = "identification"
speed_kt = 80
channel = "lon"
shape = "doublet"
amplitude_deg = 0.2
step_s = 0.5
duration_s = 2
t_start_s = 1
"""


@pytest.mark.parametrize("name, param, value, lon, theta", [
    ("cg_offset", "dx_cg", 0.10, "constant", "constant"),  # 10 cm: moves lon and the attitude
    ("lon_rigging", "delta_lon", 0.3 * 3.141592653589793 / 180, "constant", "noise"),  # 0.3 deg: lon only
])
def test_trim_shapes_tell_a_cg_offset_from_a_rigging_bias(tmp_path, name, param, value, lon, theta):
    """Generated trims with one undeclared offset-type effect: constant lon residual in both, a constant
    theta residual only for the CG offset (model_spec.md section 4, E4). M0 at the nominal values of the
    Case 1 parameters, whose shift the test allows."""
    from pyomo_heli.flighttest.generate import generate_from_file

    gen = tmp_path / "gen.toml"
    gen.write_text(GEN_TRIMS_ONLY.format(name=name, param=param, value=value))
    generate_from_file(gen, tmp_path / "data")
    cfg = load_identification_config(ROOT / "tests" / "configs" / "m0_noise_small.toml",
                                     {"data": {"dataset": str(tmp_path / "data")}})
    nominal = {p.name: cfg.model.parameters[p.name] for p in cfg.free}
    r = compute_residuals(cfg, nominal, name, roles=(), input_offsets=False)
    d = diagnose(r, n_mc=2000)
    assert d.verdict["trim_shape"] == {"col": "noise", "lon": lon, "theta": theta}
    assert "V^2" in d.shape("lon").absorbed  # twist and tail lift slope make a V^2-like lon trend themselves


def test_a_verdict_whose_tests_could_not_run_is_not_noise_only():
    """The M0 + noise result (noise only when every test runs) with parts of its residual analysis made untestable:
    an identification record that was not replayed, an output with no data in a record (Ljung-Box p = NaN) or too few
    trims for a channel's shape test. Each leaves the verdict "not fully tested", naming what was not tested, never
    "noise only"."""
    import dataclasses

    import numpy as np

    from pyomo_heli.diagnosis.analysis import verdict_status

    res = IdentificationResult.load(M0_NOISE)
    cfg = load_identification_config(find_config(M0_NOISE, res))
    r = compute_residuals(cfg, res.chosen["parameters"], "C", roles=("identification",))
    d = diagnose(r, n_mc=500)
    assert d.verdict["noise_only"] is True and verdict_status(d.verdict) == "noise only"
    first = r.time["maneuver"].iloc[0]

    gone = dataclasses.replace(r, time=r.time[r.time["maneuver"] != first].reset_index(drop=True),
                               info={**r.info, "not_replayed": [{"maneuver": first, "role": "identification"}]})
    no_data = r.time.copy()
    no_data.loc[no_data["maneuver"] == first, "res_q"] = np.nan
    few = r.trim.iloc[:5].reset_index(drop=True)
    for case, bad in (("not replayed", gone), ("whiteness of q", dataclasses.replace(r, time=no_data)),
                      ("trim shape of", dataclasses.replace(r, trim=few))):
        v = diagnose(bad, n_mc=500).verdict
        assert v["noise_only"] is False and verdict_status(v) == "not fully tested", case
        assert any(case in u for u in v["untested"]), (case, v["untested"])
    # the tests that could not run are named, not counted as white (a review found "white in all 4 tests" when 3
    # ran, and a summary row "white" for an output never tested)
    d = diagnose(dataclasses.replace(r, time=no_data), n_mc=500)
    line = next(f for f in d.findings if f.startswith("identification maneuvers:"))
    n_ran = sum(1 for w in d.whiteness if w["role"] == "identification") - 1  # q of the first record: no p
    assert f"white in all {n_ran} tests" in line and "1 not tested" in line, line
    from pyomo_heli.diagnosis.analysis import summary_rows

    q_row = next(s for s in summary_rows(d) if s["data"] == "time (identification)" and s["channel"] == "q")
    assert q_row["verdict"].endswith("1 not tested") and q_row["verdict"] != "white", q_row


def test_a_record_whose_innovations_failed_is_untested_not_white():
    """Innovations (the input noise taken out) for q on every identification record but one, whose computation
    failed: that record has no whiteness test of q, so the verdict is "not fully tested" naming it, never "noise
    only" (a review: the record was left out of the table and of the verdict without a word)."""
    import dataclasses

    import numpy as np
    import pandas as pd

    from pyomo_heli.diagnosis.analysis import verdict_status

    res = IdentificationResult.load(M0_NOISE)
    cfg = load_identification_config(find_config(M0_NOISE, res))
    r = compute_residuals(cfg, res.chosen["parameters"], "C", roles=("identification",))
    names = list(dict.fromkeys(r.time["maneuver"]))
    rng = np.random.default_rng(5)
    frames = []
    for name in names[1:]:
        t = r.time.loc[r.time["maneuver"] == name, "t"].to_numpy()[::2]
        frames.append(pd.DataFrame({"maneuver": name, "role": "identification", "t": t,
                                    "inn_q": rng.standard_normal(t.size)}))
    inn = pd.concat(frames, ignore_index=True)
    rate = 1.0 / float(np.median(np.diff(frames[0]["t"])))
    ok = dataclasses.replace(r, innovations=inn, info={**r.info, "innovations": {
        "outputs": ["q"], "test_rate_hz": rate, "failed": []}})
    failed = dataclasses.replace(r, innovations=inn, info={**r.info, "innovations": {
        "outputs": ["q"], "test_rate_hz": rate, "failed": [{"maneuver": names[0], "role": "identification"}]}})
    assert verdict_status(diagnose(ok, n_mc=500).verdict) == "noise only"
    v = diagnose(failed, n_mc=500).verdict
    assert verdict_status(v) == "not fully tested"
    assert any(names[0] in u and "innovations failed" in u for u in v["untested"]), v["untested"]


def test_the_report_prints_the_identification_bound(tmp_path):
    """The report's "bound ... for identification" is alpha over the identification tests, not the smallest bound of
    both roles (a review found the validation role's, which has more tests)."""
    import re

    from pyomo_heli.report.diagnosis import write_diagnosis_report

    res = IdentificationResult.load(M0_NOISE)
    cfg = load_identification_config(find_config(M0_NOISE, res))
    import dataclasses

    import numpy as np

    r = compute_residuals(cfg, res.chosen["parameters"], "C")
    # one identification record, one of its outputs without data: fewer identification tests than validation ones
    t = r.time
    first = t.loc[t["role"] == "identification", "maneuver"].iloc[0]
    t = t[(t["role"] == "validation") | (t["maneuver"] == first)].reset_index(drop=True)
    t.loc[t["maneuver"] == first, "res_q"] = np.nan
    r = dataclasses.replace(r, time=t)
    d = diagnose(r, n_mc=200)
    n_id = sum(1 for w in d.whiteness if w["role"] == "identification" and w["p"] is not None and w["p"] == w["p"])
    n_val = sum(1 for w in d.whiteness if w["role"] == "validation")
    assert n_val > n_id > 0  # the case the old code got wrong
    text = write_diagnosis_report(tmp_path, r, d).read_text()
    got = float(re.search(r"bound ([0-9.e-]+) for identification", text).group(1))
    assert got == pytest.approx(d.settings["alpha"] / n_id, rel=0.01)
