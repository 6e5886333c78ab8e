"""Tests of the NLP solver layer (pyomo_heli.solvers): small problems with known answers."""

import math

import pyomo.environ as pyo
import pytest

from pyomo_heli.solvers import (
    SOLVER_NAMES,
    ModelChangedError,
    SolveResult,
    SolverUnavailableError,
    available_solvers,
    make_solver,
    scale_multipliers,
)
from pyomo_heli.solvers.casadi_ipopt import resolve_options

AVAILABLE = available_solvers()
BACKENDS = [
    pytest.param(name, marks=pytest.mark.skipif(name not in AVAILABLE, reason=f"{name} not available"))
    for name in ("casadi-ipopt", "pounce")
]


# ---------------------------------------------------------------- problems
def disk_problem():
    """min (x-1)^2+(y-2)^2 s.t. x+y <= 1: x=0, y=1, KKT multiplier 2.

    Pyomo/ASL dual = d(objective)/d(rhs) = -2 for this minimisation.
    """
    m = pyo.ConcreteModel()
    m.x = pyo.Var(initialize=0.0)
    m.y = pyo.Var(initialize=0.0)
    m.c = pyo.Constraint(expr=m.x + m.y <= 1)
    m.o = pyo.Objective(expr=(m.x - 1) ** 2 + (m.y - 2) ** 2)
    return m


def bound_problem(sense=pyo.minimize):
    """min (x-2)^2+(y+1)^2+z^2 s.t. x<=1, y>=0, x+z>=1.5 (non-degenerate).

    Optimum x=1, y=0, z=0.5; multipliers: constraint 1, upper bound of x 3,
    lower bound of y 2. ``sense=maximize`` solves the negated objective, so
    the point is the same and every ASL multiplier flips sign.
    """
    s = 1 if sense == pyo.minimize else -1
    m = pyo.ConcreteModel()
    m.x = pyo.Var(initialize=0.5, bounds=(None, 1))
    m.y = pyo.Var(initialize=0.5, bounds=(0, None))
    m.z = pyo.Var(initialize=0.0)
    m.w = pyo.Var(initialize=7.0)  # fixed, used: not in the NL, must stay 7
    m.w.fix()
    m.c = pyo.Constraint(expr=m.x + m.z >= 1.5)
    m.o = pyo.Objective(expr=s * ((m.x - 2) ** 2 + (m.y + 1) ** 2 + m.z**2 + 3 + 0 * m.w), sense=sense)
    return m


def rosenbrock_eps(eps, n=4):
    """Extended Rosenbrock with an epsilon constraint J2 = |x|^2 <= eps (Param in the bound)."""
    m = pyo.ConcreteModel()
    m.I = pyo.RangeSet(0, n - 1)
    m.x = pyo.Var(m.I, initialize=lambda m, i: -1.2 if i % 2 == 0 else 1.0, bounds=(-3, 3))
    m.eps = pyo.Param(initialize=eps, mutable=True)
    m.J2 = pyo.Expression(expr=sum(m.x[i] ** 2 for i in m.I))
    m.eps_con = pyo.Constraint(expr=m.J2 <= m.eps)
    m.o = pyo.Objective(
        expr=sum(100 * (m.x[i + 1] - m.x[i] ** 2) ** 2 + (1 - m.x[i]) ** 2 for i in range(n - 1))
    )
    return m


def xs(m):
    return [pyo.value(m.x[i]) for i in m.I]


# ------------------------------------------------------------------- (a) KKT
@pytest.mark.parametrize("name", BACKENDS)
def test_constraint_dual_matches_analytic_kkt(name):
    m = disk_problem()
    res = make_solver(m, name).solve(warm_start="none")
    assert isinstance(res, SolveResult)
    assert res.success and res.status == "Solve_Succeeded"
    assert res.iterations > 0
    assert m.x.value == pytest.approx(0.0, abs=1e-6)
    assert m.y.value == pytest.approx(1.0, abs=1e-6)
    assert res.objective == pytest.approx(2.0, abs=1e-6)
    # analytic KKT multiplier +2 of "x+y<=1"; ASL dual is d(obj)/d(rhs) = -2
    assert m.dual[m.c] == pytest.approx(-2.0, abs=1e-6)


