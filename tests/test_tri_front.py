"""Tri-objective epsilon-constraint front and Eq. 11 for three objectives, on an analytic problem."""
import math

import numpy as np
import pyomo.environ as pyo

from pyomo_heli.pareto.front import ParetoSettings
from pyomo_heli.pareto.tri_front import TriParetoSolver, utopia_distance_n


def _toy():
    """Three convex quadratics of (a, b), minima at (1, 0), (0, 1), (-1, 0).

    Analytic facts: each single-objective minimum is its own point; the Pareto set is the
    triangle spanned by the three minima; the lexicographic anchor B (min J_trim, then J_time)
    is (0, 1) exactly since J_trim's minimiser is unique.
    """
    m = pyo.ConcreteModel()
    m.free_parameters = pyo.Set(initialize=["a", "b"], ordered=True)
    m.theta_s = pyo.Var(m.free_parameters, initialize=0.3, bounds=(-5, 5))
    m.theta_scale = pyo.Param(m.free_parameters, initialize=1.0)
    a, b = m.theta_s["a"], m.theta_s["b"]
    m.J_time = pyo.Expression(expr=(a - 1) ** 2 + b**2 + 1.0)
    m.J_trim = pyo.Expression(expr=a**2 + (b - 1) ** 2)
    m.J_linear = pyo.Expression(expr=(a + 1) ** 2 + b**2)
    m.eps_trim = pyo.Param(initialize=1e20, mutable=True)
    m.eps_con = pyo.Constraint(expr=m.J_trim <= m.eps_trim)
    return m


def test_tri_front_on_analytic_problem():
    m = _toy()
    ps = TriParetoSolver(m, ParetoSettings(points=3, solver="casadi-ipopt", solver_options={"tol": 1e-10}),
                         linear_points=3)
    pts = ps.front()
    a, b, c = ps.anchor_points["A"], ps.anchor_points["B"], ps.anchor_points["C"]
    np.testing.assert_allclose([a.parameters["a"], a.parameters["b"]], [1, 0], atol=1e-6)
    np.testing.assert_allclose([b.parameters["a"], b.parameters["b"]], [0, 1], atol=1e-3)
    np.testing.assert_allclose([c.parameters["a"], c.parameters["b"]], [-1, 0], atol=1e-3)
    grid = [p for p in pts if p.kind == "eps"]
    assert len(grid) == 3 * 3 - 1
    # bounds: eps_trim = 2, 0.447, 0.1 and eps_linear = 4, 0.894, 0.2 (geometric, tight end 5 % above
    # the minimum). {J_trim <= e1} and {J_linear <= e2} are discs of radius sqrt(e1), sqrt(e2) around
    # (0, 1) and (-1, 0), 1.414 apart: they miss each other exactly at grid points (1,2), (2,1), (2,2)
    np.testing.assert_allclose(ps.eps_trim, [2, math.sqrt(0.2), 0.1], rtol=1e-3)
    failed = sorted((p.i_trim, p.i_linear) for p in grid if not p.success)
    assert failed == [(1, 2), (2, 1), (2, 2)]
    for p in (p for p in grid if p.success):  # every bound is respected, and active unless the point is A's
        assert p.J_trim <= p.epsilon * (1 + 1e-6) and p.J_linear <= p.epsilon_linear * (1 + 1e-6)
        # the recorded multipliers make the point stationary (KKT): grad J_time + k_trim grad J_trim
        # + k_linear grad J_linear = 0, with the gradients in closed form; k >= 0
        x, y = p.parameters["a"], p.parameters["b"]
        k1, k2 = p.multiplier_trim, p.multiplier_linear
        kkt = np.array([2 * (x - 1) + k1 * 2 * x + k2 * 2 * (x + 1), 2 * y + k1 * 2 * (y - 1) + k2 * 2 * y])
        assert min(k1, k2) > -1e-8 and np.abs(kkt).max() < 1e-5, (p.i_trim, p.i_linear, k1, k2, kkt)
    # snake path: row 1 is visited right to left
    row1 = [p.i_linear for p in grid if p.i_trim == 1]
    assert row1 == [2, 1, 0]
    # utopia = the three minima (J_time 1, J_trim 0, J_linear 0); nadir = worst over the anchors
    utopia, nadir = ps.utopia_nadir()
    np.testing.assert_allclose(utopia, [1, 0, 0], atol=1e-6)
    np.testing.assert_allclose(nadir, [5, 2, 4], atol=1e-3)
    chosen, d, _, _ = ps.choose()
    assert math.isclose(utopia_distance_n([[chosen.J_time, chosen.J_trim, chosen.J_linear]], utopia, nadir)[0],
                        d.min())
    # the direct Eq. 11 solve is at least as close to utopia as any grid point
    direct = ps.direct_choice(chosen)
    dd = utopia_distance_n([[direct.J_time, direct.J_trim, direct.J_linear]], utopia, nadir)[0]
    assert direct.success and dd <= d.min() + 1e-9


def test_utopia_distance_n_matches_two_objective_formula():
    from pyomo_heli.pareto.front import utopia_distance

    J = np.array([[3.0, 0.5], [2.0, 1.0]])
    np.testing.assert_allclose(utopia_distance_n(J, (1.0, 0.0), (4.0, 2.0)),
                               utopia_distance(J[:, 0], J[:, 1], (1.0, 0.0), (4.0, 2.0)))
