"""Do the records agree on each output's bias (diagnosis/record_bias.py)?

The chi-square is checked against hand-computed values; on the bundled flight test the exact model at the
true parameters passes it, and an airspeed reading that is 3 kt high in the slow records only (a position
error of the probe) is found by it, although the innovations stay white.
"""
from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from pyomo_heli.config import load_identification_config
from pyomo_heli.diagnosis.analysis import diagnose
from pyomo_heli.diagnosis.record_bias import record_bias_tests
from pyomo_heli.diagnosis.residuals import compute_residuals
from pyomo_heli.flighttest.generate import truth_model_of
from pyomo_heli.units import KT

ROOT = Path(__file__).resolve().parent.parent
EIV = ROOT / "tests" / "configs" / "close_loop_eiv.toml"
MANEUVERS = ["lon3211_80kt_a", "lon3211_80kt_b", "londoublet_20kt_a", "londoublet_20kt_b"]


def test_chi_square_by_hand():
    rows = [{"trim_speed": 10.0, "bias_TAS": 0.0, "se_bias_TAS": 0.5},
            {"trim_speed": 40.0, "bias_TAS": 1.0, "se_bias_TAS": 0.5},
            {"trim_speed": 40.0, "bias_TAS": 2.0, "se_bias_TAS": 1.0}]
    t = record_bias_tests(rows, alpha=0.01)["TAS"]
    w = np.array([4.0, 4.0, 1.0])
    b = np.array([0.0, 1.0, 2.0])
    common = (w @ b) / w.sum()  # 6 / 9
    assert t.common == pytest.approx(common)
    assert t.chi2 == pytest.approx(float(w @ (b - common) ** 2))
    assert t.df == 2 and t.p == pytest.approx(stats.chi2.sf(t.chi2, 2))
    # per speed: the weighted mean of the records flown there, against the common mean
    at40 = next(r for r in t.by_speed if r["V"] == 40.0)
    assert at40["shift"] == pytest.approx((4 * 1.0 + 1 * 2.0) / 5 - common)
    assert at40["se"] == pytest.approx(np.sqrt(1 / 5)) and at40["records"] == 2
    # equal biases agree whatever their size (a sensor bias is no model error)
    same = record_bias_tests([{"trim_speed": v, "bias_q": 3.0, "se_bias_q": 0.1} for v in (10.0, 20.0)])["q"]
    assert same.chi2 == pytest.approx(0.0) and same.consistent
    # the level is Bonferroni over the outputs tested
    two = record_bias_tests([{**r, "bias_q": 0.0, "se_bias_q": 1.0} for r in rows], alpha=0.01)
    assert two["q"].bound == pytest.approx(0.005) and two["TAS"].bound == pytest.approx(0.005)


def _residuals(dataset: Path):
    cfg = load_identification_config(EIV, overrides={"data": {"dataset": str(dataset)}})
    model = truth_model_of(dataset)
    cfg = dataclasses.replace(cfg, maneuvers=list(MANEUVERS), validation=[], model=model)
    return compute_residuals(cfg, model.parameters.to_dict(), label="truth", trim_sensitivities=False)


@pytest.fixture(scope="module")
def pitot_error(tmp_path_factory):
    """The exact model's residuals on the bundled flight test with its airspeed 3 kt high in the 20 kt records
    (nothing else changed)."""
    ds = tmp_path_factory.mktemp("data") / "bo105_synthetic"
    shutil.copytree(ROOT / "data" / "bo105_synthetic", ds)
    for name in ("londoublet_20kt_a", "londoublet_20kt_b"):
        f = ds / "maneuvers" / f"{name}.csv"
        df = pd.read_csv(f)
        df["tas_kt"] += 3.0
        df.to_csv(f, index=False)
    return _residuals(ds)


def test_exact_model_records_agree():
    d = diagnose(_residuals(ROOT / "data" / "bo105_synthetic"))
    assert d.verdict["record_biases_agree"] and d.verdict["noise_only"], d.findings
    assert set(d.record_biases) == {"q", "theta", "n_x", "n_z", "TAS", "beta_0"}
    assert all(t["df"] == 3 for t in d.record_biases.values())


