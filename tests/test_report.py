"""Tests of the identification report (pyomo_heli.report): figures, tables, metrics, failure handling.

A fake result folder (written with IdentificationResult.save) is paired with a tiny copy of
bo105_clean (one identification and one validation maneuver cut to 3 s, five trim points), so
no NLP is solved. The time-domain point A is put exactly at the truth parameters: its validation
and trim RMS must then be ~0, an independent check that the report's float-model simulations
replicate the data generator.
"""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pyomo_heli.config import load_identification_config
from pyomo_heli.dataset import FlightTest, load_flight_test, write_flight_test
from pyomo_heli.pareto.result import IdentificationResult
from pyomo_heli.report import identification as rep
from pyomo_heli.report import plots
from pyomo_heli.simulation import replay
from pyomo_heli.units import KT

ROOT = Path(__file__).resolve().parents[1]
CLEAN = ROOT / "data" / "bo105_clean"
DEG = math.pi / 180.0
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
FILES = ("pareto_front.png", "trim_vs_speed.png", "validation.png", "parameters.md", "parameters.csv",
         "metrics.json", "report.md")
VAL = "londoublet_80kt_val"


def _truth() -> dict:
    return json.loads((CLEAN / "truth.json").read_text())["parameters"]


def _tiny_dataset(path: Path, truth: bool) -> Path:
    """bo105_clean with one identification and one validation maneuver cut to 3 s and five trims."""
    ft = load_flight_test(CLEAN)
    mans = {}
    for name in ("lon3211_80kt_a", VAL):
        mv = ft.maneuvers[name]
        mv.data = mv.data[mv.data["t"] <= 3.0 + 1e-9].reset_index(drop=True)
        mv.file = ""
        mans[name] = mv
    trims = ft.trims
    level = trims[trims["source"] == "level"]
    keep = pd.concat([level[(level["V"] / KT).round(6).isin([10.0, 40.0, 80.0, 120.0])],
                      trims[trims["source"] == "lon3211_80kt_a"]]).reset_index(drop=True)
    tiny = FlightTest(aircraft=ft.aircraft, mass=ft.mass, rho=ft.rho, g=ft.g, maneuvers=mans, trims=keep,
                      description="tiny copy of bo105_clean for the report tests")
    write_flight_test(path, tiny)
    if truth:
        shutil.copy(CLEAN / "truth.json", path / "truth.json")
    return path


def _point(index, kind, J_time, J_trim, twist, cl, eps=None, success=True, iterations=20, cold=None):
    return {"cold_iterations": cold, "cold_wall_time": None if cold is None else 3.0, "index": index, "kind": kind,
            "epsilon": eps, "J_time": J_time, "J_trim": J_trim, "success": success,
            "status": "Solve_Succeeded" if success else "Infeasible_Problem_Detected", "iterations": iterations,
            "wall_time": 1.5, "setup_time": 0.0, "warm_start": "primal",
            "parameters": {"theta_twist": twist, "CL_alpha_HT": cl}}


def _fake_result(out: Path) -> IdentificationResult:
    """A front from A (at the truth) to B, with one failed interior point; C is front point 1."""
    t = _truth()
    tw, cl = t["theta_twist"], t["CL_alpha_HT"]
    pts = [_point(0, "A", -500.0, 4.0e-3, tw, cl, eps=math.inf, iterations=60),
           _point(1, "eps", -498.0, 1.0e-3, tw * 1.03, cl * 0.97, eps=2e-3, iterations=12, cold=30),
           _point(2, "eps", -496.0, 5.0e-4, tw * 1.06, cl * 0.95, eps=1e-3, success=False, iterations=30, cold=40),
           _point(3, "eps", -493.0, 3.0e-4, tw * 1.08, cl * 0.93, eps=5e-4, iterations=9, cold=29),
           _point(4, "B", -480.0, 2.0e-4, tw * 1.12, cl * 0.90, eps=2.5e-4, iterations=15)]
    rows = []
    for p in pts:
        r = {k: v for k, v in p.items() if k != "parameters"}
        r["epsilon"] = math.inf if p["epsilon"] is None else p["epsilon"]
        rows.append({**r, **p["parameters"]})
    front = pd.DataFrame(rows)
    front["utopia_distance"] = np.nan
    chosen = {**pts[1], "epsilon": 2e-3}
    direct = _point(-1, "direct", -497.5, 1.1e-3, tw * 1.031, cl * 0.969, iterations=40)
    res = IdentificationResult(front=front, parameters=["theta_twist", "CL_alpha_HT"],
                               units={"theta_twist": "rad/m", "CL_alpha_HT": "1/rad"},
                               utopia=(-500.0, 2.0e-4), nadir=(-480.0, 4.0e-3), chosen=chosen, direct=direct,
                               time_domain={**pts[0], "epsilon": None},
                               info={"maneuvers": ["lon3211_80kt_a"], "solver": "fake", "total_time": 1.0})
    res.save(out)
    return res


