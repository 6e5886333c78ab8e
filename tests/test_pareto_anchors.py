"""A front whose anchor did not converge (pyomo_heli.pareto.front, workflows.identify).

Anchors set the utopia point, the nadir, the epsilon grid and the scale, so a failed anchor spoils
everything derived from them. A failed anchor is retried (B cold, A from B's solution); one that still
fails is marked: chosen.json ``info.unreliable``, the printed result, and exit status 1.
Forced failures: ``max_iter = 1`` on the chosen solves only (tiny Case 1).
"""
import json
from pathlib import Path

import pandas as pd
import pytest

from pyomo_heli.cli import main
from pyomo_heli.config import load_identification_config
from pyomo_heli.workflows.identify import run_identification
from pyomo_heli.pareto.front import ParetoSolver
from pyomo_heli.pareto.result import IdentificationResult

HERE = Path(__file__).parent
TINY = HERE / "configs" / "tiny_case1_noisy.toml"
COLS = ("J_time", "J_trim", "theta_twist", "CL_alpha_HT")


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Both anchors converged at the first attempt (the undisturbed run)."""
    out = tmp_path_factory.mktemp("ref")
    res = run_identification(load_identification_config(TINY), out, progress=lambda *_: None, uncertainty=False)
    assert res.info["unreliable"] is None
    return pd.read_csv(out / "front.csv").set_index("kind")


def _fail(monkeypatch, which, times):
    """max_iter = 1 on the first ``times`` solves whose point kind is in ``which``."""
    original = ParetoSolver._solve
    left = {"n": times}

    def solve(self, kind, index, point_kind, epsilon, warm_start, options=None, **obj):
        if point_kind in which and left["n"] > 0:
            left["n"] -= 1
            options = {**(options or {}), "max_iter": 1}
        return original(self, kind, index, point_kind, epsilon, warm_start, options, **obj)

    monkeypatch.setattr(ParetoSolver, "_solve", solve)


def test_failed_anchor_a_is_retried_from_b(reference, tmp_path, monkeypatch):
    _fail(monkeypatch, {"A"}, 1)
    res = run_identification(load_identification_config(TINY), tmp_path, progress=lambda *_: None,
                             uncertainty=False)
    front = pd.read_csv(tmp_path / "front.csv").set_index("kind")
    a = front.loc["A"]
    assert a["success"] and a["warm_start"] == "none (Maximum_Iterations_Exceeded), then primal from anchor B"
    for col in COLS:  # the cold anchor A of the undisturbed run, reached from B instead
        assert a[col] == pytest.approx(reference.loc["A", col], rel=1e-6, abs=1e-8), col
    assert res.info["unreliable"] is None and res.utopia[0] == pytest.approx(reference.loc["A", "J_time"], rel=1e-9)


def test_failed_anchor_b_is_retried_cold(reference, tmp_path, monkeypatch):
    _fail(monkeypatch, {"B1"}, 1)  # B's first stage, started from A
    res = run_identification(load_identification_config(TINY), tmp_path, progress=lambda *_: None,
                             uncertainty=False)
    b = pd.read_csv(tmp_path / "front.csv").set_index("kind").loc["B"]
    assert b["success"] and b["warm_start"].startswith("primal (first stage (min J_trim): Maximum_Iterations")
    assert b["warm_start"].endswith("then none")
    for col in COLS:
        assert b[col] == pytest.approx(reference.loc["B", col], rel=1e-5, abs=1e-7), col
    assert res.info["unreliable"] is None


def test_anchor_failing_after_its_retries_is_marked_unreliable(tmp_path, monkeypatch, capsys):
    """Anchor A fails every attempt: the run finishes, marks the anchors' quantities unreliable and exits 1
    (before: exit 0, and the choice among the converged points was reported as the answer)."""
    _fail(monkeypatch, {"A"}, 10)
    out = tmp_path / "o"
    assert main(["identify", str(TINY), "--out", str(out), "--no-report", "--uncertainty", "none"]) == 1
    captured = capsys.readouterr()
    assert "anchor A did not converge (Maximum_Iterations_Exceeded" in captured.err
    assert "unreliable" in captured.err and "UNRELIABLE" in captured.out
    info = json.loads((out / "chosen.json").read_text())["info"]
    assert info["unreliable"]["reason"].startswith("anchor A did not converge")
    assert {"utopia", "nadir", "epsilon grid", "chosen", "direct"} <= set(info["unreliable"]["quantities"])
    a = pd.read_csv(out / "front.csv").set_index("kind").loc["A"]
    assert not a["success"] and a["warm_start"] == "none (Maximum_Iterations_Exceeded), then primal from anchor B"
    # commands that analyse a point say how its solve ended
    from pyomo_heli.cli import _solver_status_line

    result = IdentificationResult.load(out)
    line = _solver_status_line(result, "time_domain")
    assert "Maximum_Iterations_Exceeded" in line and "did not converge" in line
    assert "unreliable" in _solver_status_line(result, "chosen")