def test_a_speed_dependent_airspeed_error_is_found_where_whiteness_is_blind(pitot_error):
    d = diagnose(pitot_error)
    assert all(w["white"] for w in d.whiteness), d.whiteness  # constant within a record: whiteness cannot see it
    assert not d.verdict["record_biases_agree"] and not d.verdict["noise_only"]
    bad = {o for o, t in d.record_biases.items() if not t["consistent"]}
    assert bad == {"TAS"}, d.record_biases
    by = {round(r["V"] / KT): r for r in d.record_biases["TAS"]["by_speed"]}
    # residual = model - data: the slow records' bias is lower by the 3 kt added to their data
    diff = by[20]["shift"] - by[80]["shift"]
    se = np.hypot(by[20]["se"], by[80]["se"])
    assert abs(diff + 3.0 * KT) < 4 * se, (diff, se)
    assert any(f.startswith("record biases of TAS differ") for f in d.findings)
    assert not d.verdict["noise_only"]


def test_the_report_shows_the_records_that_disagree(pitot_error, tmp_path):
    from pyomo_heli.report.diagnosis import write_diagnosis_report

    text = write_diagnosis_report(tmp_path, pitot_error, diagnose(pitot_error)).read_text()
    assert "### Record biases" in text
    assert "TAS: residual bias (model - data) of the records at each trim speed against their mean" in text
    assert "theta: residual bias" not in text  # only the output whose records disagree
    # the common bias in each output's display unit, labelled (a review: it was SI, rad beside deg, unlabelled)
    from pyomo_heli.diagnosis.residuals import DISPLAY

    d = diagnose(pitot_error)
    for o, t in d.record_biases.items():
        unit, fac = DISPLAY[o]
        section = text.split("### Record biases", 1)[1].splitlines()
        row = next(ln for ln in section if ln.startswith(f"| {o} |"))
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert float(cells[cells.index(unit) - 1]) == pytest.approx(t["common"] * fac, rel=2e-3, abs=1e-12), row


def test_level_study_writes_each_seed_and_resumes(tmp_path):
    """The level study (pyomo_heli.studies.record_bias_level) on one seed of the small held-out flight test (three
    records): one test per output on 2 df, its p the chi-square's; the seed's data are removed once it is done, and
    a rerun reads the seed back."""
    from pyomo_heli.studies.record_bias_level import main

    argv = ["--seeds", "7", "--config", str(ROOT / "studies" / "held_out_small.toml"),
            "--data-config", str(ROOT / "studies" / "held_out_small_gen.toml"), "--out", str(tmp_path)]
    assert main(argv) == 0
    import json

    doc = json.loads((tmp_path / "seed_7.json").read_text())
    assert doc["records"] == 3 and set(doc["tests"]) == {"q", "theta", "n_x", "n_z", "TAS", "beta_0"}
    for t in doc["tests"].values():
        assert t["df"] == 2 and t["p"] == pytest.approx(stats.chi2.sf(t["chi2"], 2))
    assert not (tmp_path / "data").exists()
    summary = pd.read_csv(tmp_path / "summary.csv")
    assert list(summary["output"])[-1] == "all" and int(summary["tests"].iloc[-1]) == 6
    (tmp_path / "seed_7.json").write_text(json.dumps({**doc, "records": 99}))
    assert main(argv) == 0 and "(99 records each" in (tmp_path / "summary.md").read_text()


def test_the_shape_table_lists_each_speed_in_display_units():
    """report.diagnosis.record_bias_shapes (the diagnosis report and the loop report's residual analysis): only the
    outputs whose records disagree, each speed in kt with its bias in the output's display unit."""
    from pyomo_heli.report.diagnosis import record_bias_shapes

    rows = [{"trim_speed": v * KT, "bias_theta": b, "se_bias_theta": 1e-4, "bias_q": 0.0, "se_bias_q": 1e-3}
            for v, b in ((20, 0.0), (80, 0.01))]
    tests = {o: t.to_dict() for o, t in record_bias_tests(rows).items()}
    text = "\n".join(record_bias_shapes(tests))
    assert "theta: residual bias" in text and "q: residual bias" not in text
    # equal standard errors: each speed is 0.01 rad / 2 = 0.286 deg off the mean; SE 1e-4 rad = 0.00573 deg
    assert "| 20 | -0.286 | 0.00573 | 1 |" in text and "| 80 | 0.286 | 0.00573 | 1 |" in text