def _config(tmp: Path, dataset: Path) -> Path:
    f = tmp / "case.toml"
    f.write_text(f"""
[data]
dataset = "{dataset.as_posix()}"
maneuvers = ["lon3211_80kt_a"]

[parameters.theta_twist]
unit = "deg/m"
initial = -2.1228
lower = -10.0
upper = 0.0

[parameters.CL_alpha_HT]
unit = "1/rad"
initial = 4.3516
lower = 0.1
upper = 10.0
""")
    return f


@pytest.fixture(scope="module")
def report_with_truth(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("with_truth")
    ds = _tiny_dataset(tmp / "data", truth=True)
    out = tmp / "out"
    _fake_result(out)
    cfg = load_identification_config(_config(tmp, ds))
    return rep.write_report(out, cfg), cfg


def test_report_files_exist_and_pngs_are_valid(report_with_truth):
    path, _ = report_with_truth
    out = path.parent
    assert path == out / "report.md"
    for name in FILES:
        f = out / name
        assert f.is_file() and f.stat().st_size > 0, name
        if name.endswith(".png"):
            assert f.read_bytes()[:8] == PNG_MAGIC, name
            assert f.stat().st_size > 10_000, name  # a real figure, not an empty canvas
    text = path.read_text()
    for name in ("pareto_front.png", "trim_vs_speed.png", "validation.png", "parameters.md"):
        assert f"({name})" in text
    assert "Mean iterations per interior front point: 17" in text  # (12 + 30 + 9) / 3
    assert "mean iterations warm 17, cold 33 (ratio warm/cold 0.515" in text  # (30 + 40 + 29) / 3
    assert "None: every trim and simulation succeeded." in text
    assert VAL in text


def test_parameter_table_has_truth_and_display_units(report_with_truth):
    path, _ = report_with_truth
    tab = pd.read_csv(path.parent / "parameters.csv")
    assert list(tab["unit"]) == ["deg/m", "1/rad"]
    assert "truth" in tab.columns and "multi-objective error %" in tab.columns
    tw = tab.set_index("parameter").loc["theta_twist"]
    assert tw["truth"] == pytest.approx(_truth()["theta_twist"] / DEG)
    assert tw["time-domain"] == pytest.approx(tw["truth"])  # A sits at the truth
    assert tw["time-domain error %"] == pytest.approx(0.0, abs=1e-9)
    assert tw["multi-objective error %"] == pytest.approx(-3.0)  # 3 % more twist (negative)
    assert tw["initial"] == pytest.approx(-2.1228)
    assert "| truth |" in (path.parent / "parameters.md").read_text()


def test_truth_parameters_replicate_the_data(report_with_truth):
    """At the truth, the report's float-model trims and simulations reproduce bo105_clean (SI RMS < 1e-6)."""
    path, cfg = report_with_truth
    m = json.loads((path.parent / "metrics.json").read_text())
    assert m["validation_maneuvers"] == [VAL]
    a = m["validation_rms"][rep.TIME_DOMAIN]
    for o in rep.VALIDATION_OUTPUTS:
        assert a[VAL][o] < 1e-6, o
    for c in rep.TRIM_CHANNELS:
        assert m["trim_rms"][rep.TIME_DOMAIN]["all"][c] < 1e-6, c
    # the multi-objective point is 3 % off the truth: visibly non-zero errors
    assert m["validation_rms"][rep.MULTI_OBJECTIVE][VAL]["theta"] > 1e-5
    assert m["trim_rms"][rep.MULTI_OBJECTIVE]["all"]["col"] > 1e-4
    # the same check straight through the API, with the full truth parameter table
    ft = load_flight_test(cfg.dataset)
    pred = rep.predict("truth", cfg.model, _truth(), ft.trims["V"], ft.validation())
    assert pred.problems == []
    rms = rep.validation_rms(pred, ft.validation())
    assert max(rms["all"].values()) < 1e-6


def test_no_truth_column_without_truth_json(tmp_path):
    ds = _tiny_dataset(tmp_path / "data", truth=False)
    out = tmp_path / "out"
    res = _fake_result(out)
    cfg = load_identification_config(_config(tmp_path, ds))
    tab = rep.parameter_table(res, cfg, rep.read_truth(cfg.dataset))
    assert rep.read_truth(cfg.dataset) is None
    assert not any("truth" in c or "error" in c for c in tab.columns)
    assert list(tab.columns) == ["parameter", "unit", "initial", "time-domain", "multi-objective", "Eq. 11 direct"]


def test_failed_simulation_is_reported_not_raised(tmp_path, monkeypatch):
    ds = _tiny_dataset(tmp_path / "data", truth=False)
    out = tmp_path / "out"
    res = _fake_result(out)
    cfg = load_identification_config(_config(tmp_path, ds))
    real = replay.simulate_states
    bad = res.chosen["parameters"]["CL_alpha_HT"]

    def flaky(model, *args, **kw):  # the multi-objective model "diverges"
        if model.parameters["CL_alpha_HT"] == bad:
            raise RuntimeError("simulation failed: Required step size is less than spacing between numbers.")
        return real(model, *args, **kw)

    monkeypatch.setattr(replay, "simulate_states", flaky)
    path = rep.write_report(out, cfg)
    text = path.read_text()
    assert f"multi-objective (C): maneuver {VAL}: simulation failed" in text
    assert "| multi-objective (C) | " + VAL + " | failed |" in text
    assert "| truth |" not in text and "truth" not in (out / "parameters.md").read_text()
    m = json.loads((out / "metrics.json").read_text())
    assert m["validation_rms"][rep.MULTI_OBJECTIVE][VAL] is None
    assert m["validation_rms"][rep.TIME_DOMAIN][VAL]["q"] < 1e-6
    assert (out / "validation.png").read_bytes()[:8] == PNG_MAGIC


def test_diverging_simulation_is_cut_short(tmp_path):
    """A model whose response leaves the plausible range is stopped there and reported as diverged."""
    ft = load_flight_test(_tiny_dataset(tmp_path / "data", truth=False))
    mv = ft.maneuvers[VAL]
    mv.data = mv.data.assign(lon=mv.data["lon"] + np.where(mv.data["t"] > 0.5, 20 * DEG, 0.0))  # 20 deg step
    from pyomo_heli.physics.model import HelicopterModel

    pred = rep.predict("stepped", HelicopterModel(), {}, [], [mv])
    assert pred.maneuvers[VAL] is None and VAL in pred.partial
    assert "diverged" in pred.problems[0]
    part = pred.partial[VAL]
    assert 0.5 < part["t"].iloc[-1] < 3.0
    assert rep.validation_rms(pred, [mv])[VAL] is None


def test_plot_functions_return_figures():
    front = pd.DataFrame({"kind": ["A", "eps", "B"], "J_time": [0.0, 1.0, 3.0], "J_trim": [2.0, 0.5, 0.0],
                          "success": [True, True, True]})
    fig = plots.plot_pareto_front(front, (0.0, 0.0), (3.0, 2.0), {"J_time": 1.0, "J_trim": 0.5}, None)
    assert len(fig.axes) == 2
    trims = pd.DataFrame({"V": [0.0, 20.0], "col": [0.1, 0.09], "lon": [0.0, -0.02], "theta": [0.05, 0.03]})
    fig = plots.plot_trim_vs_speed(trims, {"m": trims})
    assert len(fig.axes) == 3
    fig = plots.plot_validation({}, {"m": {}})
    assert fig.axes


def test_a_report_names_a_dataset_inside_the_working_directory_by_its_relative_path(tmp_path, monkeypatch):
    """Committed reports name data/... rather than the folder of the machine that wrote them."""
    from pyomo_heli.report.identification import shown_path

    (tmp_path / "data" / "flight").mkdir(parents=True)
    monkeypatch.chdir(tmp_path)
    assert shown_path(tmp_path / "data" / "flight") == str(Path("data") / "flight")
    assert shown_path("/elsewhere/flight") == "/elsewhere/flight"
