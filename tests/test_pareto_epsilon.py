"""The N-objective epsilon-constraint solver (pyomo_heli.pareto.epsilon) against closed-form answers.

Problem "box" (three objectives of x = (a, b), all minimised):

    f1 = a^2 + b^2,   f2 = (a - 1)^2,   f3 = (b - 1)^2.

Minimising f1 under f2 <= e2, f3 <= e3 decouples: a = 1 - sqrt(e2), b = 1 - sqrt(e3) (for e in
[0, 1]), so every front point is known in closed form. The Pareto set is the square [0, 1]^2. Anchors:
A = (0, 0) with f = (0, 1, 1); B = (1, 0) with (1, 0, 1); C = (0, 1) with (1, 1, 0). Utopia (0, 0, 0);
payoff nadir (1, 1, 1). The true nadir is (2, 1, 1) (point (1, 1) is Pareto optimal with f1 = 2): the
payoff table underestimates f1's range. On the grid (each bound from 1 down to 0.05), the worst f1 of
the non-dominated points is at the tight corner, 2 (1 - sqrt(0.05))^2.

Eq. 11 as one NLP, min sum_k (f_k / N_k)^2, is convex and symmetric, so a = b = t with
16 t^3 / N1^2 = 8 (1 - t)^3 (N2 = N3 = 1), i.e. t = 1 / (1 + (2 / N1^2)^(1/3)).
"""
import math
import tomllib
from pathlib import Path

import numpy as np
import pyomo.environ as pyo
import pytest

from pyomo_heli.pareto.epsilon import (DIRECT_STARTS, INFEASIBLE, EpsilonConstraintSolver, GridStart, dominating,
                                       nondominated,
                                       nondominated_nadir, snake, utopia_distance_n)
from pyomo_heli.pareto.front import ParetoSettings
from pyomo_heli.pareto.steps import starts_note

NAMES = ("f1", "f2", "f3")
SETTINGS = ParetoSettings(points=[4, 4], solver_options={"tol": 1e-10, "constr_viol_tol": 1e-13}, max_iter=100)


def _model(J, names=NAMES):
    m = pyo.ConcreteModel()
    m.free_parameters = pyo.Set(initialize=["a", "b"], ordered=True)
    m.theta_s = pyo.Var(m.free_parameters, initialize=0.3, bounds=(-5, 5))
    m.theta_scale = pyo.Param(m.free_parameters, initialize=1.0)
    a, b = m.theta_s["a"], m.theta_s["b"]
    for name, expr in zip(names, J(a, b)):
        m.add_component(f"J_{name}", pyo.Expression(expr=expr))
    return m


def _box():
    return _model(lambda a, b: (a**2 + b**2, (a - 1) ** 2, (b - 1) ** 2))


def _f(a, b):
    return np.array([a**2 + b**2, (a - 1) ** 2, (b - 1) ** 2])


def _t(n1):
    return 1.0 / (1.0 + (2.0 / n1**2) ** (1.0 / 3.0))


@pytest.fixture(scope="module")
def box_front():
    ps = EpsilonConstraintSolver(_box(), NAMES, SETTINGS)
    ps.grid_front(SETTINGS.grid)
    return ps


def test_front_points_match_the_closed_form(box_front):
    ps = box_front
    anchors = ps.anchor_points
    for name, (a, b) in {"A": (0, 0), "B": (1, 0), "C": (0, 1)}.items():
        p = anchors[name]  # B, C hold their objective at its minimum (1 + 1e-6) + 1e-12: a or b at 1 - 1e-6
        np.testing.assert_allclose([p.parameters["a"], p.parameters["b"]], [a, b], atol=2e-4)
    axis = np.geomspace(1.0, 0.05, 4)  # from f_k(A) = 1 down to 5 % of the range above the minimum 0
    np.testing.assert_allclose(ps.axes[0], axis, rtol=1e-6)
    grid = [p for p in ps.points if p.kind == "eps"]
    assert len(grid) == 4 * 4 - 1 and all(p.success for p in grid)
    assert [p.grid for p in grid] == [q for q in snake((4, 4)) if any(q)]
    for p in grid:
        e2, e3 = p.epsilon["f2"], p.epsilon["f3"]
        # column 0 leaves f3 free (inf); row 0 bounds f2 by its value at A, 1
        assert (e3 == math.inf) == (p.grid[1] == 0) and e2 == pytest.approx(axis[p.grid[0]])
        a, b = 1 - math.sqrt(e2), 1 - math.sqrt(min(e3, 1.0))  # f3 free: b = 0, as under f3 <= f3(A) = 1
        # 1e-5: on row/column 0 the bound sits where f1's gradient vanishes (a weakly active constraint, zero
        # multiplier), and the barrier keeps the iterate ~sqrt(tol) inside
        np.testing.assert_allclose([p.parameters["a"], p.parameters["b"]], [a, b], atol=1e-5)
        np.testing.assert_allclose([p.J_f1, p.J_f2, p.J_f3], _f(a, b), atol=2e-5)
        assert 0 < p.iterations < 100
        # the bounds' multipliers, -df1/df_k = a / (1 - a) (KKT: 2a + 2 lambda (a - 1) = 0), 0 where inactive
        np.testing.assert_allclose([p.multipliers["f2"], p.multipliers["f3"]], [a / (1 - a), b / (1 - b)],
                                   rtol=1e-4, atol=1e-5)
        assert p.row()["multiplier_f2"] == p.multipliers["f2"]


