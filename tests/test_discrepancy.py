"""The generic discrepancy family (pyomo_heli.physics.discrepancy): zero gives M0; the float model, the Pyomo trim
block and the analytic equation agree on what a term adds."""
import numpy as np
import pytest

from pyomo_heli.nlp.trim_table import trim_table
from pyomo_heli.physics.discrepancy import generic_names, generic_term
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.simulation.trim import trim_float
from pyomo_heli.units import DEG, KT


def test_family_names_round_trip_and_bad_name_is_clear():
    names = generic_names()
    assert len(names) == len(set(names)) >= 40
    for n in names:
        t = generic_term(n)
        assert t.name == n and t.strength == f"c_{n}"
        assert HelicopterModel(extensions=[t]).parameters[t.strength] == 0.0
    with pytest.raises(KeyError, match="unknown discrepancy term 'dM_bump99'"):
        generic_term("dM_bump99")


@pytest.mark.parametrize("name", ["dM_bump05", "dX_mu4", "dZ_lam", "TAS_scale", "lon_delay"])
def test_zero_is_m0_in_float_and_pyomo_trims(name):
    t = generic_term(name)
    a, b = trim_float(HelicopterModel(), 30 * KT), trim_float(HelicopterModel(extensions=[t]), 30 * KT)
    assert (b.col, b.lon, b.theta) == pytest.approx((a.col, a.lon, a.theta), abs=1e-12)
    pa = trim_table(HelicopterModel(), [30 * KT]).iloc[0]
    pb = trim_table(HelicopterModel(extensions=[t]), [30 * KT]).iloc[0]
    for k in ("col", "lon", "theta"):
        assert pb[k] == pytest.approx(pa[k], abs=1e-9)


def test_a_moment_term_is_the_same_in_float_and_pyomo_and_equals_its_equation():
    """dM = c m g R exp(-((mu - 0.05)/0.05)^2): the float trim and the Pyomo trim block agree with it on, and the
    moment the float model adds at the trim state is the equation's value."""
    t = generic_term("dM_bump05")
    m = HelicopterModel(extensions=[t]).with_parameters(c_dM_bump05=0.002)
    V = 20 * KT
    f = trim_float(m, V)
    py = trim_table(m, [V]).iloc[0]
    for k in ("col", "lon", "theta"):
        assert py[k] == pytest.approx(getattr(f, k), abs=1e-7), k
    assert abs(f.lon - trim_float(HelicopterModel(), V).lon) > 0.03 * DEG  # it acts (0.054 deg of lon)
    x = {"u": f.u, "w": f.w, "q": 0.0, "theta": f.theta, "lambda_i": f.lambda_i}
    ctx = m.evaluate(x, {"col": f.col, "lon": f.lon})
    p = m.parameters
    mu = ctx.flow.mu
    expected = 0.002 * p["m"] * p["g"] * p["R"] * np.exp(-((mu - 0.05) / 0.05) ** 2)
    assert t.value(ctx) == pytest.approx(expected, rel=1e-12)
    ctx0 = HelicopterModel().evaluate(x, {"col": f.col, "lon": f.lon})
    assert ctx.forces.M - ctx0.forces.M == pytest.approx(t.value(ctx), rel=1e-9)


def test_sensor_scale_term_scales_the_output():
    t = generic_term("TAS_scale")
    m = HelicopterModel(extensions=[t]).with_parameters(c_TAS_scale=0.03)
    f = trim_float(m, 60 * KT)
    x = {"u": f.u, "w": f.w, "q": 0.0, "theta": f.theta, "lambda_i": f.lambda_i}
    a = HelicopterModel().outputs(x, {"col": f.col, "lon": f.lon})["TAS"]
    assert m.outputs(x, {"col": f.col, "lon": f.lon})["TAS"] == pytest.approx(1.03 * a, rel=1e-12)


def test_input_time_shift_lags_the_response_and_leaves_the_trim():
    """lon_delay: c d(lon_d)/dt = lon - lon_d. Trim unchanged; after a lon step the rotor's cyclic follows
    1 - exp(-t/c), so the pitch rate responds later than M0's (smaller q early on, same sign)."""
    from pyomo_heli.simulation.inputs import InputSignal
    from pyomo_heli.simulation.integrate import simulate

    t_ = np.linspace(0.0, 2.0, 101)
    m = HelicopterModel(extensions=[generic_term("lon_delay")]).with_parameters(c_lon_delay=0.1)
    a, b = trim_float(HelicopterModel(), 40 * KT), trim_float(m, 40 * KT)
    assert b.lon == pytest.approx(a.lon, abs=1e-12) and b.extra_states["lon_delayed"] == pytest.approx(a.lon, abs=1e-12)
    sig = {"lon": InputSignal("lon", "step", 0.5 * DEG, 1.0, t_start=0.5, ramp=0.0)}
    q0, q1 = (simulate(mm, tp, t_, sig, max_step=0.01)["q"].to_numpy() for mm, tp in ((HelicopterModel(), a), (m, b)))
    k = np.searchsorted(t_, 0.6)  # 0.1 s after the step: the delayed rotor has seen 63 % of it
    assert abs(q1[k]) < 0.8 * abs(q0[k]) and np.sign(q1[k]) == np.sign(q0[k])


