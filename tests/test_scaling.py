"""Scaling through IDAES's API (nlp/scaling.py) and the casadi adapter's scaled solve (solvers/casadi_scaling.py).

- the Scaler writes a factor for every free variable, active row and the objective of a small identification
  NLP, with the physics nominals (checked against the numbers written here, not read back from the module);
- the adapter's scaled solve of a two-variable problem gives the analytic solution, objective and the same
  multipliers as the unscaled solve;
- point A of a small instance solved scaled equals the unscaled estimate to 1e-6 relative;
- a 3-point front of the tiny instance scaled gives the unscaled estimates in no more iterations, in all and at
  every point; the anchors of the small instance likewise (slow);
- a scaled re-solve from a solution keeps Ipopt's multiplier estimate (constr_mult_init_max translated): no more
  iterations than unscaled, the analytic solution;
- the epsilon row takes the largest factor of its variables, and the adapter applies a row's factor only while
  the row has a finite bound (the analytic solution with the bound off, on and off again).
"""
from pathlib import Path

import pyomo.environ as pe
import pytest

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "tests" / "configs" / "tiny_case1_noisy.toml"


@pytest.fixture(scope="module")
def tiny():
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.nlp.identification import identification_data

    cfg = load_identification_config(TINY)
    return cfg, identification_data(cfg)


def _build(tiny):
    from pyomo_heli.nlp.identification import build_identification_nlp

    cfg, data = tiny
    return build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp)


def test_scaler_sets_a_physics_factor_on_every_family(tiny):
    from idaes.core.scaling import get_scaling_factor

    from pyomo_heli.nlp.scaling import IdentificationScaler

    cfg, _ = tiny
    m = _build(tiny)
    m.eps_trim = pe.Param(initialize=1e20, mutable=True)  # the Pareto solver's epsilon row (pareto.epsilon)
    m.eps_con = pe.Constraint(expr=m.J_trim / 0.2 <= m.eps_trim)
    IdentificationScaler().scale_model(m)
    free = [v for v in m.component_data_objects(pe.Var, descend_into=True) if not v.fixed]
    rows = list(m.component_data_objects(pe.Constraint, active=True, descend_into=True))
    assert [v.name for v in free if get_scaling_factor(v) is None] == []
    assert [c.name for c in rows if get_scaling_factor(c) is None] == []
    assert all(get_scaling_factor(c) > 0 for c in [*free, *rows])
    # every variable and row family of the maneuver and trim blocks is there
    blk = m.man[m.maneuver_names.first()]
    t = blk.t.at(3)
    trim = m.trim[m.trim_speeds.first()]
    expected = [  # 1 / nominal: u 40 m/s, w 5 m/s, q 0.2 rad/s, theta 0.1 rad, inflow 0.05, time scale 1 s
        (blk.x["u", t], 1 / 40), (blk.x["w", t], 1 / 5), (blk.x["q", t], 1 / 0.2), (blk.x["theta", t], 1 / 0.1),
        (blk.x["lambda_i", t], 1 / 0.05), (blk.dx["q", t], 1 / 0.2), (blk.beta["beta_1c", t], 1 / 0.05),
        (blk.y["TAS", blk.samples.first()], 1 / 40), (blk.y["n_z", blk.samples.first()], 1.0),
        (trim.V, 1 / 40), (trim.col, 1 / 0.15), (trim.lon, 1 / 0.05), (trim.theta, 1 / 0.1),
        (blk.ode["u", t], 1 / 40), (blk.ode["q", t], 1 / 0.2), (blk.dx_disc_eq["w", t], 1 / 5),
        (blk.initial["theta"], 1 / 0.1), (blk.output_eq["q", blk.samples.first()], 1 / 0.2),
        (trim.equilibrium["lambda_i"], 1 / 0.05), (trim.V_spec, 1 / 40),
    ]
    for c, sf in expected:
        assert get_scaling_factor(c) == pytest.approx(sf), c.name
    for f in cfg.free:  # theta_s = p / scale, nominal max(|ParameterSpec value| / scale, 1)
        nominal = max(abs(cfg.model.parameters[f.name]) / f.scale, 1.0)
        assert get_scaling_factor(m.theta_s[f.name]) == pytest.approx(1 / nominal), f.name
    # flapping rows: IDAES's nominal-value walk, one factor per family
    assert len({get_scaling_factor(c) for c in blk.flapping.values()}) == 1
    # the epsilon row: the largest factor of its variables, the trim inputs' lon 1 / 0.05
    assert get_scaling_factor(m.eps_con) == pytest.approx(1 / 0.05)
    # objective by its value at the start
    sfx = m.component("scaling_factor")
    assert sfx[m.objective] == pytest.approx(1 / abs(pe.value(m.J_time)))


