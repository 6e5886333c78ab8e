"""Resuming a front or a multi-start (pyomo_heli.pareto.store, workflows.multistart): failures never stop a
sweep, nothing finished is lost.

All on a tiny Case 1 (one 80 kt maneuver cut to 2 s, noisy data, 4 front
points). The kill test runs the real command in a subprocess, SIGKILLs it once
the anchors and the first interior point are on disk, reruns the same command
and compares every number with an uninterrupted run of the same command.
"""
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pyomo_heli.config import load_identification_config
from pyomo_heli.workflows.identify import build_problem, run_identification
from pyomo_heli.workflows.multistart import MultistartResult, draw_starts, run_multistart
from pyomo_heli.nlp.identification import initialise_at
from pyomo_heli.pareto.front import ParetoSolver, _Snapshot
from pyomo_heli.pareto.store import PointStore, StoreMismatchError

HERE = Path(__file__).parent
ROOT = HERE.parent
TINY = HERE / "configs" / "tiny_case1_noisy.toml"
TIMING = ["wall_time", "setup_time", "cold_wall_time"]


def _cli(*args, **kw):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    return subprocess.Popen([sys.executable, "-m", "pyomo_heli", *map(str, args)], env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kw)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted run of the command."""
    out = tmp_path_factory.mktemp("uninterrupted")
    proc = _cli("identify", TINY, "--out", out, "--no-report")
    stdout, stderr = proc.communicate(timeout=600)
    assert proc.returncode == 0, stderr
    return out


def _numbers(out: Path):
    front = pd.read_csv(out / "front.csv").drop(columns=TIMING, errors="ignore")
    chosen = json.loads((out / "chosen.json").read_text())
    return front, {k: chosen[k] for k in ("chosen", "direct", "utopia", "nadir")}


def _strip_times(d):
    return {k: v for k, v in d.items() if k not in TIMING} if d else d


def test_killed_sweep_resumes_to_identical_results(reference, tmp_path):
    out = tmp_path / "killed"
    proc = _cli("identify", TINY, "--out", out, "--no-report")
    target = out / "points" / "eps001.npz"  # A, B and the first interior point are finished
    deadline = time.monotonic() + 600
    while not target.exists():
        assert proc.poll() is None, "the run ended before it could be killed"
        assert time.monotonic() < deadline
        time.sleep(0.005)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    finished = sorted(p.name for p in (out / "points").glob("*.npz"))
    assert "direct.npz" not in finished and not (out / "chosen.json").exists()  # really cut short
    assert len(finished) < 5  # A, B, eps001 (eps002 at most, if it finished in the last milliseconds)

    again = _cli("identify", TINY, "--out", out, "--no-report")
    stdout, stderr = again.communicate(timeout=600)
    assert again.returncode == 0, stderr
    assert stdout.count("(from disk)") == len(finished)
    assert "resuming:" in stdout

    f_res, c_res = _numbers(out)
    f_ref, c_ref = _numbers(reference)
    pd.testing.assert_frame_equal(f_res, f_ref, check_exact=True)
    for key in ("chosen", "direct"):
        assert _strip_times(c_res[key]) == _strip_times(c_ref[key]), key
    assert c_res["utopia"] == c_ref["utopia"] and c_res["nadir"] == c_ref["nadir"]


def test_changed_config_is_refused_unless_restart(reference, tmp_path):
    changed = tmp_path / "changed.toml"
    changed.write_text(TINY.read_text().replace("points = 4", "points = 5")
                       .replace("../../data", str(ROOT / "data")))
    proc = _cli("identify", changed, "--out", reference, "--no-report")
    _, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 2
    assert len(stderr.strip().splitlines()) == 1 and "--restart" in stderr and str(reference) in stderr
    # --restart discards the stored points (checked on the store itself: no second full run needed)
    store = PointStore(tmp_path / "s", "one")
    store.save("A", {"x": 1.0})
    with pytest.raises(StoreMismatchError, match="--restart"):
        PointStore(tmp_path / "s", "two")
    assert PointStore(tmp_path / "s", "two", restart=True).keys() == []


def test_failed_interior_point_is_recorded_and_the_sweep_goes_on(reference, tmp_path, monkeypatch):
    """Point 1 gets max_iter=1: it fails, is recorded, point 2 starts from A and reaches the same optimum."""
    original = ParetoSolver._solve

    def solve(self, kind, index, point_kind, epsilon, warm_start, options=None, **obj):
        if point_kind == "eps" and index == 1:
            options = {**(options or {}), "max_iter": 1}
        return original(self, kind, index, point_kind, epsilon, warm_start, options, **obj)

    monkeypatch.setattr(ParetoSolver, "_solve", solve)
    cfg = load_identification_config(TINY)
    res = run_identification(cfg, tmp_path, progress=lambda *_: None)
    front = pd.read_csv(tmp_path / "front.csv").set_index("index")
    assert list(front.index) == [0, 1, 2, 3]
    assert front.loc[1, "status"] == "Maximum_Iterations_Exceeded" and not front.loc[1, "success"]
    assert front.drop(index=1)["success"].all()
    assert res.info["failed_points"] == [{"index": 1, "kind": "eps", "status": "Maximum_Iterations_Exceeded"}]
    ref = pd.read_csv(reference / "front.csv").set_index("index")
    # point 2 was warm-started from A instead of the failed point 1: same local optimum
    for col in ("J_time", "J_trim", "theta_twist", "CL_alpha_HT"):
        assert front.loc[2, col] == pytest.approx(ref.loc[2, col], rel=1e-5, abs=1e-7), col
    assert res.chosen is not None and res.chosen["index"] != 1


def test_a_resumed_front_knows_the_bounds_its_loaded_points_meet(tmp_path, monkeypatch):
    """Ipopt's Restoration_Failed on bounds a converged solve meets is a failure to retry, not an infeasible point
    (which would mark every tighter point infeasible unsolved). Anchor B meets every bound of the front. Resumed
    from a store that holds A and B, the loaded anchors are witnesses as the solved ones were: a failed solve
    halfway between them is still a failure, as in the uninterrupted run, and not "infeasible"."""
    from types import SimpleNamespace

    from pyomo_heli.nlp.identification import build_identification_nlp, identification_data
    from pyomo_heli.pareto.front import ParetoSettings

    cfg = load_identification_config(TINY)
    data = identification_data(cfg)
    statuses = []
    for run in ("solved", "resumed"):
        m = build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp)
        ps = ParetoSolver(m, ParetoSettings(points=4), store=PointStore(tmp_path, "fp"))
        a, b = ps.anchors()
        assert getattr(a, "from_disk", False) == getattr(b, "from_disk", False) == (run == "resumed")
        eps = {"trim": 0.5 * (a.J_trim + b.J_trim)}
        assert ps.witnessed(eps), run
        monkeypatch.setattr(ps.solver, "solve", lambda **kw: SimpleNamespace(
            success=False, status="Restoration_Failed", iterations=5, wall_time=0.0, setup_time=0.0))
        statuses.append(ps.solve_eps(1, eps, "primal").status)
    assert statuses == ["Restoration_Failed", "Restoration_Failed"]


def test_every_point_failing_still_finishes_the_sweep(tmp_path):
    """max_iter=1 everywhere: every point recorded as not converged, no exception, exit status 1."""
    from pyomo_heli.cli import main

    cfg = tmp_path / "fail.toml"
    cfg.write_text(TINY.read_text().replace("../../data", str(ROOT / "data"))
                   .replace('name = "casadi-ipopt"', 'name = "casadi-ipopt"\noptions = { max_iter = 1 }'))
    assert main(["identify", str(cfg), "--out", str(tmp_path / "o"), "--no-report"]) == 1
    front = pd.read_csv(tmp_path / "o" / "front.csv")
    assert sorted(front["index"]) == [0, 1, 2, 3]
    assert front["status"].str.contains("Maximum_Iterations_Exceeded").all() and not front["success"].any()
    chosen = json.loads((tmp_path / "o" / "chosen.json").read_text())
    assert chosen["chosen"] is None


def test_initialise_at_reproduces_the_built_start():
    """Re-initialising the built NLP at the configured guess gives back the values the build set."""
    cfg = load_identification_config(TINY)
    m, data, _ = build_problem(cfg)
    built = _Snapshot(m)
    pairs = [(v, None if math.isnan(val) else val) for v, val in zip(built.vars, built.values.tolist())]
    initialise_at(m, data, cfg.model, cfg.free, {f.name: f.upper * 0.5 + f.lower * 0.5 for f in cfg.free})
    changed = [v for v, val in pairs if v.value != val]
    assert changed  # the start really moved
    initialise_at(m, data, cfg.model, cfg.free, {f.name: f.initial for f in cfg.free})
    for v, val in pairs:
        assert v.value == (None if val is None else pytest.approx(val, rel=1e-12, abs=1e-12)), v.name


def test_draw_starts_seeded_within_bounds():
    cfg = load_identification_config(TINY)
    a = draw_starts(cfg.free, 20, seed=3)
    assert a == draw_starts(cfg.free, 20, seed=3)
    assert a[:5] == draw_starts(cfg.free, 5, seed=3)  # a start does not depend on how many are run
    assert a != draw_starts(cfg.free, 20, seed=4)
    for f in cfg.free:
        x = np.array([s[f.name] for s in a])
        assert np.all((x >= f.lower) & (x <= f.upper))
        assert x.max() - x.min() > 0.5 * (f.upper - f.lower)  # spread over the box


def test_multistart_share_and_resume(reference, tmp_path):
    """5 random starts reach anchor A of the front; a killed multistart resumes to the same table."""
    cfg = load_identification_config(TINY)
    res = run_multistart(cfg, tmp_path / "whole", starts=5, seed=1, progress=lambda *_: None)
    a = pd.read_csv(reference / "front.csv").set_index("index").loc[0]  # anchor A, from the config's guess
    assert res.best["objective"] == pytest.approx(a["J_time"], rel=1e-9)
    for f in cfg.free:
        assert res.best["parameters"][f.name] == pytest.approx(a[f.name], rel=1e-5, abs=1e-6)
    assert res.share >= 0.9 and res.n_reached == int(res.starts["reached_best"].sum())
    # the best is the first start that reached it, not whichever is lowest by rounding
    assert res.best["start"] == int(res.starts.loc[res.starts["reached_best"], "start"].min())
    assert len(pd.read_csv(tmp_path / "whole" / "starts.csv")) == 5
    # the same command in a real process, SIGKILLed once two starts are on disk, then run again
    out = tmp_path / "killed"
    proc = _cli("multistart", TINY, "--starts", 5, "--seed", 1, "--out", out)
    deadline = time.monotonic() + 600
    while not (out / "points" / "start001.npz").exists():
        assert proc.poll() is None, "the run ended before it could be killed"
        assert time.monotonic() < deadline
        time.sleep(0.005)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=60)
    done = len(list((out / "points").glob("*.npz")))
    assert 2 <= done < 5 and not (out / "multistart.json").exists()
    again = run_multistart(cfg, out, starts=5, seed=1, progress=lambda *_: None)
    assert again.info["resumed_starts"] == done
    cols = [c for c in res.starts.columns if c != "wall_time"]
    pd.testing.assert_frame_equal(again.starts[cols], res.starts[cols], check_exact=True)
    loaded = MultistartResult.load(out)
    assert loaded.share == again.share and "reached the best optimum" in str(loaded)
    with pytest.raises(StoreMismatchError):
        run_multistart(cfg, out, starts=5, seed=2, progress=lambda *_: None)


@pytest.mark.slow
def test_case1_multistart_share_at_least_90_percent(tmp_path):
    """The study of docs/results.md: Case 1 (10 Hz), 20 seeded starts, >= 90 % reach the best J_time."""
    cfg = load_identification_config(ROOT / "tests" / "configs" / "multistart_case1.toml")
    res = run_multistart(cfg, tmp_path, starts=20, seed=1, progress=print)
    assert len(res.starts) == 20
    assert res.share >= 0.9


def test_store_round_trips_solution_and_multipliers_exactly(tmp_path):
    """What a resumed full warm start needs: primal values, constraint and bound multipliers, bit for bit."""
    import pyomo.environ as pyo

    from pyomo_heli.solvers import make_solver

    def model():
        m = pyo.ConcreteModel()
        m.x = pyo.Var([0, 1], bounds=(0.0, 10.0), initialize=1.0)
        m.c = pyo.Constraint(expr=m.x[0] + m.x[1] >= 3.3)
        m.o = pyo.Objective(expr=(m.x[0] - 0.3) ** 2 + (m.x[1] - 1.1) ** 2 + pyo.exp(-m.x[0]))
        return m

    m = model()
    assert make_solver(m).solve().success
    store = PointStore(tmp_path, "fp")
    store.save("p", {"J": 1.0 / 3.0, "eps": float("inf")}, m, duals=True)
    fresh = model()
    store.restore("p", fresh)
    assert [v.value for v in fresh.x.values()] == [v.value for v in m.x.values()]
    assert fresh.dual[fresh.c] == m.dual[m.c] != 0.0
    assert [fresh.ipopt_zL_out[v] for v in fresh.x.values()] == [m.ipopt_zL_out[v] for v in m.x.values()]
    assert store.record("p") == {"J": 1.0 / 3.0, "eps": float("inf")}
    other = pyo.ConcreteModel()
    other.y = pyo.Var()
    with pytest.raises(StoreMismatchError, match="variable values"):
        store.restore("p", other)