# CI time: one output in the default run (the lag is written once for every output), all three with --runslow
@pytest.mark.parametrize("name,out", [("nz_delay", "n_z"), pytest.param("TAS_delay", "TAS", marks=pytest.mark.slow),
                                      pytest.param("beta0_delay", "beta_0", marks=pytest.mark.slow)])
def test_output_time_shift_is_a_first_order_lag_of_the_output(name, out):
    """c d(y_d)/dt = y - y_d, the record holds y_d: the trim is M0's, and the recorded output is M0's output passed
    through 1/(c s + 1) (scipy.signal.lsim: a second method); the states are M0's. The float simulator and the
    compiled RK4 replay agree."""
    from scipy import signal

    from pyomo_heli.simulation.compiled import simulate_outputs
    from pyomo_heli.simulation.inputs import InputSignal
    from pyomo_heli.simulation.integrate import sampled, simulate

    tau = 0.08
    t_ = np.linspace(0.0, 3.0, 601)
    t = generic_term(name)
    m = HelicopterModel(extensions=[t]).with_parameters(**{t.strength: tau})
    a, b = trim_float(HelicopterModel(), 60 * KT), trim_float(m, 60 * KT)
    assert (b.col, b.lon, b.theta) == pytest.approx((a.col, a.lon, a.theta), abs=1e-12)
    assert b.extra_states[f"{out}_delayed"] == pytest.approx(HelicopterModel().outputs(a.state(), a.inputs())[out],
                                                             rel=1e-12)  # at trim the lag state is the output
    dlon = InputSignal("lon", "3211", 0.5 * DEG, 0.4, t_start=0.3, ramp=0.1)(t_)
    y0 = simulate(HelicopterModel(), a, t_, {"lon": sampled(t_, dlon)}, max_step=0.002)
    y1 = simulate(m, b, t_, {"lon": sampled(t_, dlon)}, max_step=0.002)
    _, lagged, _ = signal.lsim(([1.0], [tau, 1.0]), y0[out].to_numpy() - y0[out].iloc[0], t_)
    span = np.ptp(y0[out].to_numpy())
    shift = np.max(np.abs(y1[out].to_numpy() - y0[out].to_numpy()))
    assert shift > 0.03 * span  # it acts
    assert np.max(np.abs(y1[out].to_numpy() - y0[out].iloc[0] - lagged)) < 0.002 * shift
    q0 = y0["q"].to_numpy()
    assert np.max(np.abs(y1["q"].to_numpy() - q0)) < 1e-6 * np.ptp(q0)  # the dynamics are M0's
    comp = simulate_outputs(m, b, t_, {"lon": dlon}, [out], substeps=2)[out]
    assert np.max(np.abs(comp - y1[out].to_numpy())) < 1e-3 * span


def test_output_time_shift_in_the_collocation_nlp_equals_the_float_simulation():
    """nz_delay at c = 0.08 s: a trim block and a 3-2-1-1 maneuver as a square collocation NLP (parameters fixed)
    give the float simulator's recorded n_z, the lag state starting at the trim's n_z."""
    import pyomo.environ as pyo

    from pyomo_heli.nlp.maneuver_block import build_maneuver_block
    from pyomo_heli.nlp.parameters import add_parameters
    from pyomo_heli.nlp.trim_block import build_trim_block
    from pyomo_heli.simulation.inputs import InputSignal
    from pyomo_heli.simulation.integrate import sampled, simulate
    from pyomo_heli.solvers import make_solver

    t = generic_term("nz_delay")
    model = HelicopterModel(extensions=[t]).with_parameters(c_nz_delay=0.08)
    V = 80 * KT
    tp = trim_float(model, V)
    ts = np.arange(0.0, 3.0 + 1e-9, 0.02)
    dlon = InputSignal("lon", "3211", 0.5 * DEG, 0.4, t_start=0.5, ramp=0.1)(ts)
    ref = simulate(model, tp, ts, {"lon": sampled(ts, dlon)}, max_step=0.01)
    m = pyo.ConcreteModel()
    pmap = add_parameters(m, model.parameters, [])
    m.trim = pyo.Block()
    build_trim_block(m.trim, model, pmap, V, guess={**tp.to_dict(), **tp.extra_states})
    m.man = pyo.Block()
    build_maneuver_block(m.man, model, pmap, ts, {"lon": dlon}, m.trim, ncp=3)
    for (s, tt), v in m.man.x.items():
        v.set_value({**tp.state(), **tp.extra_states}[s])
    m.obj = pyo.Objective(expr=0.0)
    assert make_solver(m).solve(warm_start="none").success
    assert pyo.value(m.trim.n_z_delayed) == pytest.approx(ref["n_z"].iloc[0], abs=1e-8)
    y = np.array([pyo.value(m.man.y["n_z", tt]) for tt in m.man.samples])
    r = ref["n_z"].to_numpy()
    assert np.max(np.abs(y - r)) <= 2e-3 * np.ptp(r)