def _two_variable_model(scaled: bool):
    """min (x - 3)^2 + (y/1000 - 2)^2  s.t.  x + y/1000 = 4,  y <= 1400: x = 2.6, y = 1400, f = 0.52."""
    m = pe.ConcreteModel()
    m.x = pe.Var(initialize=0.0)
    m.y = pe.Var(initialize=0.0, bounds=(None, 1400.0))
    m.c = pe.Constraint(expr=m.x + m.y / 1000 == 4)
    m.o = pe.Objective(expr=(m.x - 3) ** 2 + (m.y / 1000 - 2) ** 2)
    if scaled:
        m.scaling_factor = pe.Suffix(direction=pe.Suffix.EXPORT)
        m.scaling_factor[m.y] = 1e-3
        m.scaling_factor[m.c] = 10.0
        m.scaling_factor[m.o] = 0.5
    return m


def test_adapter_scaled_solve_matches_analytic_solution_and_multipliers():
    from pyomo_heli.solvers.casadi_ipopt import CasadiIpoptSolver, CasadiSettings

    out = {}
    for scaled in (False, True):
        m = _two_variable_model(scaled)
        solver = CasadiIpoptSolver(m, {"tol": 1e-10}, CasadiSettings(scaling=scaled))
        assert (solver._scaling is not None) == scaled
        r = solver.solve("none")
        assert r.success
        assert pe.value(m.x) == pytest.approx(2.6, abs=1e-7)
        assert pe.value(m.y) == pytest.approx(1400.0, rel=1e-7)
        assert r.objective == pytest.approx(0.52, rel=1e-7)  # unscaled objective, whatever the factor
        out[scaled] = (m.dual[m.c], m.ipopt_zU_out[m.y])
    # multipliers of the unscaled problem: lam = -2 (x - 3) = 0.8 for the row; for y the bound multiplier
    # 2 (y/1000 - 2)/1000 + lam/1000 = -0.4e-3 (ASL signs: dual = -lam, zU <= 0)
    assert out[True][0] == pytest.approx(out[False][0], rel=1e-6)
    assert out[True][1] == pytest.approx(out[False][1], rel=1e-6)
    assert out[True][0] == pytest.approx(-0.8, rel=1e-6)
    assert out[True][1] == pytest.approx(-0.4e-3, rel=1e-5)


def test_adapter_leaves_a_row_without_bound_unscaled():
    """min (x - 3)^2 s.t. 2 x <= eps, the row's factor 20: while eps = 1e20 (beyond Ipopt's infinity, no
    constraint) the solve uses factor 1 on the row, x = 3; at eps = 4 the factor 20, x = 2 with multiplier 1
    (2 (x - 3) + 2 lam = 0); back at 1e20 the first scaled functions and solver again."""
    from pyomo_heli.solvers.casadi_ipopt import CasadiIpoptSolver, CasadiSettings

    m = pe.ConcreteModel()
    m.x = pe.Var(initialize=0.0)
    m.eps = pe.Param(initialize=1e20, mutable=True)
    m.c = pe.Constraint(expr=2 * m.x <= m.eps)
    m.o = pe.Objective(expr=(m.x - 3) ** 2)
    m.scaling_factor = pe.Suffix(direction=pe.Suffix.EXPORT)
    m.scaling_factor[m.c] = 20.0
    solver = CasadiIpoptSolver(m, {"tol": 1e-10}, CasadiSettings(scaling=True))
    assert solver.solve("none").success and pe.value(m.x) == pytest.approx(3.0, abs=1e-7)
    assert solver._scaling.sg.tolist() == [1.0]
    first = solver._solvers
    m.eps = 4.0
    assert solver.solve("primal").success and pe.value(m.x) == pytest.approx(2.0, abs=1e-7)
    assert solver._scaling.sg.tolist() == [20.0]
    assert abs(m.dual[m.c]) == pytest.approx(1.0, rel=1e-6)
    m.eps = 1e20
    assert solver.solve("primal").success and pe.value(m.x) == pytest.approx(3.0, abs=1e-7)
    assert solver._scaling.sg.tolist() == [1.0] and solver._solvers is first


def test_scaled_point_a_equals_unscaled_estimate(tiny):
    import dataclasses

    from pyomo_heli.pareto.front import ParetoSolver

    from pyomo_heli.uncertainty.reduced_hessian import reduced_hessian_covariance

    cfg, _ = tiny
    res, se = {}, {}
    for scaled in (False, True):
        m = _build(tiny)
        settings = dataclasses.replace(cfg.pareto, solver_options={**cfg.pareto.solver_options, "scaling": scaled})
        ps = ParetoSolver(m, settings)
        assert (ps.solver._scaling is not None) == scaled  # the scaled problem is the one solved
        res[scaled] = ps.point_a()
        assert res[scaled].success
        # the reduced Hessian reads the unscaled derivatives whatever the solves use
        se[scaled] = reduced_hessian_covariance(m, ps.solver, 1.0 / ps.s_time)["se"]
    for name, v in res[False].parameters.items():
        assert res[True].parameters[name] == pytest.approx(v, rel=1e-6), name
        assert se[True][name] == pytest.approx(se[False][name], rel=1e-5), name
    assert res[True].J_time == pytest.approx(res[False].J_time, rel=1e-9)


