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