def test_the_float_simulator_refuses_a_sensor_effect_on_a_state_output():
    """q and theta are states and outputs, one column each in the simulator's frame: an extension that changes the
    recorded q is refused with a clear error, not silently dropped."""
    from pyomo_heli.physics.extensions import Extension
    from pyomo_heli.simulation.integrate import simulate

    class QBias(Extension):
        name, strength = "q_bias", ""

        def adjust_outputs(self, ctx):
            ctx.outputs["q"] = ctx.outputs["q"] + 0.01

    tp = trim_float(HelicopterModel(), 40 * KT)
    with pytest.raises(ValueError, match="changes the recorded q"):
        simulate(HelicopterModel(extensions=[QBias()]), tp, np.linspace(0, 0.1, 3))


def test_the_default_library_offers_the_whole_family_and_a_config_can_narrow_it():
    """With no [loop] generic list, discovery scores every term of the family, output time shifts included;
    a list narrows it."""
    from pyomo_heli.diagnosis.discovery import library

    lib = library(HelicopterModel())
    assert set(generic_names()) <= set(lib) and {"nz_delay", "nx_delay", "TAS_delay", "beta0_delay"} <= set(lib)
    assert library(HelicopterModel(), physical=[], generic=["nz_delay", "dM_one"]) == ["nz_delay", "dM_one"]


def test_the_extended_family_adds_speed_products_and_input_scale_factors_to_the_standard_one():
    """generic_names() is the standard library (unchanged); "extended" adds the regressors x mu/0.3 of every channel
    and the two input scale factors; a config chooses it with [loop] generic_family."""
    from pyomo_heli.physics.discrepancy import SPEED_PRODUCTS

    std, ext = generic_names(), generic_names("extended")
    assert len(std) == 51 and set(std) < set(ext)
    assert sorted(set(ext) - set(std)) == sorted([f"d{c}_{r}mu" for c in "XZM" for r in SPEED_PRODUCTS]
                                                 + ["lon_scale", "col_scale"])
    with pytest.raises(ValueError, match="unknown discrepancy family 'big'"):
        generic_names("big")


def test_a_speed_product_is_the_product_of_its_two_regressors():
    """dM_qmu = c m g R (q/0.2)(mu/0.3): at a state with pitch rate, the float model adds exactly that."""
    m = HelicopterModel(extensions=[generic_term("dM_qmu")]).with_parameters(c_dM_qmu=-0.003)
    f = trim_float(HelicopterModel(), 60 * KT)
    x = {"u": f.u, "w": f.w, "q": 0.1, "theta": f.theta, "lambda_i": f.lambda_i}
    ctx = m.evaluate(x, {"col": f.col, "lon": f.lon})
    p = m.parameters
    expected = -0.003 * p["m"] * p["g"] * p["R"] * (0.1 / 0.2) * (ctx.flow.mu / 0.3)
    ctx0 = HelicopterModel().evaluate(x, {"col": f.col, "lon": f.lon})
    assert ctx.forces.M - ctx0.forces.M == pytest.approx(expected, rel=1e-9)
    assert float(ctx.flow.mu) > 0.05  # it acts at speed