#: anchor B's J_time, scaled against unscaled: B's row J_trim <= J_trim_min (1 + 1e-6) holds to Ipopt's bound
#: relaxation, 1e-8 of max(1, |bound|) in the units Ipopt sees; the scaled epsilon row (factor 20, bound about 19)
#: makes that 1e-8 of J_trim, unscaled (bound 0.96) 1.04e-8, and the front is steep enough at B that J_time follows
#: by 1e-8 (tiny) to 2.4e-7 (Case 1) relative (docs/performance.md, "Scaling")
B_J_TIME_REL = 1e-6


def test_scaled_front_equals_unscaled_front_in_no_more_iterations(tiny):
    """A 3-point front (A, one interior point, B) of the tiny instance unscaled and scaled: the same estimates at
    every point (1e-6 relative to max(|value|, scale)) and the scaled solves take no more Ipopt iterations in all."""
    import dataclasses

    from pyomo_heli.pareto.front import ParetoSolver

    cfg, _ = tiny
    runs = {}
    for scaled in (False, True):
        settings = dataclasses.replace(cfg.pareto, points=3, cold_check=False,
                                       solver_options={**cfg.pareto.solver_options, "scaling": scaled})
        runs[scaled] = ParetoSolver(_build(tiny), settings).front()
        assert all(p.success for p in runs[scaled])
    scales = {f.name: f.scale for f in cfg.free}
    for pu, ps_ in zip(runs[False], runs[True]):
        assert (pu.kind, pu.index) == (ps_.kind, ps_.index)
        for name, v in pu.parameters.items():
            assert abs(ps_.parameters[name] - v) <= 1e-6 * max(abs(v), scales.get(name, 1.0)), (pu.kind, name)
        assert ps_.J_time == pytest.approx(pu.J_time, rel=B_J_TIME_REL if pu.kind == "B" else 1e-8)
    iterations = {s: [p.iterations for p in runs[s]] for s in runs}
    print(f"iterations per point (A, interior, B): unscaled {iterations[False]}, scaled {iterations[True]}")
    assert sum(iterations[True]) <= sum(iterations[False]), iterations
    assert all(s_ <= u for u, s_ in zip(iterations[False], iterations[True])), iterations  # and at every point


def _circle_model(scaled: bool):
    """min 800 (x + y) + (x - y)^2  s.t.  x^2 + y^2 = 2: x = y = -1, f = -1600, row multiplier 400
    (800 = 2 lam |x|; ASL sign: dual = -400). Scaled, the row by 1e-2: its multiplier 4e4 in the scaled problem,
    above Ipopt's constr_mult_init_max of 1000, while unscaled 400 is below it."""
    m = pe.ConcreteModel()
    m.x = pe.Var(initialize=0.5)
    m.y = pe.Var(initialize=-0.2)
    m.c = pe.Constraint(expr=m.x ** 2 + m.y ** 2 == 2)
    m.o = pe.Objective(expr=800 * (m.x + m.y) + (m.x - m.y) ** 2)
    if scaled:
        m.scaling_factor = pe.Suffix(direction=pe.Suffix.EXPORT)
        m.scaling_factor[m.c] = 1e-2
    return m


def test_scaled_primal_resolve_keeps_the_multiplier_estimate():
    """A re-solve from a perturbed solution (warm start "primal"): Ipopt's least-squares multiplier estimate is
    kept in the scaled problem as in the unscaled one (the adapter translates constr_mult_init_max by
    max(s_f / s_g) = 100), so the scaled re-solve takes no more iterations and gives the analytic solution.
    (Without the translation the scaled estimate, 4e4, was discarded: 5 iterations against 2.)"""
    from pyomo_heli.solvers.casadi_ipopt import CasadiIpoptSolver, CasadiSettings

    iterations = {}
    for scaled in (False, True):
        m = _circle_model(scaled)
        solver = CasadiIpoptSolver(m, {"tol": 1e-10}, CasadiSettings(scaling=scaled))
        assert solver.solve("none").success
        if scaled:
            assert solver._scaling.multiplier_factor == pytest.approx(100.0)
            assert solver._scaling.primal_restart_options({})["constr_mult_init_max"] == pytest.approx(1e5)
        m.x.set_value(pe.value(m.x) + 1e-3)
        r = solver.solve("primal")
        assert r.success
        assert (pe.value(m.x), pe.value(m.y)) == (pytest.approx(-1.0, abs=1e-8), pytest.approx(-1.0, abs=1e-8))
        assert r.objective == pytest.approx(-1600.0, rel=1e-10)
        assert m.dual[m.c] == pytest.approx(-400.0, rel=1e-7)
        iterations[scaled] = r.iterations
    assert iterations[True] <= iterations[False], iterations