def test_eq11_choice_under_both_nadir_rules(box_front):
    ps = box_front
    utopia, payoff = ps.utopia_nadir(rule="payoff")
    np.testing.assert_allclose(utopia, [0, 0, 0], atol=1e-9)
    np.testing.assert_allclose(payoff, [1, 1, 1], atol=1e-5)  # B, C hold their objective at <= 1e-12: a, b = 1 - 1e-6
    _, nd = ps.utopia_nadir(rule="nondominated")
    n1 = 2 * (1 - math.sqrt(0.05)) ** 2  # the tight corner of the grid
    np.testing.assert_allclose(nd, [n1, 1, 1], atol=1e-6)
    for rule, nadir in (("payoff", (1.0, 1.0, 1.0)), ("nondominated", (n1, 1.0, 1.0))):
        # post hoc: the grid point nearest to utopia, from the closed-form front
        chosen, d, _, _ = ps.eq11(rule)
        axis = np.geomspace(1.0, 0.05, 4)
        cand = [(0.0, 0.0)] + [(1 - math.sqrt(e2), 1 - math.sqrt(e3)) for e2 in axis for e3 in axis]
        dist = utopia_distance_n([_f(a, b) for a, b in cand], (0, 0, 0), nadir)
        a, b = cand[int(np.argmin(dist))]
        np.testing.assert_allclose([chosen.parameters["a"], chosen.parameters["b"]], [a, b], atol=1e-5)
        assert d.min() == pytest.approx(dist.min(), abs=1e-6)
        # direct Eq. 11 solve: a = b = t(N1)
        direct = ps.direct_choice(chosen, rule=rule)
        t = _t(nadir[0])
        assert direct.success
        np.testing.assert_allclose([direct.parameters["a"], direct.parameters["b"]], [t, t], atol=1e-5)
    assert _t(1.0) == pytest.approx(1 / (1 + 2 ** (1 / 3)))  # 0.4425: the payoff rule's choice
    choices = ps.choices()
    assert set(choices) == {"payoff", "nondominated"}
    assert choices["nondominated"]["nadir"] == pytest.approx([n1, 1, 1], abs=1e-6)


def test_direct_eq11_solve_that_fails_goes_on_from_the_next_start_and_reaches_the_closed_form(box_front):
    """A direct Eq. 11 solve stopped by Ipopt (Error_In_Step_Computation on a flat front, here simulated for
    the first three attempts) is solved again from the next converged points nearest to utopia, then
    midway between the first two; the answer is the closed form's, and the record names every attempt."""
    ps = box_front
    chosen, d, _, _ = ps.eq11("payoff")
    pts = ps.front_candidates()
    nearest = [pts[i] for i in np.argsort(d, kind="stable")]
    assert nearest[0] is chosen
    real, seen = ps._direct_once, []

    def failing_thrice(utopia, nadir):
        seen.append((pyo.value(ps.m.theta_s["a"]), pyo.value(ps.m.theta_s["b"])))
        p = real(utopia, nadir)
        if len(seen) <= DIRECT_STARTS:
            p.success, p.status = False, "Error_In_Step_Computation"
        return p

    ps._direct_once = failing_thrice
    try:
        direct = ps.direct_choice(chosen, rule="payoff")
    finally:
        del ps._direct_once
    starts = [(p.parameters["a"], p.parameters["b"]) for p in nearest[:DIRECT_STARTS]]
    np.testing.assert_allclose(seen, starts + [tuple(np.mean(starts[:2], axis=0))], atol=1e-9)  # last: midway
    assert direct.success
    np.testing.assert_allclose([direct.parameters["a"], direct.parameters["b"]], [_t(1.0)] * 2, atol=1e-5)
    label = [f"point {p.index} (eps)" for p in nearest[:DIRECT_STARTS]]
    assert direct.warm_start == ("primal from " + "".join(f"{x} (Error_In_Step_Computation), then " for x in label)
                                 + f"midway between {label[0]} and {label[1]}")
    assert direct.iterations > 0
    assert starts_note(direct) == f" ({direct.warm_start})" and starts_note(ps.eq11("payoff")[0]) == ""
    kept, ps.snapshots = ps.snapshots, {}
    try:  # no solution kept: the one start is the model's current values
        assert [label for label, _ in ps.direct_starts(chosen)] == ["the current values"]
    finally:
        ps.snapshots = kept