@pytest.mark.parametrize("name, ch", [("lon_scale", "lon"), ("col_scale", "col")])
def test_an_input_scale_factor_is_a_trim_that_needs_less_measured_control(name, ch):
    """The rotor sees (1 + c) u: the measured trim control is M0's divided by 1 + c (float trim and Pyomo trim block
    agree); attitude and the other control are M0's."""
    m = HelicopterModel(extensions=[generic_term(name)]).with_parameters(**{f"c_{name}": 0.05})
    V = 50 * KT
    a, b = trim_float(HelicopterModel(), V), trim_float(m, V)
    assert getattr(b, ch) == pytest.approx(getattr(a, ch) / 1.05, rel=1e-9)
    other = "col" if ch == "lon" else "lon"
    assert (getattr(b, other), b.theta) == pytest.approx((getattr(a, other), a.theta), abs=1e-10)
    py = trim_table(m, [V]).iloc[0]
    for k in ("col", "lon", "theta"):
        assert py[k] == pytest.approx(getattr(b, k), abs=1e-8), k


def test_a_maneuver_flown_with_an_input_scale_factor_is_m0_flown_with_the_scaled_control():
    from pyomo_heli.simulation.inputs import InputSignal
    from pyomo_heli.simulation.integrate import simulate

    t_ = np.linspace(0.0, 2.0, 101)
    m = HelicopterModel(extensions=[generic_term("lon_scale")]).with_parameters(c_lon_scale=0.05)
    b = trim_float(m, 40 * KT)
    a = trim_float(HelicopterModel(), 40 * KT)
    sig_b = {"lon": InputSignal("lon", "doublet", 0.5 * DEG, 1.0, t_start=0.3, ramp=0.05)}
    sig_a = {"lon": InputSignal("lon", "doublet", 1.05 * 0.5 * DEG, 1.0, t_start=0.3, ramp=0.05)}
    sb = simulate(m, b, t_, sig_b, max_step=0.01)
    sa = simulate(HelicopterModel(), a, t_, sig_a, max_step=0.01)
    for k in ("q", "theta", "u", "w"):
        np.testing.assert_allclose(sb[k].to_numpy(), sa[k].to_numpy(), atol=1e-9, err_msg=k)
    assert sb["lon"].to_numpy()[0] == pytest.approx(a.lon / 1.05, rel=1e-9)  # the record holds the measured control


def test_the_control_family_adds_the_control_path_feedback_terms_to_the_extended_one():
    """generic_names("control") is the extended family (unchanged) and four feedback terms; a config chooses it."""
    from pyomo_heli.settings.identification import LoopTable

    ext, ctl = generic_names("extended"), generic_names("control")
    assert ctl[:len(ext)] == ext and ctl[len(ext):] == ["lon_q", "lon_theta", "col_q", "col_theta"]
    assert LoopTable(generic_family="control").generic_family == "control"
    assert LoopTable(generic=["lon_q"]).generic == ["lon_q"]
    t = generic_term("lon_q")
    assert t.on_input and t.value(None) == 0.0 and "lon + c (0.05 rad) q/(0.2 rad/s)" in t.formula()


def test_an_attitude_feedback_trims_with_the_rotor_seeing_m0s_control():
    """lon_theta: the rotor sees lon + c 0.05 theta/0.1. At trim the aircraft is M0's (same attitude, same
    collective) and the recorded lon is M0's minus the feedback; the float trim and the Pyomo trim block agree."""
    c, V = 0.3, 50 * KT
    m = HelicopterModel(extensions=[generic_term("lon_theta")]).with_parameters(c_lon_theta=c)
    a, b = trim_float(HelicopterModel(), V), trim_float(m, V)
    assert (b.col, b.theta) == pytest.approx((a.col, a.theta), abs=1e-10)
    assert b.lon + c * 0.05 * b.theta / 0.1 == pytest.approx(a.lon, abs=1e-10)
    assert abs(b.lon - a.lon) > 0.01 * DEG  # it acts
    py = trim_table(m, [V]).iloc[0]
    for k in ("col", "lon", "theta"):
        assert py[k] == pytest.approx(getattr(b, k), abs=1e-8), k


