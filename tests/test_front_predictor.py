"""The secant predictor of the front's warm starts (pyomo_heli.pareto.front): arithmetic and effect.

Checked against hand-computed extrapolations and, on an epsilon-constrained
Rosenbrock problem, against the solution of the next point solved from the
last one without the predictor (same optimum, the predicted start is nearer).
"""
import pyomo.environ as pyo
import pytest

from pyomo_heli.pareto.front import ParetoSettings
from pyomo_heli.pareto.snapshot import Snapshot
from pyomo_heli.solvers import make_solver

from test_solvers import rosenbrock_eps, xs


def test_extrapolation_is_linear_clipped_to_bounds_and_keeps_multiplier_signs():
    m = pyo.ConcreteModel()
    m.x = pyo.Var(initialize=1.0)
    m.y = pyo.Var(initialize=0.5, bounds=(0, 1))
    m.f = pyo.Var(initialize=3.0)
    m.f.fix()
    m.c = pyo.Constraint(expr=m.x + m.y <= 2)
    m.dual = pyo.Suffix(direction=pyo.Suffix.IMPORT_EXPORT)
    m.ipopt_zL_out = pyo.Suffix(direction=pyo.Suffix.IMPORT)
    m.dual[m.c] = -1.0
    m.ipopt_zL_out[m.y] = 0.2
    old = Snapshot(m)
    m.x.set_value(2.0)
    m.y.set_value(0.8)
    m.dual[m.c] = -3.0
    m.ipopt_zL_out[m.y] = 0.1
    new = Snapshot(m)
    new.extrapolated(old, 0.5).restore()
    assert m.x.value == pytest.approx(2.5)  # 2 + 0.5 (2 - 1)
    assert m.y.value == pytest.approx(0.95)  # 0.8 + 0.5 (0.8 - 0.5)
    assert m.dual[m.c] == pytest.approx(-4.0)
    assert m.ipopt_zL_out[m.y] == pytest.approx(0.05)
    assert m.f.value == 3.0  # fixed: untouched
    new.extrapolated(old, 2.0).restore()
    assert m.y.value == 1.0  # 0.8 + 0.6 clipped to the upper bound
    assert m.ipopt_zL_out[m.y] == pytest.approx(0.1)  # 0.1 - 0.2 would change sign: kept
    with pytest.raises(ValueError, match="pareto.predictor"):
        ParetoSettings(predictor="quadratic")


def test_extrapolation_keeps_missing_values_and_new_multipliers():
    m = pyo.ConcreteModel()
    m.x = pyo.Var(initialize=1.0)
    m.z = pyo.Var()  # never given a value
    m.c = pyo.Constraint(expr=m.x >= 0)
    m.dual = pyo.Suffix(direction=pyo.Suffix.IMPORT_EXPORT)
    old = Snapshot(m)
    m.x.set_value(2.0)
    m.dual[m.c] = 0.7  # only the newer snapshot has this multiplier
    new = Snapshot(m)
    m.z.set_value(5.0)
    new.extrapolated(old, 0.5).restore()
    assert m.x.value == pytest.approx(2.5)
    assert m.z.value is None
    assert m.dual[m.c] == pytest.approx(0.7)
    m.w = pyo.Var(initialize=0.0)
    with pytest.raises(ValueError, match="different models"):
        Snapshot(m).extrapolated(old, 0.5)


def test_secant_start_is_nearer_and_solves_to_the_same_point():
    m = rosenbrock_eps(2.0)
    solver = make_solver(m)
    grid = (1.6, 1.4, 1.2)
    m.eps = grid[0]
    assert solver.solve(warm_start="none").success
    s0 = Snapshot(m)
    m.eps = grid[1]
    assert solver.solve(warm_start="continuation").success
    s1 = Snapshot(m)
    # the reference: the next point solved from the last solution
    m.eps = grid[2]
    plain = solver.solve(warm_start="continuation")
    target = xs(m)
    # the same point from the secant prediction
    predicted = s1.extrapolated(s0, (grid[2] - grid[1]) / (grid[1] - grid[0]))
    predicted.restore()
    start = xs(m)
    s1.restore()
    last = xs(m)
    predicted.restore()
    res = solver.solve(warm_start="continuation")
    assert plain.success and res.success
    assert res.objective == pytest.approx(plain.objective, rel=1e-8)
    assert xs(m) == pytest.approx(target, abs=1e-6)
    dist = lambda a: sum((u - v) ** 2 for u, v in zip(a, target)) ** 0.5  # noqa: E731
    assert dist(start) < 0.5 * dist(last)
    assert res.iterations <= plain.iterations
