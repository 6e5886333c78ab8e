"""Adaptive epsilon placement for three objectives (pareto/placement_nd.py, issue 31 point 5).

The pure functions on configurations whose answer is known by construction, the driver on an analytic
three-objective front (no NLP: each epsilon solve is a formula) whose Eq. 11 point is known in closed
form, and a tiny tri-objective identification with ``[pareto] placement = "adaptive"``.

The analytic front ("box", as in test_pareto_epsilon.py): f1 = p a^2 + q b^2, f2 = (a - 1)^2,
f3 = (b - 1)^2. Minimising f1 under f2 <= e2, f3 <= e3 gives a = 1 - sqrt(e2), b = 1 - sqrt(e3); a cut
a + b <= cut makes the tight corner of the bounds infeasible. Anchors A (0, 0), B (1, 0), C (0, 1); utopia
(0, 0, 0), payoff nadir (max(p, q), 1, 1). With p = q = 1 the Eq. 11 point is a = b = t with
2 t^3 = (1 - t)^3, t = 1 / (1 + 2^(1/3)) = 0.4425.
"""
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import minimize

from pyomo_heli.pareto.placement import chosen_point, neighbours, normalise
from pyomo_heli.pareto.placement_nd import AdaptiveFrontN, cone_neighbours, edge_gaps, model_minimum
from pyomo_heli.pareto.steps import INFEASIBLE, EpsilonPoint, epsilon_grid

T = 1.0 / (1.0 + 2.0 ** (1.0 / 3.0))


# --------------------------------------------------------------- pure functions
def test_model_minimum_is_the_minimum_when_the_front_is_quadratic():
    """z1 exactly quadratic in (z2, z3): the model is exact, so its minimum is that of |z|^2, found here by
    a brute-force grid search instead."""
    def z1(z2, z3):
        return 0.9 - 0.6 * z2 - 0.8 * z3 + 0.3 * z2**2 + 0.1 * z2 * z3 + 0.4 * z3**2

    g = np.linspace(0.0, 1.0, 2001)
    G2, G3 = np.meshgrid(g, g, indexing="ij")
    d2 = z1(G2, G3) ** 2 + G2**2 + G3**2
    k = np.unravel_index(np.argmin(d2), d2.shape)
    truth = np.array([g[k[0]], g[k[1]]])  # (0.243, 0.3045)
    rng = np.random.default_rng(7)
    centre = truth + [0.06, -0.05]  # C, off the minimum
    E = np.vstack([centre, centre + 0.3 * rng.uniform(-1, 1, (14, 2))])
    Z = np.c_[z1(E[:, 0], E[:, 1]), E]
    e = model_minimum(Z, 0)
    np.testing.assert_allclose(e, truth, atol=1e-3)  # the search grid's step is 5e-4
    assert model_minimum(Z, 0, taken=[e]) is None  # a point already placed there is not placed again
    assert model_minimum(Z[:6], 0) is None  # fewer points than the quadratic's coefficients + 1


def test_cone_neighbours_and_infeasible_edges():
    """C = (0.5, 0.5) in the epsilon plane: one point in each compass cone, the nearest in its cone; an
    infeasible bound nearer than the point of its cone stands for the edge there."""
    E = np.array([[0.5, 0.5],   # 0: C
                  [0.6, 0.52],  # 1: +z2 (largest difference along z2, positive)
                  [0.8, 0.5],   # 2: +z2 as well, farther: not a neighbour
                  [0.45, 0.52],  # 3: -z2
                  [0.5, 0.3],   # 4: -z3
                  [0.5, 0.9]])  # 5: +z3, but the infeasible bound (0.5, 0.7) is nearer
    Z = np.c_[np.zeros(len(E)), E]
    out = cone_neighbours(Z, 0, infeasible=[np.array([0.5, 0.7])])
    points = sorted(j for kind, j in out if kind == "point")
    edges = [x for kind, x in out if kind == "edge"]
    assert points == [1, 3, 4] and len(edges) == 1 and edges[0] == pytest.approx([0.5, 0.7])
    assert neighbours(Z, 0) == [1, 3, 4, 5]  # without the infeasible bound, point 5 bounds +z3
    # point 1 lies 0.102 away and 2 standard errors from C: 0.051 per standard error; the edge, 0.2 away, is
    # about 3.9 standard errors from C
    (x, gap), = edge_gaps(Z, 0, {1: 2.0, 3: 0.5, 4: 0.0}, edges)
    assert gap == pytest.approx(0.2 / (math.hypot(0.1, 0.02) / 2.0))
    (_, gap), = edge_gaps(Z, 0, {4: 0.0}, edges)
    assert gap == math.inf  # no neighbour that moved: the distance to the edge is unknown


