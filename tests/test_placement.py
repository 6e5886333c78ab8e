"""Adaptive epsilon placement (pareto/placement.py, issue 31 point 5).

Pure functions on analytic fronts whose knee and Eq. 11 point are known, the driver on an analytic
front solver (no NLP: the epsilon solve is a formula), and a tiny identification with
``[pareto] placement = "adaptive"`` that resumes from its stored points.
"""
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pyomo_heli.pareto.front import FrontPoint, ParetoSettings
from pyomo_heli.pareto.placement import (AdaptiveFront, chosen_point, distance_in_se, front_edges, largest_gap,
                                         neighbours, normalise, predicted_minimum, probe_fraction,
                                         refinement_probes)

HERE = Path(__file__).parent
TINY = HERE / "configs" / "tiny_case1_noisy.toml"


# --------------------------------------------------------------- analytic L-shaped front
# f1 = 1 / f2 on f2 in [0.01, 1]: anchors A (f1 = 1, f2 = 1) and B (f1 = 100, f2 = 0.01); utopia (1, 0.01),
# nadir (100, 1). Normalised, z1 = (1/f2 - 1) / 99 and z2 = (f2 - 0.01) / 0.99: an L whose knee is at
# f2 = 0.1 (z = (0.0909, 0.0909), the point of the front closest to utopia in the normalised plane, by symmetry:
# the front is symmetric under z1 <-> z2 because f1 = 1/f2 maps [0.01, 1] onto [1, 100]).
U, N = (1.0, 0.01), (100.0, 1.0)


def f1_of(f2):
    return 1.0 / np.asarray(f2, float)


def knee_f2() -> float:
    f2 = np.geomspace(0.01, 1, 200001)
    return float(f2[np.argmin(np.linalg.norm(normalise(np.c_[f1_of(f2), f2], U, N), axis=1))])


def place(n_points: int) -> np.ndarray:
    """Anchors, a seed in the middle of f2, then ``n_points - 3`` points by normalised arc length."""
    f2 = [1.0, 0.01, 0.505]
    taken = []
    while len(f2) < n_points:
        Z = normalise(np.c_[f1_of(f2), f2], U, N)
        (_i, _j), mid = largest_gap(Z, taken)
        taken.append(mid)
        f2.append(float(U[1] + mid[0] * (N[1] - U[1])))
    return np.array(f2)


def test_knee_is_where_the_symmetry_says():
    assert knee_f2() == pytest.approx(0.1, rel=1e-3)


def test_arc_length_puts_points_in_the_knee_where_a_uniform_grid_does_not():
    """Six points: the uniform (linear) epsilon grid has none with f2 in [0.05, 0.2] (the knee region, within
    a factor 2 of the knee); arc length puts two there, and its point nearest utopia is nearer."""
    knee = (0.05, 0.2)
    uniform = np.linspace(1.0, 0.01, 6)
    adaptive = place(6)
    assert not np.any((uniform >= knee[0]) & (uniform <= knee[1]))
    assert np.sum((adaptive >= knee[0]) & (adaptive <= knee[1])) >= 2

    def best(f2):
        return np.min(np.linalg.norm(normalise(np.c_[f1_of(f2), f2], U, N), axis=1))

    exact = best([knee_f2()])
    assert best(adaptive) < best(uniform)
    assert best(adaptive) < 1.15 * exact  # within 15 % of the knee's distance to utopia


def test_largest_gap_is_the_longest_edge_and_skips_filled_gaps():
    Z = np.array([[0.0, 1.0], [0.1, 0.5], [1.0, 0.0]])  # edges: (0,1) length 0.51, (1,2) length 1.03
    (i, j), mid = largest_gap(Z)
    assert {i, j} == {1, 2} and mid == pytest.approx([0.25])
    # a gap in the front: a solve at the midpoint came back to an existing point; the edge is not split again
    (i, j), mid = largest_gap(Z, taken=[np.array([0.25])])
    assert {i, j} == {0, 1} and mid == pytest.approx([0.75])
    assert largest_gap(Z, taken=[np.array([0.25]), np.array([0.75])]) is None


def test_front_edges_for_three_objectives_triangulate_the_epsilon_plane():
    """Four points at the corners of the (z2, z3) unit square plus its centre: the Delaunay edges join
    the centre to every corner, and the longest edge (a square's side, length 1 in z2 z3 plus z1) is split."""
    E = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [0.5, 0.5]], float)
    Z = np.c_[np.zeros(5), E]
    edges = front_edges(Z)
    assert all((min(4, k), max(4, k)) in edges for k in range(4))
    (i, j), mid = largest_gap(Z)
    assert np.linalg.norm(Z[i] - Z[j]) == pytest.approx(1.0)
    assert mid.shape == (2,)


