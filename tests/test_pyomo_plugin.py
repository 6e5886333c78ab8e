"""The casadi-Ipopt adapter as a Pyomo solver (issue 30, point 3): SolverFactory("casadi_ipopt").

Checked against things it does not compute itself: Pyomo's own example models with analytic or published
answers, parmest's own extensive form, and pyomo_heli's point A.
"""
import math
import os
import subprocess
import sys
from pathlib import Path

import pyomo.environ as pe
import pytest
from pyomo.opt import SolverStatus, TerminationCondition

import pyomo_heli  # noqa: F401  (registers the solver)
from pyomo_heli.solvers.pyomo_plugin import as_ipopt

ROOT = Path(__file__).resolve().parent.parent


def test_the_issues_command_prints_true():
    cmd = "import pyomo.environ as pe, pyomo_heli; print(pe.SolverFactory('casadi_ipopt').available())"
    proc = subprocess.run([sys.executable, "-c", cmd], capture_output=True, text=True, cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 0 and proc.stdout.strip() == "True", proc.stderr


def test_pyomo_example_reactor_design_matches_the_closed_form():
    """Pyomo's parmest example reactor_design (a maximisation): with the rate constants fixed the steady
    state has a closed form (the ca balance is a quadratic)."""
    from pyomo.contrib.parmest.examples.reactor_design.reactor_design import reactor_design_model

    m = reactor_design_model()
    for k in (m.k1, m.k2, m.k3):
        k.fix()
    res = pe.SolverFactory("casadi_ipopt").solve(m, options={"tol": 1e-10})
    assert res.solver.termination_condition == TerminationCondition.optimal
    assert res.solver.status == SolverStatus.ok
    pe.assert_optimal_termination(res)
    k1, k2, k3, sv, caf = (pe.value(x) for x in (m.k1, m.k2, m.k3, m.sv, m.caf))
    ca = (-(sv + k1) + math.sqrt((sv + k1) ** 2 + 8 * k3 * sv * caf)) / (4 * k3)
    cb = k1 * ca / (sv + k2)
    assert pe.value(m.ca) == pytest.approx(ca, rel=1e-9)
    assert pe.value(m.cb) == pytest.approx(cb, rel=1e-9)
    assert pe.value(m.cc) == pytest.approx(k2 * cb / sv, rel=1e-9)
    assert pe.value(m.cd) == pytest.approx(k3 * ca ** 2 / sv, rel=1e-9)
    assert res.problem.sense == pe.maximize and res.problem.lower_bound == pytest.approx(cb, rel=1e-9)
    assert [s.name for s in m.component_objects(pe.Suffix)] == []  # the solver added nothing to the model


def test_parmest_rooney_biegler_reaches_the_published_estimate():
    """Pyomo's parmest example (Rooney and Biegler 2001): theta = (19.1426, 0.5311) as its own test states."""
    import pandas as pd
    from pyomo.contrib.parmest.examples.rooney_biegler.rooney_biegler import RooneyBieglerExperiment
    from pyomo.contrib.parmest.parmest import Estimator

    data = pd.DataFrame([[1, 8.3], [2, 10.3], [3, 19.0], [4, 16.0], [5, 15.6], [7, 19.8]], columns=["hour", "y"])
    est = Estimator([RooneyBieglerExperiment(data.loc[i, :]) for i in range(len(data))], obj_function="SSE")
    before = pe.SolverFactory.get_class("ipopt") if "ipopt" in pe.SolverFactory else None
    with as_ipopt():
        assert pe.SolverFactory("ipopt").name == "casadi_ipopt"
        _, theta = est.theta_est()
    assert (pe.SolverFactory.get_class("ipopt") if "ipopt" in pe.SolverFactory else None) is before  # restored
    assert theta["asymptote"] == pytest.approx(19.1426, rel=5e-5)
    assert theta["rate_constant"] == pytest.approx(0.5311, rel=5e-4)


def test_infeasible_problem_is_reported_infeasible():
    m = pe.ConcreteModel()
    m.x = pe.Var(bounds=(0, 1), initialize=0.5)
    m.y = pe.Var(initialize=0.0)
    m.c = pe.Constraint(expr=m.x + m.y ** 2 >= 2)  # with y = 0 and x <= 1 no point satisfies this
    m.d = pe.Constraint(expr=m.y == 0)
    m.o = pe.Objective(expr=(m.x - 0.2) ** 2)
    res = pe.SolverFactory("casadi_ipopt").solve(m)
    assert res.solver.termination_condition == TerminationCondition.infeasible
    with pytest.raises(RuntimeError):
        pe.assert_optimal_termination(res)


def test_iteration_limit_and_load_solutions_false():
    def rosenbrock():
        m = pe.ConcreteModel()
        m.x = pe.Var(initialize=-1.2)
        m.y = pe.Var(initialize=1.0)
        m.o = pe.Objective(expr=(1 - m.x) ** 2 + 100 * (m.y - m.x ** 2) ** 2)
        return m

    m = rosenbrock()
    res = pe.SolverFactory("casadi_ipopt").solve(m, options={"max_iter": 3})
    assert res.solver.termination_condition == TerminationCondition.maxIterations
    m = rosenbrock()
    res = pe.SolverFactory("casadi_ipopt").solve(m, load_solutions=False)
    assert res.solver.termination_condition == TerminationCondition.optimal
    assert pe.value(m.x) == -1.2  # untouched until loaded
    m.solutions.load_from(res)
    assert pe.value(m.x) == pytest.approx(1.0, abs=1e-7) and pe.value(m.y) == pytest.approx(1.0, abs=1e-7)


def test_parmest_through_the_labelled_model_reaches_point_a():
    """parmest (its own extensive form, solved by casadi_ipopt) and pyomo_heli's own point A agree to 1e-6."""
    from pyomo.contrib.parmest.parmest import Estimator

    from pyomo_heli.config import load_identification_config
    from pyomo_heli.nlp.identification import build_identification_nlp, identification_data
    from pyomo_heli.nlp.parmest_experiment import IdentificationExperiment, time_domain_objective
    from pyomo_heli.pareto.front import ParetoSolver

    cfg = load_identification_config(ROOT / "tests" / "configs" / "small_case1_noisy.toml",
                                     overrides={"data": {"maneuvers": ["lon3211_80kt_a"], "max_duration_s": 3.0}})
    data = identification_data(cfg)
    m = build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp)
    a = ParetoSolver(m, cfg.pareto).point_a()
    assert a.success
    exp = IdentificationExperiment(cfg, data)
    labelled = exp.get_labeled_model()
    n_out = len(cfg.nlp.time_outputs) * sum(len(mv.data) for mv in data.maneuvers)
    assert len(labelled.experiment_outputs) == n_out and len(labelled.unknown_parameters) == len(cfg.free)
    est = Estimator([exp], obj_function=time_domain_objective, solver_options={"tol": 1e-8})
    with as_ipopt():
        obj, theta = est.theta_est()
    for f in cfg.free:
        assert theta[f"theta_s[{f.name}]"] * f.scale == pytest.approx(a.parameters[f.name], rel=1e-6), f.name
    assert obj * pe.value(labelled.J_time_scale) == pytest.approx(a.J_time, rel=1e-8)