# --------------------------------------------------------------- the driver on an analytic front
class BoxFront:
    """The interface AdaptiveFrontN uses (EpsilonConstraintSolver's), on the analytic front of the module
    docstring; parameters a, b with the standard error ``se`` everywhere."""

    names = ("f1", "f2", "f3")
    store = None

    def __init__(self, se, p=1.0, q=1.0, cut=1.5):
        self.se, self.p, self.q, self.cut, self.points, self.solves = se, p, q, cut, [], 0
        self.seen = []

    def f(self, a, b):
        return (self.p * a * a + self.q * b * b, (a - 1) ** 2, (b - 1) ** 2)

    def _point(self, index, kind, a, b, eps, grid=()):
        self.solves += 1
        ok = a + b <= self.cut + 1e-12
        J = dict(zip(self.names, self.f(a, b) if ok else (math.nan,) * 3))
        p = EpsilonPoint(index=index, kind=kind, J=J, epsilon=eps, parameters={"a": a, "b": b}, success=ok,
                         status="Solve_Succeeded" if ok else INFEASIBLE, iterations=1, wall_time=0.0, grid=grid)
        self.points.append(p)
        self.seen.append(p)  # the solver's on_point
        return p

    def anchors(self):
        self.points = []
        return [self._point(0, "A", 0.0, 0.0, {}), self._point(-1, "B", 1.0, 0.0, {}),
                self._point(-2, "C", 0.0, 1.0, {})]

    def grid_axes(self, counts, margin=0.05):  # from f_k(A) = 1 to 5 % of the range above the minimum 0
        return [epsilon_grid(1.0, margin, n) for n in counts]

    def utopia_nadir(self, rule=None):
        return (0.0, 0.0, 0.0), (max(self.p, self.q), 1.0, 1.0)

    def solve_at(self, eps, index=None, key=None, grid=()):
        e2, e3 = eps
        return self._point(max(p.index for p in self.points) + 1, "eps", max(1 - math.sqrt(max(e2, 0.0)), 0.0),
                           max(1 - math.sqrt(max(e3, 0.0)), 0.0), {"f2": e2, "f3": e3}, grid)

    def eq11_truth(self):
        """The Eq. 11 point by a second method: min over (a, b) of the normalised distance of the front point."""
        N = np.array(self.utopia_nadir()[1])
        return minimize(lambda x: np.sum((np.array(self.f(*x)) / N) ** 2), [0.4, 0.4], method="Nelder-Mead",
                        options={"xatol": 1e-12, "fatol": 1e-16}).x


def _place(front, max_solves):
    ada = AdaptiveFrontN(front, max_solves, lambda p: {"a": front.se, "b": front.se}, progress=lambda *_: None)
    return ada, ada.run()


def _chosen(front, points):
    ok = [p for p in points if p.success]
    return ok[chosen_point(normalise([[p.J_f1, p.J_f2, p.J_f3] for p in ok], *front.utopia_nadir()))]