def test_refinement_probes_and_moves_in_standard_errors():
    se = {"a": 0.1, "b": 1.0}
    assert distance_in_se({"a": 0.0, "b": 0.0}, {"a": 0.25, "b": 0.5}, se) == pytest.approx(2.5)
    assert distance_in_se({"a": 0.0}, {"a": 5.0}, {"a": math.inf}) == 0.0  # undetermined: any move is within it
    assert distance_in_se({"a": 1.0}, {"a": 1.0}, {"a": math.nan}) == 0.0  # at a bound, unmoved
    assert distance_in_se({"a": 1.0}, {"a": 1.5}, {"a": math.nan}) == math.inf
    assert probe_fraction(9.0) == pytest.approx(0.1) and probe_fraction(1.2) == 0.5
    # three points on the line z1 + z2 = 1, whose point nearest utopia is (0.5, 0.5): a sixth of the way from
    # point 1 to point 2
    Z = np.array([[0.0, 1.0], [0.4, 0.6], [1.0, 0.0]])
    assert chosen_point(Z) == 1 and neighbours(Z, 1) == [0, 2]
    side, t = predicted_minimum(Z, 1, [0, 2])
    assert side == 2 and t == pytest.approx(1 / 6, abs=1e-9)
    # both neighbours 9 standard errors away: towards point 2 the probe goes to the predicted minimum
    # (z2 = 0.5), towards point 0 it aims at 0.9 standard errors, 0.9 / 9 of the edge (z2 = 0.64)
    assert np.concatenate(refinement_probes(Z, 1, {0: 9.0, 2: 9.0})) == pytest.approx([0.64, 0.5])
    # a neighbour within one standard error gets no probe
    assert np.concatenate(refinement_probes(Z, 1, {0: 9.0, 2: 0.5})) == pytest.approx([0.64])


# --------------------------------------------------------------- the driver on an analytic front solver
class AnalyticFront:
    """The narrow interface AdaptiveFront uses, on f1 = 1/f2: the solve at epsilon is f2 = epsilon, and one
    'parameter' theta = log(f2) with a standard error ``se`` everywhere."""

    def __init__(self, se=0.02, store=None):
        self.se, self.points, self.snapshots, self.solves = se, [], {}, 0
        self.m = None
        self.stored = store if store is not None else {}

    def _point(self, index, kind, f2):
        self.solves += 1
        return FrontPoint(index=index, kind=kind, epsilon=f2, J_time=1.0 / f2, J_trim=f2,
                          parameters={"theta": math.log(f2)}, success=True, status="ok", iterations=1,
                          wall_time=0.0)

    def solve_point(self, key, solve):
        if key not in self.stored:
            self.stored[key] = solve()
        return self.stored[key]

    def anchors(self):
        a = self.solve_point("A", lambda: self._point(0, "A", 1.0))
        b = self.solve_point("B", lambda: self._point(1, "B", 0.01))
        self._snap_a = self._snap_b = None
        return a, b

    def anchor_a_start(self):
        return None

    def solve_epsilon(self, epsilon, index, start, leaving=False):
        return self._point(index, "eps", epsilon)

    def utopia_nadir(self):
        return U, N


@pytest.fixture
def no_snapshot(monkeypatch):
    import pyomo_heli.pareto.placement as placement

    monkeypatch.setattr(placement, "Snapshot", lambda m: None)


def _run(solver, max_solves):
    # linear spacing: the seed (f2 = 0.505) is not the knee, which geometric spacing would hit exactly here
    ada = AdaptiveFront(solver, max_solves, lambda p: {"theta": solver.se}, spacing="linear", progress=lambda *_: None)
    return ada, ada.run()


@pytest.mark.parametrize("max_solves", [6, 9])
def test_a_placement_stopped_by_its_cap_reports_the_chosen_point_the_front_ends_with(no_snapshot, max_solves):
    """Found by a review: the cap can stop a round after a probe that becomes the Eq. 11 choice; the summary's last
    round still named the chosen point before it (and its bracket). A final look names the front's own choice."""
    ps = AnalyticFront(se=0.05)
    ada, points = _run(ps, max_solves)
    s = ada.summary
    assert s.stop == f"cap of {max_solves} front solves reached" and not s.converged
    c = points[chosen_point(normalise([[p.J_time, p.J_trim] for p in points], U, N))]
    assert s.rounds[-1].chosen == c.index


def test_refinement_stops_within_one_standard_error_of_the_known_choice(no_snapshot):
    """The Eq. 11 point is f2 = 0.1 (theta = log 0.1). Refinement stops because the chosen point's
    neighbours lie within one standard error, and the chosen point is then within one standard error of it."""
    ps = AnalyticFront(se=0.05)
    ada, points = _run(ps, 30)
    s = ada.summary
    assert s.converged and s.rounds[-1].bracket_se <= 1.0
    assert s.solves == len(points) == ps.solves <= 30 and s.refinement_solves > 0
    ok = [p for p in points]
    c = ok[chosen_point(normalise([[p.J_time, p.J_trim] for p in ok], U, N))]
    assert abs(c.parameters["theta"] - math.log(knee_f2())) < ps.se