def test_parmest_measurement_errors_come_from_the_lead_in_and_weight_the_fit():
    """An output-error config with a quiet lead-in: each output's measurement_error is the pooled lead-in sigma
    (computed here from the records), so parmest's "SSE_weighted" lands near point A (a review: with the labels
    None, parmest's fits summed rad/s, rad, g and m/s unweighted and put both parameters at their bounds)."""
    import numpy as np
    from pyomo.contrib.parmest.parmest import Estimator

    from pyomo_heli.config import load_identification_config
    from pyomo_heli.nlp.identification import build_identification_nlp, identification_data
    from pyomo_heli.nlp.parmest_experiment import IdentificationExperiment
    from pyomo_heli.pareto.front import ParetoSolver

    cfg = load_identification_config(ROOT / "tests" / "configs" / "small_case1_noisy.toml", overrides={
        "data": {"maneuvers": ["lon3211_80kt_a"], "max_duration_s": 3.0, "input_reference_s": 0.8}})
    data = identification_data(cfg)
    exp = IdentificationExperiment(cfg, data)
    labelled = exp.get_labeled_model()
    for o in cfg.nlp.time_outputs:
        ss = dof = 0
        for mv in data.maneuvers:
            x = mv.data[o].to_numpy()[mv.data["t"].to_numpy() <= mv.data["t"].iloc[0] + 0.8 + 1e-9]
            ss, dof = ss + np.sum((x - x.mean()) ** 2), dof + len(x) - 1
        assert labelled.measurement_error[labelled.y_hat[0, o]] == pytest.approx((ss / dof) ** 0.5, rel=1e-9), o
    m = build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp)
    a = ParetoSolver(m, cfg.pareto).point_a()
    est = Estimator([exp], obj_function="SSE_weighted", solver_options={"tol": 1e-8})
    with as_ipopt():
        _, theta = est.theta_est()
    for f in cfg.free:
        assert theta[f"theta_s[{f.name}]"] * f.scale == pytest.approx(a.parameters[f.name], rel=0.05), f.name


@pytest.mark.slow
def test_idaes_scaled_point_a_reaches_the_same_estimate():
    """The IDAES Scaler's scaled copy of the NLP (Pyomo's core.scale_model, the NL route: a second way to apply
    the factors beside the casadi adapter's ``scaling``) solves to the unscaled estimate."""
    from idaes.core.scaling import get_scaling_factor

    from pyomo_heli.config import load_identification_config
    from pyomo_heli.nlp.identification import build_identification_nlp, identification_data, set_objective
    from pyomo_heli.nlp.parameters import free_parameter_values
    from pyomo_heli.nlp.scaling import IdentificationScaler
    from pyomo_heli.solvers.casadi_ipopt import CasadiIpoptSolver

    cfg = load_identification_config(ROOT / "tests" / "configs" / "small_case1_noisy.toml",
                                     overrides={"data": {"maneuvers": ["lon3211_80kt_a"], "max_duration_s": 3.0}})
    data = identification_data(cfg)

    def fresh():
        m = build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp)
        set_objective(m, m.J_time / max(abs(pe.value(m.J_time)), 1.0))
        return m

    m = fresh()
    r = CasadiIpoptSolver(m, {"point_rows": False}).solve("none")
    m2 = fresh()
    IdentificationScaler().scale_model(m2)
    big = max(m2.component_data_objects(pe.Var, descend_into=True), key=lambda v: abs(v.value or 0))
    assert get_scaling_factor(big) == pytest.approx(1 / 40)  # IDAES's suffix holds the factors (airspeed: 40 m/s)
    scaled = pe.TransformationFactory("core.scale_model").create_using(m2, rename=False)
    r2 = CasadiIpoptSolver(scaled, {"point_rows": False}).solve("none")
    pe.TransformationFactory("core.scale_model").propagate_solution(scaled, m2)
    assert r.success and r2.success
    for n, v in free_parameter_values(m).items():
        assert free_parameter_values(m2)[n] == pytest.approx(v, rel=1e-8), n