def test_a_pitch_rate_feedback_is_m0_flown_with_the_fed_back_control():
    """lon_q in closed loop equals M0 flown open loop with the control the rotor saw (the recorded lon plus
    c 0.05 q/0.2, from the closed loop's own q); the compiled RK4 replay agrees with the float simulator."""
    from pyomo_heli.simulation.compiled import simulate_outputs
    from pyomo_heli.simulation.inputs import InputSignal
    from pyomo_heli.simulation.integrate import sampled, simulate

    c = -0.4  # a damper: lon against q
    t_ = np.linspace(0.0, 3.0, 601)
    m = HelicopterModel(extensions=[generic_term("lon_q")]).with_parameters(c_lon_q=c)
    a, b = trim_float(HelicopterModel(), 60 * KT), trim_float(m, 60 * KT)
    assert b.lon == pytest.approx(a.lon, abs=1e-12)  # q = 0 at trim
    dlon = InputSignal("lon", "3211", 0.5 * DEG, 0.4, t_start=0.3, ramp=0.1)(t_)
    closed = simulate(m, b, t_, {"lon": sampled(t_, dlon)}, max_step=0.002)
    q = closed["q"].to_numpy()
    seen = dlon + c * 0.05 * q / 0.2
    opened = simulate(HelicopterModel(), a, t_, {"lon": sampled(t_, seen)}, max_step=0.002)
    free = simulate(HelicopterModel(), a, t_, {"lon": sampled(t_, dlon)}, max_step=0.002)["q"].to_numpy()
    assert np.ptp(q) < 0.7 * np.ptp(free)  # it damps (0.48 here)
    assert np.max(np.abs(opened["q"].to_numpy() - q)) < 5e-4 * np.ptp(q)
    comp = simulate_outputs(m, b, t_, {"lon": dlon}, ["q"], substeps=2)["q"]
    assert np.max(np.abs(comp - q)) < 1e-5 * np.ptp(q)


def test_a_config_chooses_the_extended_family_and_a_bad_family_is_a_one_line_error(tmp_path):
    from pyomo_heli.settings.identification import LoopTable

    assert LoopTable().generic_family == "standard"
    assert LoopTable(generic_family="extended", generic=["dM_qmu"]).generic == ["dM_qmu"]
    with pytest.raises(Exception, match="generic_family"):
        LoopTable(generic_family="big")


@pytest.mark.parametrize("name", ["col_delay", "nz_delay"])
def test_a_lag_state_at_zero_starts_at_what_it_follows(name):
    """A delay term at c = 0 (as the NLP screen holds it: the float model then has no lag state) starts the NLP
    with its lag state equal to what it follows, in every trim block and at every collocation point: its own
    equation holds at the start, and every other variable starts as in M0's NLP (started at 0, a lagged collective
    was 0.11-0.15 rad off what it follows everywhere)."""
    import dataclasses
    from pathlib import Path

    import pyomo.environ as pyo

    from pyomo_heli.config import load_identification_config
    from pyomo_heli.nlp.identification import build_problem

    cfg = load_identification_config(Path(__file__).parent / "configs" / "small_case2.toml")
    m0, _, _ = build_problem(cfg)
    t = generic_term(name)
    m1, data, _ = build_problem(dataclasses.replace(
        cfg, model=HelicopterModel(parameters=cfg.model.parameters, extensions=[t])))
    lag, follows = t.states[0], {"col_delay": "col", "nz_delay": "n_z"}[name]
    for i in m1.trim:
        assert pyo.value(getattr(m1.trim[i], lag)) == pytest.approx(
            pyo.value(getattr(m1.trim[i], follows) if follows == "col" else m1.trim[i].outputs[follows]), abs=1e-12)
    for mv in data.maneuvers:
        b0, b1 = m0.man[mv.name], m1.man[mv.name]
        for tt in list(b1.t)[1:]:
            assert abs(pyo.value(b1.ode[lag, tt].body)) < 1e-12  # c dx = follows - lag, at rest
        for (s, tt), v in b0.x.items():
            assert b1.x[s, tt].value == v.value
    if name == "col_delay":  # the collective it follows is 0.11-0.15 rad: far from the old start at 0
        assert min(pyo.value(getattr(m1.trim[i], lag)) for i in m1.trim) > 0.1


@pytest.mark.parametrize("order", [("TAS_delay", "TAS_scale"), ("TAS_scale", "TAS_delay")])
def test_an_output_time_shift_acts_before_a_scale_on_the_same_output_in_either_order(order):
    """The family's formula: the record holds the lagged output y_d, which the scale then acts on, (1 + c) y_d.
    With the scale listed first the record read y_d + c y (the lag added its y_d - y to the scaled output). At a
    60 kt trim with the lag state set to 25 m/s, c_scale 0.1: 27.5 m/s whatever the order."""
    from pyomo_heli.physics.discrepancy import generic_term
    from pyomo_heli.physics.model import HelicopterModel
    from pyomo_heli.simulation.trim import trim_float
    from pyomo_heli.units import KT

    m = HelicopterModel(extensions=[generic_term(n) for n in order]).with_parameters(c_TAS_scale=0.1,
                                                                                     c_TAS_delay=0.2)
    tp = trim_float(m, 60 * KT)
    x = {**tp.state(), "TAS_delayed": 25.0}
    ctx = m.evaluate(x, tp.inputs())
    assert abs(float(ctx.true_outputs["TAS"]) - 25.0) > 5.0
    assert float(ctx.outputs["TAS"]) == pytest.approx(1.1 * 25.0, rel=1e-12)