def test_refinement_stops_at_the_cap_and_says_so(no_snapshot):
    ada, points = _run(AnalyticFront(se=1e-6), 8)  # an unreachable standard error
    assert len(points) == 8 and not ada.summary.converged
    assert "cap of 8" in ada.summary.stop


def test_a_resumed_placement_solves_nothing_again(no_snapshot):
    """Points loaded from the store place the next points exactly as in the first run."""
    first = AnalyticFront(se=0.05)
    _, p1 = _run(first, 30)
    again = AnalyticFront(se=0.05, store=dict(first.stored))
    _, p2 = _run(again, 30)
    assert again.solves == 0
    assert [(p.index, p.J_trim) for p in p1] == [(p.index, p.J_trim) for p in p2]


# --------------------------------------------------------------- a tiny identification
def test_settings_check_placement():
    with pytest.raises(ValueError, match="pareto.placement"):
        ParetoSettings(placement="smart")
    with pytest.raises(ValueError, match="pareto.max_solves"):
        ParetoSettings(placement="adaptive", max_solves=3)


def test_tiny_identification_with_adaptive_placement_runs_and_resumes(tmp_path, monkeypatch):
    """A run interrupted at its fourth epsilon solve resumes from the stored points to the front of an
    uninterrupted run (the placement depends only on the finished points, which are loaded exactly)."""
    from pyomo_heli import interrupts
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.pareto.front import ParetoSolver
    from pyomo_heli.pareto.result import IdentificationResult
    from pyomo_heli.workflows.identify import run_identification

    cfg = load_identification_config(TINY, {"pareto": {"placement": "adaptive", "max_solves": 7}})
    original, calls = ParetoSolver.solve_epsilon, {"n": 0}

    def interrupted_at_the_fourth(self, *args, **kw):
        calls["n"] += 1
        if calls["n"] == 4:
            raise interrupts.Interrupted()
        return original(self, *args, **kw)

    monkeypatch.setattr(ParetoSolver, "solve_epsilon", interrupted_at_the_fourth)
    with pytest.raises(interrupts.Interrupted):
        run_identification(cfg, tmp_path / "resumed", progress=lambda *_: None, uncertainty=False)
    assert len(list((tmp_path / "resumed" / "points").glob("*.npz"))) == 5  # A, B and three epsilon points
    monkeypatch.setattr(ParetoSolver, "solve_epsilon", original)
    resumed = run_identification(cfg, tmp_path / "resumed", progress=lambda *_: None, uncertainty=False)
    assert resumed.info["resumed_points"] == 5
    fresh = run_identification(cfg, tmp_path / "fresh", progress=lambda *_: None, uncertainty=False)

    s = fresh.info["placement"]
    front = pd.read_csv(tmp_path / "fresh" / "front.csv")
    assert s["solves"] == len(front) <= 7 and set(front["kind"]) <= {"A", "B", "eps"}
    assert front["success"].all()
    assert s["rounds"] and s["direct_se"] is not None
    # converged means the chosen point's neighbours were within one standard error, and then the direct
    # Eq. 11 solve is too (the cap may stop it first: then the summary says so)
    assert s["converged"] == (s["rounds"][-1]["bracket_se"] <= 1.0)
    if s["converged"]:
        assert s["direct_se"] <= 1.0
    else:
        assert "cap of 7" in s["stop"]
    cols = ["index", "kind", "epsilon", "J_time", "J_trim", "theta_twist", "CL_alpha_HT", "iterations"]
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "resumed" / "front.csv")[cols], front[cols])
    assert resumed.info["placement"] == s
    assert IdentificationResult.load(tmp_path / "fresh").info["placement"] == s


def test_placement_flag_reaches_the_config(tmp_path, monkeypatch):
    """``--placement adaptive`` on identify overrides [pareto] placement (the demo shares the flag)."""
    import pyomo_heli.workflows.identify as wf
    from pyomo_heli.cli import build_parser, main

    seen = {}

    def stop(cfg, out, **kw):
        seen["pareto"] = cfg.pareto
        raise SystemExit(0)

    monkeypatch.setattr(wf, "run_identification", stop)
    with pytest.raises(SystemExit):
        main(["identify", str(TINY), "--placement", "adaptive", "--out", str(tmp_path / "out")])
    assert seen["pareto"].placement == "adaptive" and seen["pareto"].max_solves == 14
    assert build_parser().parse_args(["demo", "--placement", "adaptive"]).placement == "adaptive"


def test_a_solve_that_raised_is_left_out_of_the_mean_iteration_count():
    """A solve that raised records -1 iterations (no count): the mean of the interior points leaves it out."""
    import pandas as pd

    from pyomo_heli.report.identification import mean_interior_iterations

    front = pd.DataFrame({"kind": ["A", "eps", "eps", "eps", "B"], "iterations": [20, 6, -1, 10, 30]})
    assert mean_interior_iterations(front) == 8.0