def test_refinement_converges_within_one_standard_error_of_the_closed_form_choice():
    front = BoxFront(se=0.01)
    assert front.eq11_truth() == pytest.approx([T, T], abs=1e-6)  # the closed form and the second method agree
    ada, points = _place(front, 30)
    s = ada.summary
    assert s.converged and s.rounds[-1].bracket_se <= 1.0, s.stop
    assert s.solves == len(points) == front.solves <= 30 and s.refinement_solves > 0
    assert s.arc_length_solves == 3 + 8  # anchors and the coarse 3 x 3 grid less A's corner
    c = _chosen(front, points)
    assert abs(c.parameters["a"] - T) < front.se and abs(c.parameters["b"] - T) < front.se
    # the coarse grid: its positions, and its tight corner (a = b = 1 - sqrt(0.05) = 0.776, a + b > 1.5)
    # reported infeasible, as on the uniform grid
    coarse = {p.grid: p for p in points if p.grid}
    assert set(coarse) == {(i, j) for i in range(3) for j in range(3)} - {(0, 0)}
    assert coarse[(2, 2)].status == INFEASIBLE and not coarse[(2, 2)].success
    assert all(p.success for p in points if p.grid != (2, 2))
    assert front.seen == points  # every point went to the solver's on_point, in the order solved


@pytest.mark.parametrize("p, q, cut", [(1, 1, 1.5), (3, 1, 1.5), (1, 5, 1.2), (0.3, 2, 1.5)])
@pytest.mark.parametrize("se, cap", [(0.01, 30), (0.03, 28), (0.1, 24)])
def test_a_converged_placement_is_within_one_standard_error_of_the_choice(p, q, cut, se, cap):
    """Asymmetric fronts, some with the infeasible cut near the choice: when the placement says converged,
    its choice lies within one standard error of the Eq. 11 point found by the second method."""
    front = BoxFront(se=se, p=p, q=q, cut=cut)
    ada, points = _place(front, cap)
    truth = front.eq11_truth()
    c = _chosen(front, points)
    assert ada.summary.converged, ada.summary.stop
    assert abs(c.parameters["a"] - truth[0]) <= se and abs(c.parameters["b"] - truth[1]) <= se


def test_refinement_stops_at_the_cap_and_says_so():
    ada, points = _place(BoxFront(se=1e-7), 16)
    assert len(points) == 16 and not ada.summary.converged and "cap of 16" in ada.summary.stop


# --------------------------------------------------------------- a tiny tri-objective identification
def test_tiny_tri_identification_with_adaptive_placement(tmp_path):
    """tiny_case1_tri_adaptive.toml (2 s of one record, one frequency response, adaptive placement): every point
    converges or is reported infeasible within the iteration cap, the choice is the Eq. 11 point of
    front.csv, and C's neighbours bracket it within one of its standard errors. Those are taken at the weights C's
    solve is stationary for (its J_trim multiplier; before, the weights were fitted to the time and trim gradients
    alone, which the J_linear bound's term leaves unbalanced, and came out time-only: the twist's SE 700 times larger):
    the direct Eq. 11 solve is 2.05 of them from C, recomputed here from C's standard errors."""
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.workflows.identify import run_identification

    cfg = load_identification_config(Path(__file__).parent / "configs" / "tiny_case1_tri_adaptive.toml")
    res = run_identification(cfg, tmp_path, progress=lambda *_: None)
    s = res.info["placement"]
    front = pd.read_csv(tmp_path / "front.csv")
    placed = front[front.kind != "direct"]
    assert s["solves"] == len(placed) <= 30 and res.info["grid"] == [3, 3]
    coarse = placed[placed.i_trim >= 0]
    assert set(zip(coarse.i_trim, coarse.i_linear)) == {(i, j) for i in range(3) for j in range(3)}
    ok = placed.success.astype(bool) | (placed.status == INFEASIBLE)
    assert ok.all() and (placed.iterations < 100).all()
    conv = placed[placed.success.astype(bool)]
    Zc = normalise(conv[["J_time", "J_trim", "J_linear"]].to_numpy(), res.utopia, res.nadir)
    assert int(conv.iloc[chosen_point(Zc)]["index"]) == res.chosen["index"]
    assert s["converged"] and s["rounds"][-1]["bracket_se"] <= 1.0, s["stop"]
    from pyomo_heli.nlp.identification import identification_data
    from pyomo_heli.pareto.placement import distance_in_se
    from pyomo_heli.uncertainty.front import point_standard_errors

    c = front[front["index"] == res.chosen["index"]].iloc[0]
    se = point_standard_errors(cfg, identification_data(cfg), res.chosen["parameters"], "eps",
                               multiplier=float(c["multiplier_trim"]))
    assert s["direct_se"] == pytest.approx(distance_in_se(res.chosen["parameters"], res.direct["parameters"], se),
                                           rel=1e-6)
    assert 1.5 < s["direct_se"] < 3.0