def test_a_direct_eq11_solve_that_ends_farther_from_utopia_than_its_start_is_not_taken(box_front):
    """A direct Eq. 11 solve that reports success at a point farther from utopia than the post-hoc choice it
    started from has stopped in a worse local minimum (seen on a full-size loop: J_time 185 000 above every front
    point, at the same J_trim). Here the first attempt's J_f1 is moved up by 10 after it converged: it counts as
    failed, with a status that says why, and the next start gives the closed form. If every attempt does so, the
    direct solve fails and the caller keeps the post-hoc choice."""
    ps = box_front
    chosen, _, utopia, nadir = ps.eq11("payoff")
    real, seen = ps._direct_once, []

    def worse(times):
        def once(u, n):
            seen.append(1)
            p = real(u, n)
            if len(seen) <= times:
                p.J_f1 = p.J_f1 + 10.0
            return p
        return once

    ps._direct_once = worse(1)
    try:
        direct = ps.direct_choice(chosen, rule="payoff")
    finally:
        del ps._direct_once
    assert direct.success and len(seen) == 2
    np.testing.assert_allclose([direct.parameters["a"], direct.parameters["b"]], [_t(1.0)] * 2, atol=1e-5)
    assert "(Solve_Succeeded but farther from utopia than the post-hoc choice" in direct.warm_start
    d_direct = utopia_distance_n([[direct.J_f1, direct.J_f2, direct.J_f3]], utopia, nadir)[0]
    assert d_direct <= utopia_distance_n([[chosen.J_f1, chosen.J_f2, chosen.J_f3]], utopia, nadir)[0]
    kept = ps.points
    ps.points = [p for p in ps.points if p.kind != "direct"]  # the stored direct point: solve it again
    seen.clear()
    ps._direct_once = worse(99)
    try:
        direct = ps.direct_choice(chosen, rule="payoff")
    finally:
        del ps._direct_once
        ps.points = kept  # the module's front as it was, for the tests after this one
    assert not direct.success and len(seen) == DIRECT_STARTS + 1
    assert "not the minimiser" in direct.status
    # f1's range on the front taken as solver noise (nadir = utopia there): Eq. 11 does not weigh f1, so the
    # post-hoc choice moved up in f1 is as close to utopia as it, but the choice dominates it: not taken either
    U, N = ps.utopia_nadir(rule="payoff")
    real_un = ps.utopia_nadir
    ps.utopia_nadir = lambda rule=None: (U, (U[0],) + tuple(N[1:]))
    ps.points = [p for p in kept if p.kind != "direct"]
    seen.clear()

    def off_the_front(u, n):
        seen.append(1)
        if len(seen) == 1:
            q = real(u, n)
            q.J_f1, q.J_f2, q.J_f3 = chosen.J_f1 + 10.0, chosen.J_f2, chosen.J_f3
            return q
        return real(u, n)

    ps._direct_once = off_the_front
    try:
        direct = ps.direct_choice(chosen, rule="payoff")
    finally:
        del ps._direct_once, ps.utopia_nadir
        ps.points = kept
    assert ps.utopia_nadir == real_un
    assert direct.success and len(seen) == 2
    assert "(Solve_Succeeded but dominated by front point" in direct.warm_start


def test_dominating_finds_a_front_point_better_beyond_solver_noise():
    """The full-size case behind the direct solve's check (fuselage_pitch_damping 24, M0 + dM_q): anchor B at
    (J_time, J_trim) = (-117017.6, 0.0277476018) dominates the direct point (68545.8, 0.0277476025): J_trim
    equal within solver noise, J_time far better. Points equal within noise, or better in one objective and
    worse in another, do not dominate."""
    B, direct = [-117017.62448489462, 0.027747601849345455], [68545.7856677683, 0.0277476024669234]
    assert dominating(direct, [[-117017.66, 0.02847], B]) == 1
    assert dominating(B, [direct]) is None
    assert dominating(direct, [[68545.7856, 0.0277476024]]) is None  # the same point within 1e-6
    assert dominating([1.0, 1.0], [[0.5, 2.0], [2.0, 0.5]]) is None
    assert dominating([1.0, 1.0, 1.0], [[1.0, 1.0, 0.9]]) == 0