@pytest.mark.parametrize("name", BACKENDS)
@pytest.mark.parametrize("sense", [pyo.minimize, pyo.maximize], ids=["min", "max"])
def test_bound_multipliers_and_objective_sense(name, sense):
    m = bound_problem(sense)
    res = make_solver(m, name).solve()
    s = 1 if sense == pyo.minimize else -1
    assert res.success
    assert (m.x.value, m.y.value, m.z.value) == pytest.approx((1.0, 0.0, 0.5), abs=1e-6)
    assert m.w.value == 7.0 and m.w.fixed
    assert res.objective == pytest.approx(s * 5.25, abs=1e-6)
    assert res.objective == pytest.approx(pyo.value(m.o), abs=1e-9)
    assert m.dual[m.c] == pytest.approx(s * 1.0, abs=1e-6)
    assert m.ipopt_zU_out[m.x] == pytest.approx(s * -3.0, abs=1e-6)  # ASL: zU <= 0 (min)
    assert m.ipopt_zL_out[m.y] == pytest.approx(s * 2.0, abs=1e-6)  # ASL: zL >= 0 (min)


@pytest.mark.skipif("pounce" not in AVAILABLE, reason="pounce not available")
@pytest.mark.parametrize("sense", [pyo.minimize, pyo.maximize], ids=["min", "max"])
def test_casadi_and_pounce_agree(sense):
    got = {}
    for name in ("casadi-ipopt", "pounce"):
        m = bound_problem(sense)
        make_solver(m, name).solve()
        got[name] = (
            [m.x.value, m.y.value, m.z.value, m.dual[m.c]]
            + [m.ipopt_zL_out.get(v, 0.0) for v in (m.x, m.y, m.z)]
            + [m.ipopt_zU_out.get(v, 0.0) for v in (m.x, m.y, m.z)]
        )
    assert got["casadi-ipopt"] == pytest.approx(got["pounce"], abs=1e-6)


# ------------------------------------------------------ (c) eps re-solves
def test_eps_resolve_without_rebuild_matches_fresh_model():
    m = rosenbrock_eps(2.0)
    solver = make_solver(m)
    first = solver.solve(warm_start="none")
    assert first.success and first.setup_time > 0
    for eps in (1.5, 1.0):
        m.eps = eps
        res = solver.solve(warm_start="primal")
        assert res.success and res.setup_time == 0.0
        assert pyo.value(m.J2) == pytest.approx(eps, abs=1e-6)  # constraint active at new eps
        fresh = rosenbrock_eps(eps)
        ref = make_solver(fresh).solve(warm_start="none")
        assert res.objective == pytest.approx(ref.objective, rel=1e-6)
        assert xs(m) == pytest.approx(xs(fresh), abs=1e-5)
    # the eps-constraint dual is the Pareto slope dJ1/deps (< 0 here)
    slope = m.dual[m.eps_con]
    m.eps = 1.0 - 1e-4
    before = pyo.value(m.o)
    solver.solve()
    assert (pyo.value(m.o) - before) / -1e-4 == pytest.approx(slope, rel=1e-2)


@pytest.mark.parametrize("name", BACKENDS)
@pytest.mark.parametrize("mode", ["primal", "full", "continuation"])
def test_warm_resolve_is_cheaper_than_cold(name, mode):
    m = rosenbrock_eps(2.0)
    solver = make_solver(m, name)
    assert solver.solve(warm_start="none").success
    m.eps = 1.8
    warm = solver.solve(warm_start=mode)
    cold = make_solver(rosenbrock_eps(1.8), name).solve(warm_start="none")
    assert warm.success and cold.success
    assert warm.objective == pytest.approx(cold.objective, rel=1e-6)
    assert warm.iterations < cold.iterations