@pytest.mark.slow
def test_scaled_anchors_of_small_instance_in_no_more_iterations():
    """Anchors A and B of tests/configs/small_case1_noisy.toml (three maneuvers, hover included) unscaled and scaled:
    the same estimates and no more iterations at either anchor. The estimates agree to 1e-5 of max(|value|, scale):
    A's twist sits at its bound 0 within the barrier's distance, -1.0e-7 rad/m unscaled and -1.9e-7 scaled (5e-6 of
    its scale, 1 deg/m); CL_alpha_HT and J_time agree to 1e-8. Anchor B's
    second stage is the re-solve whose multiplier estimate the scaled problem kept only with the translated
    constr_mult_init_max (before: B 32 iterations scaled against 23 unscaled)."""
    import dataclasses

    from pyomo_heli.config import load_identification_config
    from pyomo_heli.nlp.identification import build_identification_nlp, identification_data
    from pyomo_heli.pareto.front import ParetoSolver

    cfg = load_identification_config(ROOT / "tests" / "configs" / "small_case1_noisy.toml")
    data = identification_data(cfg)
    runs = {}
    for scaled in (False, True):
        settings = dataclasses.replace(cfg.pareto, points=2, cold_check=False,
                                       solver_options={**cfg.pareto.solver_options, "scaling": scaled})
        runs[scaled] = ParetoSolver(build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp), settings).anchors()
        assert all(p.success for p in runs[scaled])
    scales = {f.name: f.scale for f in cfg.free}
    for pu, ps_ in zip(runs[False], runs[True]):
        for name, v in pu.parameters.items():
            assert abs(ps_.parameters[name] - v) <= 1e-5 * max(abs(v), scales.get(name, 1.0)), (pu.kind, name)
        assert ps_.J_time == pytest.approx(pu.J_time, rel=B_J_TIME_REL if pu.kind == "B" else 1e-8)
    iterations = {s: [p.iterations for p in runs[s]] for s in runs}
    print(f"iterations (A, B): unscaled {iterations[False]}, scaled {iterations[True]}")
    assert all(s_ <= u for u, s_ in zip(iterations[False], iterations[True])), iterations


def test_scaling_is_an_adapter_option():
    from pyomo_heli.solvers import validate_solver_options

    validate_solver_options("casadi-ipopt", {"scaling": True})
    with pytest.raises(ValueError, match="'scaling' applies to casadi-ipopt only"):
        validate_solver_options("pounce", {"scaling": True})
    with pytest.raises(ValueError, match="'scaling' must be true or false"):
        validate_solver_options("casadi-ipopt", {"scaling": "yes"})


def test_the_scaled_case1_config_is_case1_with_scaling_on():
    """studies/case1_scaled.toml (docs/results/scaling) differs from studies/case1.toml in the solver option alone,
    so that the comparison with docs/results/case1 is of scaling only."""
    import tomllib
    from pathlib import Path

    studies = Path(__file__).resolve().parents[1] / "studies"
    plain, scaled = (tomllib.loads((studies / f).read_text()) for f in ("case1.toml", "case1_scaled.toml"))
    assert scaled["solver"]["options"].pop("scaling") is True
    assert scaled == plain


def test_the_committed_scaled_case1_front_is_the_unscaled_one():
    """docs/performance.md, "Scaling": the 11-point Case 1 front solved scaled (docs/results/scaling/case1_scaled)
    against the committed unscaled one (docs/results/case1): the same estimates and J_time to 1e-6 relative to
    max(|value|, 1) at every point (2.8e-7 at B, where the front is steepest), and no more Ipopt iterations in all,
    warm or cold."""
    from pathlib import Path

    import pandas as pd

    results = Path(__file__).resolve().parents[1] / "docs" / "results"
    scaled, plain = (pd.read_csv(results / f / "front.csv") for f in ("scaling/case1_scaled", "case1"))
    assert list(scaled["kind"]) == list(plain["kind"])
    for c in ("theta_twist", "CL_alpha_HT", "J_time", "J_trim"):
        rel = (scaled[c] - plain[c]).abs() / plain[c].abs().clip(lower=1.0)
        assert rel.max() < 1e-6, (c, rel.max())
    assert scaled["iterations"].sum() <= plain["iterations"].sum()
    assert scaled["cold_iterations"].sum() <= plain["cold_iterations"].sum()