def test_solve_at_warm_starts_from_the_nearest_point_and_matches_the_closed_form(box_front):
    ps = box_front
    p = ps.solve_at({"f2": 0.3, "f3": 0.6})
    assert p.success and p.iterations < 100
    np.testing.assert_allclose([p.parameters["a"], p.parameters["b"]], [1 - math.sqrt(0.3), 1 - math.sqrt(0.6)],
                               atol=1e-6)
    # a bound below the anchor minimum of its objective (f2 >= 0): infeasible, not solved
    q = ps.solve_at([-0.01, 0.5])
    assert q.status == INFEASIBLE and not q.success and q.iterations == 0 and "minimum of J_f2" in q.note
    assert ps.points[-1] is q


def test_infeasible_bounds_are_reported_without_an_iteration_limit_solve():
    """Discs f2 <= e2 around (0, 1) and f3 <= e3 around (-1, 0) are sqrt(2) apart: with radii
    sqrt(0.2) each they miss each other (Ipopt's infeasibility detection), and tighter bounds are
    infeasible a priori (not solved)."""
    m = _model(lambda a, b: ((a - 1) ** 2 + b**2 + 1.0, a**2 + (b - 1) ** 2, (a + 1) ** 2 + b**2))
    ps = EpsilonConstraintSolver(m, NAMES, SETTINGS)
    ps.anchors()
    p = ps.solve_at({"f2": 0.2, "f3": 0.2})
    assert p.status == INFEASIBLE and not p.success
    assert p.note in ("Infeasible_Problem_Detected", "Restoration_Failed")
    assert 0 < p.iterations < SETTINGS.max_iter  # stopped by the infeasibility detection, not the cap
    q = ps.solve_at({"f2": 0.1, "f3": 0.15})
    assert q.status == INFEASIBLE and q.iterations == 0 and "found infeasible" in q.note
    r = ps.solve_at({"f2": 0.6, "f3": 0.6})  # radii 0.77 + 0.77 > 1.41: feasible
    assert r.success and r.J_f2 <= 0.6 * (1 + 1e-6) and r.J_f3 <= 0.6 * (1 + 1e-6)


def test_a_local_infeasibility_verdict_on_bounds_a_converged_point_meets_is_a_failure_not_infeasible(monkeypatch):
    """Ipopt's Restoration_Failed is local, often numerical: on bounds that a converged solve already meets it is
    recorded as a failure (retried by the front, the note says why), not as infeasible, and looser bounds are then
    solved, not skipped as "at most those of a point found infeasible"."""
    from types import SimpleNamespace

    ps = EpsilonConstraintSolver(_box(), NAMES, SETTINGS)
    ps.anchors()
    assert ps.solve_at({"f2": 0.5, "f3": 0.5}).success  # a converged point with f2 = f3 = 0.5
    real = ps.solver.solve
    monkeypatch.setattr(ps.solver, "solve", lambda **kw: SimpleNamespace(
        success=False, status="Restoration_Failed", iterations=7, wall_time=0.0, setup_time=0.0))
    p = ps.solve_at({"f2": 0.6, "f3": 0.6})
    assert not p.success and p.status == "Restoration_Failed" and "not infeasible" in p.note
    monkeypatch.setattr(ps.solver, "solve", real)
    q = ps.solve_at({"f2": 0.55, "f3": 0.55})  # tighter than the failed point: solved, not skipped
    assert q.success and q.J_f2 <= 0.55 * (1 + 1e-6)


def test_nondominated_nadir_by_hand():
    J = np.array([[1.0, 5.0, 2.0],
                  [2.0, 3.0, 3.0],
                  [4.0, 1.0, 1.0],
                  [3.0, 4.0, 4.0],   # dominated by [2, 3, 3]
                  [9.0, 9.0, 0.5]])  # non-dominated (best f3)
    assert nondominated(J).tolist() == [True, True, True, False, True]
    assert nondominated_nadir(J) == (9.0, 9.0, 3.0)
    assert nondominated_nadir(J[:4]) == (4.0, 5.0, 3.0)
    # equal rows keep each other
    assert nondominated(np.array([[1.0, 2.0], [1.0, 2.0]])).tolist() == [True, True]