def test_continuation_starts_the_barrier_at_tol_over_ten():
    opts, _, _ = resolve_options({"tol": 1e-6}, None, "continuation")
    assert opts["mu_init"] == pytest.approx(1e-7) and opts["warm_start_init_point"] == "yes"
    assert resolve_options({"mu_init": 1e-3}, None, "continuation")[0]["mu_init"] == 1e-3  # the user's value wins
    assert "mu_init" not in resolve_options(None, None, "primal")[0]


@pytest.mark.parametrize("name", BACKENDS)
def test_rescaled_multipliers_warm_start_a_rescaled_objective(name):
    """Multipliers scale with the objective: after scale_multipliers the continuation start is consistent."""
    m = rosenbrock_eps(2.0)
    solver = make_solver(m, name)
    assert solver.solve(warm_start="none").success
    d0 = m.dual[m.eps_con]
    m.o.deactivate()
    m.o10 = pyo.Objective(expr=10 * m.o.expr)
    solver = make_solver(m, name)  # new objective: a new NL
    scale_multipliers(m, 10.0)
    assert m.dual[m.eps_con] == pytest.approx(10 * d0)
    res = solver.solve(warm_start="continuation")
    assert res.success and res.iterations <= 3
    assert m.dual[m.eps_con] == pytest.approx(10 * d0, rel=1e-5)


@pytest.mark.skipif("pounce" not in AVAILABLE, reason="pounce not available")
def test_full_warm_start_from_pounce_multipliers():
    """The suffixes are the hand-over format: casadi warm-starts from pounce's duals."""
    m = rosenbrock_eps(2.0)
    assert make_solver(m, "pounce").solve().success
    m.eps = 1.8
    warm = make_solver(m).solve(warm_start="full")
    cold = make_solver(rosenbrock_eps(1.8)).solve(warm_start="none")
    assert warm.success and warm.objective == pytest.approx(cold.objective, rel=1e-6)
    assert warm.iterations < cold.iterations


def chain_with_dense_row(n=400):
    """A dense row (sum over all states) plus a dense column (parameter p in every step)."""
    m = pyo.ConcreteModel()
    m.I = pyo.RangeSet(0, n - 1)
    m.p = pyo.Var(initialize=1.0, bounds=(0.1, 5))
    m.x = pyo.Var(m.I, initialize=0.1)
    m.eps = pyo.Param(initialize=0.5 * n, mutable=True)
    m.step = pyo.Constraint(
        range(n - 1), rule=lambda m, i: m.x[i + 1] == m.x[i] + 0.01 * (1 - m.p * pyo.sin(m.x[i]))
    )
    m.eps_con = pyo.Constraint(expr=sum(m.x[i] ** 2 for i in m.I) <= m.eps)
    m.o = pyo.Objective(expr=sum((m.x[i] - 1.0) ** 2 for i in m.I) + (m.p - 2) ** 2)
    return m


def test_dense_row_jacobian_is_fast_and_exact():
    m = chain_with_dense_row()
    res = make_solver(m).solve()
    assert res.success and res.setup_time < 3.0  # casadi's own colouring: ~15 s at n=4000
    fast = [m.p.value] + xs(m) + [m.dual[m.eps_con]]
    from pyomo_heli.solvers.casadi_ipopt import CasadiSettings

    m2 = chain_with_dense_row()
    assert make_solver(m2, settings=CasadiSettings(dense_row_threshold=10**9)).solve().success  # casadi's Jacobian
    assert fast == pytest.approx([m2.p.value] + xs(m2) + [m2.dual[m2.eps_con]], abs=1e-7)