# --------------------------------------------------------------- the N-objective solver on the analytic box
@pytest.mark.parametrize("rule", ["payoff", "nondominated"])
def test_placement_on_the_epsilon_constraint_solver(rule):
    """The real solver (Ipopt on the box, p = q = 1, no cut) through solve_at: converged, and the choice within
    one standard error of the direct Eq. 11 solve under the same nadir rule (for the payoff rule that is
    a = b = t, test_pareto_epsilon.py). With the non-dominated rule the nadir follows the points."""
    import pyomo.environ as pyo

    from pyomo_heli.pareto.epsilon import EpsilonConstraintSolver
    from pyomo_heli.pareto.front import ParetoSettings

    m = pyo.ConcreteModel()
    m.free_parameters = pyo.Set(initialize=["a", "b"], ordered=True)
    m.theta_s = pyo.Var(m.free_parameters, initialize=0.3, bounds=(-5, 5))
    m.theta_scale = pyo.Param(m.free_parameters, initialize=1.0)
    a, b = m.theta_s["a"], m.theta_s["b"]
    m.J_f1, m.J_f2, m.J_f3 = (pyo.Expression(expr=e) for e in (a**2 + b**2, (a - 1) ** 2, (b - 1) ** 2))
    settings = ParetoSettings(solver_options={"tol": 1e-10, "constr_viol_tol": 1e-13}, max_iter=100, nadir=rule,
                              placement="adaptive", max_solves=30)
    ps = EpsilonConstraintSolver(m, ("f1", "f2", "f3"), settings)
    se = 0.01
    ada = AdaptiveFrontN(ps, settings.max_solves, lambda p: {"a": se, "b": se}, progress=lambda *_: None)
    points = ada.run()
    assert ada.summary.converged, ada.summary.stop
    assert all(p.success and p.iterations < 100 for p in points)
    chosen, _, _, nadir = ps.eq11(rule)
    assert ada.nadir == pytest.approx(nadir)  # the placement's last look used the nadir of the final choice
    direct = ps.direct_choice(chosen, rule=rule)
    assert direct.success and ada.compare_direct(chosen, direct) <= 1.0
    if rule == "payoff":
        assert direct.parameters["a"] == pytest.approx(T, abs=1e-5)


def test_the_coarse_grid_leaves_the_last_objectives_free_in_their_first_position():
    """As on the grid (EpsilonConstraintSolver.grid_bounds): the coarse grid's points at position 0 of the second
    axis bound J_2 only, so that row is the two-objective front the tri-objective report takes its bi-objective
    choice from, not a front capped at J_3(A)."""
    ps = BoxFront(se=0.05)
    AdaptiveFrontN(ps, max_solves=12, standard_errors=lambda p: {"a": 0.05, "b": 0.05}).run()
    row0 = [p for p in ps.seen if p.kind == "eps" and p.grid and p.grid[1] == 0]
    assert row0 and all(p.epsilon["f3"] == math.inf and math.isfinite(p.epsilon["f2"]) for p in row0)
    assert all(math.isfinite(p.epsilon["f3"]) for p in ps.seen if p.kind == "eps" and p.grid and p.grid[1] > 0)


def test_uncertainty_refuses_a_three_objective_folder(tmp_path, capsys):
    """Found by a review: on a three-objective folder `uncertainty` fitted the direct solve's weights to the time
    and trim gradients alone (twist SE about 5.7 rad/m). Its information holds no J_linear: refused in one line."""
    from pyomo_heli.cli import main

    cfg = Path(__file__).parent / "configs" / "tiny_case1_tri_adaptive.toml"
    assert main(["identify", str(cfg), "--out", str(tmp_path / "o"), "--no-report"]) == 0
    capsys.readouterr()
    assert main(["uncertainty", str(cfg), "--results", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "a three-objective front; its standard errors leave J_linear's information out" in err[0]