def test_snake_path_visits_neighbours_in_turn():
    path = snake((3, 2, 2))
    assert len(path) == len(set(path)) == 12
    assert all(sum(abs(x - y) for x, y in zip(p, q)) == 1 for p, q in zip(path, path[1:]))
    assert snake((2, 3)) == [(0, 0), (0, 1), (0, 2), (1, 2), (1, 1), (1, 0)]


# ------------------------------------------------------------------ [pareto] settings of the N-objective front
CONFIGS = Path(__file__).parent / "configs"


def test_pareto_points_list_max_iter_and_nadir_in_the_config():
    from pyomo_heli.config import ConfigError, load_identification_config

    raw = tomllib.loads((CONFIGS / "case1_tri.toml").read_text())
    del raw["linear"]["points"]
    raw["pareto"].update(points=[5, 5], max_iter=100, nadir="nondominated")
    cfg = load_identification_config(CONFIGS / "case1_tri.toml", raw=raw)
    assert cfg.pareto.grid == (5, 5) and cfg.pareto.points == 5
    assert cfg.pareto.max_iter == 100 and cfg.pareto.nadir == "nondominated"
    bi = load_identification_config(CONFIGS / "case1.toml", {"pareto": {"points": [7]}})
    assert bi.pareto.points == 7 and bi.pareto.grid == (7,) and bi.pareto.max_iter is None
    assert load_identification_config(CONFIGS / "case1.toml").pareto.nadir == "payoff"  # the default
    for overrides, needle in (({"pareto": {"points": [5, 5]}}, "one count per bounded objective"),
                              ({"pareto": {"points": [5, 1]}}, "field 'points'"),
                              ({"pareto": {"nadir": "worst"}}, "pareto.nadir"),
                              ({"pareto": {"max_iter": 0}}, "field 'max_iter'")):
        with pytest.raises(ConfigError) as exc:
            load_identification_config(CONFIGS / "case1.toml", overrides)
        msg = str(exc.value)
        assert "case1.toml" in msg and needle in msg and "\n" not in msg, msg
    with pytest.raises(ConfigError, match=r"\[linear\]: field 'points'.*give it once"):
        load_identification_config(CONFIGS / "case1_tri.toml", {"pareto": {"points": [5, 5]}})


def test_bi_objective_front_and_solve_at_on_the_closed_form():
    """ParetoSolver (two objectives) on J_time = (a-1)^2 + b^2 + 1, J_trim = a^2 + (b-1)^2: min J_time under
    J_trim <= e is the point sqrt(e) from (0, 1) towards (1, 0), a = sqrt(e/2), b = 1 - sqrt(e/2)."""
    from pyomo_heli.pareto.front import ParetoSolver

    m = _model(lambda a, b: ((a - 1) ** 2 + b**2 + 1.0, a**2 + (b - 1) ** 2), names=("time", "trim"))
    m.eps_trim = pyo.Param(initialize=1e20, mutable=True)
    ps = ParetoSolver(m, ParetoSettings(points=5, solver_options=SETTINGS.solver_options, max_iter=100))
    pts = ps.front()
    for p in (p for p in pts if p.kind == "eps"):
        r = math.sqrt(p.epsilon / 2)
        assert p.success and p.iterations < 100
        np.testing.assert_allclose([p.parameters["a"], p.parameters["b"]], [r, 1 - r], atol=1e-5)
    p = ps.solve_at(0.5)  # between grid points: warm from the nearest
    assert p.kind == "eps" and p.epsilon == 0.5 and p.index == 5 and ps.points[-1] is p
    np.testing.assert_allclose([p.parameters["a"], p.parameters["b"]], [0.5, 0.5], atol=1e-6)
    q = ps.solve_at({"trim": -1.0})
    assert q.status == INFEASIBLE and q.iterations == 0
    chosen, d = ps.choose()
    utopia, nadir = ps.utopia_nadir()
    np.testing.assert_allclose(nadir, [3, 2], atol=1e-5)  # J_time(B) = 3 at (0, 1), J_trim(A) = 2 at (1, 0)
    assert ps.utopia_nadir(rule="nondominated")[1] == pytest.approx(nadir, abs=1e-9)  # two objectives: the same
    assert chosen.J_time == pytest.approx(min(p.J_time for p in ps.points if p.success
                                              and math.isclose(utopia_distance_n([[p.J_time, p.J_trim]], utopia,
                                                                                 nadir)[0], d.min())))