def test_params_in_lower_bound_and_equality_rows_are_refreshed():
    m = pyo.ConcreteModel()
    m.x = pyo.Var(initialize=0.0)
    m.y = pyo.Var(initialize=0.0)
    m.q = pyo.Param(initialize=3.0, mutable=True)
    m.r = pyo.Param(initialize=0.0, mutable=True)
    m.sum = pyo.Constraint(expr=m.x + m.y + 1 >= m.q)  # body constant moves into the NL bound
    m.diff = pyo.Constraint(expr=m.x - m.y == m.r)
    m.o = pyo.Objective(expr=m.x**2 + m.y**2)
    solver = make_solver(m)
    solver.solve()
    assert (m.x.value, m.y.value) == pytest.approx((1.0, 1.0), abs=1e-6)
    m.q, m.r = 5.0, 1.0
    assert solver.solve().success
    assert (m.x.value, m.y.value) == pytest.approx((2.5, 1.5), abs=1e-6)
    assert m.dual[m.sum] == pytest.approx(4.0, abs=1e-6)  # d(obj)/dq = x+y = 4


def test_variable_bound_change_is_honoured():
    m = bound_problem()
    solver = make_solver(m)
    solver.solve()
    m.x.setub(0.8)
    res = solver.solve()
    assert res.success and m.x.value == pytest.approx(0.8, abs=1e-6)


# ---------------------------------------------------- (d) failures, no raise
@pytest.mark.parametrize("name", BACKENDS)
def test_infeasible_returns_failure(name):
    m = pyo.ConcreteModel()
    m.x = pyo.Var(initialize=0.5)
    m.y = pyo.Var(initialize=0.5)
    m.disk = pyo.Constraint(expr=m.x**2 + m.y**2 <= 1)
    m.far = pyo.Constraint(expr=m.x + m.y >= 3)
    m.o = pyo.Objective(expr=(m.x - 1) ** 2 + m.y**2)
    res = make_solver(m, name).solve(options={"max_iter": 500})
    assert not res.success
    assert res.status == "Infeasible_Problem_Detected"
    assert "infeasib" in res.message.lower()


@pytest.mark.parametrize("name", BACKENDS)
def test_max_iter_returns_failure(name):
    m = rosenbrock_eps(1e6)
    res = make_solver(m, name).solve(options={"max_iter": 2})
    assert not res.success
    assert res.status == "Maximum_Iterations_Exceeded"
    assert res.iterations == 2
    assert math.isfinite(res.objective)


# ------------------------------------------------- (e) stale NL is detected
def test_changed_fixed_value_requires_rebuild():
    m = bound_problem()
    m.o.deactivate()
    m.o2 = pyo.Objective(expr=(m.x - m.w) ** 2 + (m.y + 1) ** 2 + m.z**2)
    solver = make_solver(m)
    solver.solve()
    m.w.fix(0.0)
    with pytest.raises(ModelChangedError, match=r"fixed variable w .*rebuild\(\)"):
        solver.solve()
    solver.rebuild()
    res = solver.solve()
    assert res.success and res.setup_time > 0
    assert (m.x.value, m.z.value) == pytest.approx((0.75, 0.75), abs=1e-6)  # min x^2+z^2 on x+z>=1.5


def test_fixing_a_free_variable_requires_rebuild():
    m = bound_problem()
    solver = make_solver(m)
    m.z.fix(0.0)
    with pytest.raises(ModelChangedError, match="now fixed"):
        solver.solve()


def test_param_in_constraint_body_requires_rebuild():
    m = rosenbrock_eps(2.0)
    m.p = pyo.Param(initialize=0.0, mutable=True)
    m.eps_con.set_value(m.J2 - m.p <= m.eps)
    solver = make_solver(m)
    m.p = 0.1
    with pytest.raises(ModelChangedError, match="Param p"):
        solver.solve()


# ----------------------------------------------------------- (f) factory
def test_unknown_solver_name_lists_choices():
    with pytest.raises(ValueError) as info:
        make_solver(disk_problem(), "cplex")
    for name in SOLVER_NAMES:
        assert name in str(info.value)