def test_a_start_far_from_the_front_does_not_flatten_its_ranges():
    """The same analytic front as above from a = b = 0.3 and from a = b = 3000, where J(theta_0) is 1.8e7, a
    million times the front's values: the ranges are the front's (nadir (3, 2)), and Eq. 11 chooses the same
    point and reaches its closed form a = b = 0.5. (Before, the initial guess's size was every range's floor:
    both ranges counted as solver noise and Eq. 11 silently chose anchor A.)"""
    from pyomo_heli.pareto.front import ParetoSolver

    chosen = {}
    for start in (0.3, 3000.0):
        m = _model(lambda a, b: ((a - 1) ** 2 + b**2 + 1.0, a**2 + (b - 1) ** 2), names=("time", "trim"))
        m.theta_s.set_values({"a": start, "b": start})
        m.theta_s.setlb(-1e4)
        m.theta_s.setub(1e4)
        m.eps_trim = pyo.Param(initialize=1e20, mutable=True)
        ps = ParetoSolver(m, ParetoSettings(points=6, spacing="linear", solver_options=SETTINGS.solver_options))
        ps.front()
        np.testing.assert_allclose(ps.utopia_nadir()[1], [3, 2], atol=5e-3)
        chosen[start], _ = ps.choose()
        direct = ps.direct_choice(chosen[start])
        np.testing.assert_allclose([direct.parameters["a"], direct.parameters["b"]], [0.5, 0.5], atol=1e-3)
    assert chosen[3000.0].kind == "eps" and chosen[3000.0].index == chosen[0.3].index


def test_row_minima_settle_the_infeasible_grid_points_without_solving_them():
    """The discs f2 <= e2 around (0, 1) and f3 <= e3 around (-1, 0), centres sqrt(2) apart: under f2 <= e2
    the least f3 is (sqrt(2) - sqrt(e2))^2 (closed form). Each grid row solves that once; a point of the row
    with e3 below it is infeasible a priori (0 iterations), every other point converges."""
    m = _model(lambda a, b: ((a - 1) ** 2 + b**2 + 1.0, a**2 + (b - 1) ** 2, (a + 1) ** 2 + b**2))
    ps = EpsilonConstraintSolver(m, NAMES, SETTINGS)
    ps.grid_front((3, 3))
    e2_axis, e3_axis = ps.axes
    for i, e2 in enumerate(e2_axis):
        lo = max(math.sqrt(2) - math.sqrt(e2), 0.0) ** 2
        assert ps.row_minima[i] == pytest.approx(lo, rel=1e-5, abs=1e-8)
    assert [r["row"] for r in ps.row_solves] == [1, 2]  # row 0: anchor C's minimum, no solve
    grid = [p for p in ps.points if p.kind == "eps"]
    assert len(grid) == 8
    for p in grid:
        i, j = p.grid
        if e3_axis[j] < ps.row_minima[i]:
            assert p.status == INFEASIBLE and p.iterations == 0 and "under J_f2 <=" in p.note
        else:
            assert p.success and 0 < p.iterations < SETTINGS.max_iter
    assert sum(p.status == INFEASIBLE for p in grid) == 3  # (1, 2), (2, 1), (2, 2)


def test_column_0_leaves_the_last_objective_free_where_it_rises_above_its_value_at_A():
    """f1 = (a - 1)^2 + b^2 + 1, f2 = a^2 + (b - 1)^2, f3 = (a - 1)^2 + (b + 1)^2: A = (1, 0) with f3(A) = 1, and
    f3 rises towards B = (0, 1). Under f2 <= e2 the least f3 is (sqrt(5) - sqrt(e2))^2 > 1 on rows 1, 2, so
    every bounded column there is infeasible; column 0 (f3 free) is the f1-f2 front, in closed form
    (0, 1) + sqrt(e2) (1, -1) / sqrt(2), with f3 above f3(A) (bounded at f3(A) it would be infeasible)."""
    m = _model(lambda a, b: ((a - 1) ** 2 + b**2 + 1.0, a**2 + (b - 1) ** 2, (a - 1) ** 2 + (b + 1) ** 2))
    ps = EpsilonConstraintSolver(m, NAMES, SETTINGS)
    ps.grid_front((3, 3))
    e2_axis, _ = ps.axes
    grid = {p.grid: p for p in ps.points if p.kind == "eps"}
    # C = (1, -1) has f2 = 5 > f2(A) = 2: row 0's bound is active at C, so its minimum is solved too
    assert [r["row"] for r in ps.row_solves] == [0, 1, 2]
    for i in (0, 1, 2):
        assert ps.row_minima[i] == pytest.approx((math.sqrt(5) - math.sqrt(e2_axis[i])) ** 2, rel=1e-5)
    for j in (1, 2):  # e3 = 0.224, 0.05 below row 0's least f3 0.675: infeasible without a solve
        assert grid[(0, j)].status == INFEASIBLE and grid[(0, j)].iterations == 0
    for i in (1, 2):
        p = grid[(i, 0)]
        assert p.success and p.epsilon["f3"] == math.inf and 0 < p.iterations < SETTINGS.max_iter
        r = math.sqrt(e2_axis[i] / 2)
        np.testing.assert_allclose([p.parameters["a"], p.parameters["b"]], [r, 1 - r], atol=1e-5)
        assert p.J_f3 > 1.5  # above f3(A) = 1
    converged = sorted(q for q, p in grid.items() if p.success)
    assert converged == [(1, 0), (2, 0)]
    assert all(p.status == INFEASIBLE for q, p in grid.items() if q not in converged)


def test_grid_start_is_the_distance_to_the_bounds_where_a_start_is_a_solution(box_front):
    """By hand, in the box problem's anchor ranges (f2, f3: 1 - 0 = 1 each): a start is still a solution where its
    objective vector meets the new bounds and no bound active at it is loosened; the distance to that set is the
    violation plus the loosening (bounds above the value at A read as that value)."""
    ps = box_front
    s = GridStart("s", {"f2": 0.5, "f3": 0.2}, {"f2": 0.5, "f3": 0.6}, snapshot=None)  # f2 active, f3 not
    assert ps.start_distance(s, {"f2": 0.4, "f3": 0.9}) == pytest.approx(0.1)  # f2 exceeds 0.4 by 0.1
    assert ps.start_distance(s, {"f2": 0.7, "f3": 0.1}) == pytest.approx(0.2 + 0.1)  # f2 loosened, f3 exceeded
    assert ps.start_distance(s, {"f2": math.inf, "f3": 0.3}) == pytest.approx(0.5)  # free f2: up to f2(A) = 1
    assert ps.start_distance(s, {"f2": 0.5, "f3": 0.25}) == 0.0  # f3 inactive at s: tightening it to 0.25 is free
    free = GridStart("free", {"f2": 0.3, "f3": 0.3}, {"f2": math.inf, "f3": math.inf}, snapshot=None)
    assert ps.start_distance(free, {"f2": 0.9, "f3": 0.9}) == 0.0 and ps.start_violation(free, {"f2": 0.2}) == \
        pytest.approx(0.1)
    saved = ps.starts
    try:
        ps.starts = [free, s]
        assert ps.grid_start({"f2": 0.45, "f3": 0.9}) is free  # 0.0 against 0.05
        assert ps.grid_start({"f2": 0.5, "f3": 0.25}) is s  # free: 0.05 against 0 for s
        assert ps.grid_start({"f2": 0.25, "f3": 0.25}) is free  # 0.1 against 0.25
        assert ps.grid_start({"f2": 0.45, "f3": 0.25}) is s  # a tie (0.05, 0.05): the latest
        assert ps.known_feasible({"f2": 0.3, "f3": 0.3}) and not ps.known_feasible({"f2": 0.29, "f3": 0.9})
    finally:
        ps.starts = saved


def test_every_grid_point_records_its_start_and_the_rows_are_solved_only_where_needed():
    """On the disc problem each grid point's ``start`` is the least :meth:`start_distance` over A, the grid points
    solved before it and the row minima solved before it (recomputed here), and a start at distance 0 is already
    the answer: the solve confirms it in at most 2 iterations, at the same parameters."""
    m = _model(lambda a, b: ((a - 1) ** 2 + b**2 + 1.0, a**2 + (b - 1) ** 2, (a + 1) ** 2 + b**2))
    ps = EpsilonConstraintSolver(m, NAMES, SETTINGS)
    ps.grid_front((4, 4))
    grid = [p for p in ps.points if p.kind == "eps"]
    by_label = {s.label: s for s in ps.starts}
    for n, p in enumerate(grid):
        before = [by_label["anchor A"]] + [by_label[f"point {q.index} {q.grid}"] for q in grid[:n] if q.success]
        before += [s for s in ps.starts if s.label.startswith("row") and s.label in by_label]
        if p.status == INFEASIBLE and p.iterations == 0:
            continue
        d = {s.label: ps.start_distance(s, p.epsilon) for s in before if s.label.startswith(("anchor", "point"))
             or int(s.label.split()[1]) <= p.grid[0]}
        assert d[p.start] == pytest.approx(min(d.values()), abs=1e-12), (p.grid, p.start, d)
        if d[p.start] == 0.0 and p.start.startswith("point"):
            q = next(q for q in grid if f"point {q.index} {q.grid}" == p.start)
            assert p.iterations <= 2 and p.parameters == pytest.approx(q.parameters, abs=1e-6)
    assert [r["row"] for r in ps.row_solves] == [1, 2, 3]  # row 0: anchor C's minimum