def test_available_solvers_and_unavailable_error():
    assert "casadi-ipopt" in AVAILABLE
    assert set(AVAILABLE) <= set(SOLVER_NAMES)
    for name in set(SOLVER_NAMES) - set(AVAILABLE):
        with pytest.raises(SolverUnavailableError, match=name):
            make_solver(disk_problem(), name)


def test_bad_warm_start_mode_and_result_str():
    solver = make_solver(disk_problem())
    with pytest.raises(ValueError, match="warm_start"):
        solver.solve(warm_start="hot")
    text = str(solver.solve())
    assert "Solve_Succeeded" in text and "casadi-ipopt" in text


def chain_with_dense_blocks(n=2500, k=24):
    """chain_with_dense_row plus a small dense Hessian block.

    Dense Jacobian column and Hessian row/column: p (in every step). Dense
    Jacobian rows: the epsilon row and ``block``; ``block`` couples the k
    variables y in a dense k x k Hessian block while each y sits in one row
    (the trim-block pattern of the identification NLPs).
    """
    m = pyo.ConcreteModel()
    m.I = pyo.RangeSet(0, n - 1)
    m.K = pyo.RangeSet(0, k - 1)
    m.p = pyo.Var(initialize=1.0, bounds=(0.1, 5))
    m.x = pyo.Var(m.I, initialize=0.1)
    m.y = pyo.Var(m.K, initialize=0.0, bounds=(-2, 2))
    m.eps = pyo.Param(initialize=0.5 * n, mutable=True)
    m.step = pyo.Constraint(
        range(n - 1), rule=lambda m, i: m.x[i + 1] == m.x[i] + 0.01 * (1 - m.p * pyo.sin(m.x[i]))
    )
    m.eps_con = pyo.Constraint(expr=sum(m.x[i] ** 2 for i in m.I) <= m.eps)
    m.block = pyo.Constraint(expr=pyo.exp(sum(0.1 * (j + 1) * m.y[j] for j in m.K)) <= 2.0 + m.p)
    m.o = pyo.Objective(
        expr=sum((m.x[i] - 1.0) ** 2 for i in m.I) + (m.p - 2) ** 2 + sum(m.y[j] ** 2 - m.y[j] for j in m.K)
    )
    return m


def test_blockwise_hessian_equals_casadi_hessian():
    import numpy as np

    from pyomo_heli.solvers.casadi_ipopt import CasadiSettings, resolve_options

    def build(custom):
        m = chain_with_dense_blocks()
        solver = make_solver(m, settings=CasadiSettings(custom_hessian=custom))
        opts, verbose, _ = resolve_options(solver.options, None, "primal")
        hess = solver._solver_for(opts, verbose).get_function("nlp_hess_l")
        return m, solver, hess

    m1, custom, h1 = build(True)
    assert custom._hessian_split == {"S": 2500, "D2": 24, "D1": 1}  # every block is exercised
    m2, default, h2 = build(False)
    assert h1.sparsity_out(0) == h2.sparsity_out(0)
    rng = np.random.default_rng(1)
    x = rng.uniform(-1, 1, h1.size1_in(0))
    lam_g = rng.standard_normal(h1.size1_in(3))
    a = np.array(h1(x, [], 0.7, lam_g).nonzeros())
    b = np.array(h2(x, [], 0.7, lam_g).nonzeros())
    assert a == pytest.approx(b, rel=1e-12, abs=1e-12)

    r1, r2 = custom.solve(), default.solve()
    assert r1.success and r2.success
    assert r1.iterations == r2.iterations
    assert r1.objective == pytest.approx(r2.objective, rel=1e-12)
    got1 = [m1.p.value, m1.dual[m1.block], m1.dual[m1.eps_con]] + xs(m1) + [m1.y[j].value for j in m1.K]
    got2 = [m2.p.value, m2.dual[m2.block], m2.dual[m2.eps_con]] + xs(m2) + [m2.y[j].value for j in m2.K]
    assert got1 == pytest.approx(got2, abs=1e-9)