def test_a_solution_that_meets_the_bounds_is_the_start_and_no_row_minimum_is_needed():
    """f1 = a^2 + b^2, f2 = (a - 1)^2, f3 = (a - 1)^2 + (b - 1)^2. Closed form of min f1 s.t. f2 <= e2, f3 <= e3:
    a = b = 1 - sqrt(e3 / 2) while e3 / 2 <= e2 (f2 inactive); a = 1 - sqrt(e2), b = 0 while e2 + 1 <= e3 (f3
    inactive); else a = 1 - sqrt(e2), b = 1 - sqrt(e3 - e2). Anchor C = (1, 1) lies in the grid's box (its f2 is
    0), so row 0's least f3 is C's; every later row meets its first point with a solution already at hand (the
    f3-tightest column keeps f2 = 0.05, below every row's bound but the last), so no row minimum is solved. A
    point whose start is at distance 0, f2 inactive there, gets it back in one or two iterations."""
    m = _model(lambda a, b: (a**2 + b**2, (a - 1) ** 2, (a - 1) ** 2 + (b - 1) ** 2))
    ps = EpsilonConstraintSolver(m, NAMES, SETTINGS)
    ps.grid_front((4, 4))

    def closed(e2, e3):
        e3 = min(e3, 2.0)  # free: f3(A) = 2
        if e3 / 2 <= e2:
            return [1 - math.sqrt(e3 / 2)] * 2
        if e2 + 1 <= e3:
            return [1 - math.sqrt(e2), 0.0]
        return [1 - math.sqrt(e2), 1 - math.sqrt(e3 - e2)]

    grid = [p for p in ps.points if p.kind == "eps"]
    assert len(grid) == 15 and all(p.success and p.iterations < SETTINGS.max_iter for p in grid)
    for p in grid:
        np.testing.assert_allclose([p.parameters["a"], p.parameters["b"]], closed(p.epsilon["f2"], p.epsilon["f3"]),
                                   atol=1e-5)
    assert ps.row_solves == []
    by_label = {s.label: s for s in ps.starts}
    # distance 0 with f2 clear of the new bound (on the diagonal e3 / 2 = e2 both bounds are just active there)
    exact = [p for p in grid if ps.start_distance(by_label[p.start], p.epsilon) == 0.0
             and by_label[p.start].J["f2"] < p.epsilon["f2"] - 1e-3]
    assert sorted(p.grid for p in exact) == [(1, 2), (1, 3), (2, 3)]
    for p in exact:
        q = next(q for q in grid if f"point {q.index} {q.grid}" == p.start)
        assert p.iterations <= 2 and p.parameters == pytest.approx(q.parameters, abs=1e-6)


def test_where_one_objective_alone_has_a_range_its_anchor_is_the_direct_choice_without_a_solve():
    """The full-size case behind it (fuselage_pitch_damping 24, M0 + dM_q): J_time's range on the front was solver
    noise, so Eq. 11 weighed J_trim alone, and a direct solve could leave the front along J_time. With one objective
    ranged, Eq. 11 is zero at that objective's own anchor: the direct choice is the anchor, not solved. Here f1
    moves by 1e-9 of its size along the front (noise), f2 from 1.09 to 0: the choice is anchor B, (a, b) = (1, 0)."""
    m = _model(lambda a, b: (5.0 + 1e-9 * a**2, (a - 1) ** 2 + b**2), names=("f1", "f2"))
    settings = ParetoSettings(points=[4], solver_options={"tol": 1e-10, "constr_viol_tol": 1e-13}, max_iter=100)
    ps = EpsilonConstraintSolver(m, ("f1", "f2"), settings)
    ps.grid_front(settings.grid)
    utopia, nadir = ps.utopia_nadir("payoff")
    assert nadir[0] == utopia[0] and nadir[1] > utopia[1] + 1.0  # f1: noise; f2: ranged
    calls = []
    ps._direct_once = lambda u, n: calls.append(1)
    try:
        direct = ps.direct_choice(rule="payoff")
    finally:
        del ps._direct_once
    assert calls == [] and direct.success and direct.kind == "direct" and direct.iterations == 0
    assert "only J_f2 has a range" in direct.warm_start and "anchor B" in direct.warm_start
    np.testing.assert_allclose([direct.parameters["a"], direct.parameters["b"]], [1.0, 0.0], atol=1e-5)
    assert utopia_distance_n([[direct.J_f1, direct.J_f2]], utopia, nadir)[0] == pytest.approx(0.0, abs=1e-5)
