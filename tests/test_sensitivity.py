"""Output sensitivities (pyomo_heli.simulation.sensitivity) against analytic results."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from pyomo_heli.dataset import load_flight_test
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.simulation.sensitivity import sensitivities

CLEAN = Path(__file__).resolve().parents[1] / "data" / "bo105_clean"


def test_hover_collective_sensitivity_to_twist_is_blade_element_theory():
    """Hover at fixed thrust: C_T ~ col/3 + theta_tw (1/4 - r_ref/3), so dcol/dtwist = -3 R (1/4 - r_ref/3)."""
    m = HelicopterModel()
    p = m.parameters
    s = sensitivities(m, ["theta_twist", "Iyy"], trim_speeds=[0.0], trim_out=["col", "theta"])
    expected = -3 * p["R"] * (0.25 - p["r_ref"] / 3)
    assert s.trim["col"][0, 0] == pytest.approx(expected, rel=1e-2)
    # a trim is an equilibrium: the pitch inertia cannot move it
    assert abs(s.trim["col"][0, 1]) < 1e-12 and abs(s.trim["theta"][0, 1]) < 1e-12


def test_pitch_rate_sensitivity_to_inertia_right_after_the_input():
    """Just after the input starts, q(t) ~ M t / Iyy, so dq/dIyy ~ -q / Iyy; trim does not depend on Iyy."""
    ft = load_flight_test(CLEAN)
    mv = ft.maneuvers["lon3211_80kt_a"]
    lon = mv.data["lon"].to_numpy()
    t_in = mv.data["t"].to_numpy()[np.argmax(np.abs(lon - lon[0]) > 1e-6)]  # first sample with an input
    mv = dataclasses.replace(mv, data=mv.data[mv.data["t"] <= t_in + 0.3].reset_index(drop=True))
    m = HelicopterModel()
    s = sensitivities(m, ["Iyy"], maneuvers=[mv], time_outputs=["q", "theta"])
    q = s.y_time["q"]
    t = mv.data["t"].to_numpy()
    first = int(np.argmax((t > t_in) & (np.abs(q) > 1e-5)))  # the first sample that responds
    ratio = s.time["q"][first, 0] / (-q[first] / m.parameters["Iyy"])
    assert ratio == pytest.approx(1.0, abs=0.07)  # -> 1 as t -> t_in; pitch damping acts at O(t)
    # theta' = q, so d(theta)/dIyy is the time integral of dq/dIyy (trapezoid rule at 50 Hz)
    from scipy.integrate import cumulative_trapezoid

    integral = cumulative_trapezoid(s.time["q"][:, 0], t, initial=0.0)
    scale = np.max(np.abs(s.time["theta"][:, 0]))
    assert scale > 0 and np.max(np.abs(integral - s.time["theta"][:, 0])) < 0.02 * scale
    assert np.max(np.abs(s.time["q"][t < t_in, 0])) < 1e-12  # nothing moves before the input


def test_one_sided_difference_at_a_lower_bound_matches_a_secant():
    """A parameter at its lower bound gets a one-sided derivative, consistent with a finite secant."""
    lo = HelicopterModel().parameters.spec("K_beta").bounds[0]
    m0 = HelicopterModel().with_parameters(K_beta=lo)
    s = sensitivities(m0, ["K_beta"], trim_speeds=[40.0], trim_out=["lon"])
    h = 50.0
    secant = (sensitivities(m0.with_parameters(K_beta=lo + h), [], trim_speeds=[40.0], trim_out=["lon"]).y_trim["lon"]
              - s.y_trim["lon"]) / h
    assert s.trim["lon"][0, 0] == pytest.approx(secant[0], rel=1e-2)


def test_one_sided_difference_at_an_upper_bound_matches_a_backward_secant():
    """twist at its upper bound 0: the derivative steps inward (down), consistent with a backward secant."""
    m = HelicopterModel().with_parameters(theta_twist=0.0)
    assert m.parameters.spec("theta_twist").bounds[1] == 0.0
    s = sensitivities(m, ["theta_twist"], trim_speeds=[40.0], trim_out=["col"])
    h = 1e-3  # rad/m
    secant = (s.y_trim["col"] - sensitivities(m.with_parameters(theta_twist=-h), [], trim_speeds=[40.0],
                                              trim_out=["col"]).y_trim["col"]) / h
    assert s.trim["col"][0, 0] == pytest.approx(secant[0], rel=1e-2)


def test_trims_from_the_nominal_trim_match_the_continuation_from_hover(monkeypatch):
    """The sensitivities trim a model a difference step away from the nominal trims (trim_near: fixed-Jacobian
    Newton steps, no continuation from hover). At each speed the point is the continuation's (trim_sweep, the
    second route) to rounding, for a difference step and for 30 % less twist; from starts far from the root (the
    hover trim at every speed) the fallback to the root finder gives the same points."""
    import pyomo_heli.simulation.trim as trim

    m = HelicopterModel()
    speeds = [0.0, 10.0, 30.0, 61.7]
    nominal = trim.trim_sweep(m, speeds)

    def same(want, got):
        for a, b in zip(want, got, strict=True):
            assert b.V == a.V
            assert [b.col, b.lon, b.theta, b.lambda_i] == pytest.approx([a.col, a.lon, a.theta, a.lambda_i],
                                                                        rel=1e-12, abs=1e-14), a.V

    for name, factor in (("theta_twist", 1 + 1e-5), ("CL_alpha_HT", 1 - 1e-5), ("theta_twist", 0.7)):
        near = m.with_parameters(**{name: m.parameters[name] * factor})
        same(trim.trim_sweep(near, speeds), trim.trim_near(near, nominal, trim.trim_jacobians(m, nominal)))
    fell_back, root_finder = [], trim.trim_float
    monkeypatch.setattr(trim, "trim_float", lambda model, V, *a, **k: fell_back.append(V) or root_finder(model, V, *a,
                                                                                                          **k))
    same(nominal, trim.trim_near(m, [dataclasses.replace(nominal[0], V=v) for v in speeds]))
    assert fell_back == speeds[1:]
    # a lag state that exists only at a non-zero time constant: the points lack it, the model is trimmed anew
    from pyomo_heli.physics.discrepancy import generic_term

    lag = generic_term("lon_delay")
    zero = HelicopterModel(extensions=[lag])
    at = zero.with_parameters(**{lag.strength: 0.02})
    assert len(at.state_names) == len(zero.state_names) + 1
    same(trim.trim_sweep(at, speeds), trim.trim_near(at, trim.trim_sweep(zero, speeds)))


def test_difference_steps_do_not_shrink_to_rounding_near_zero():
    """A parameter at a normal value steps by rel_step times its magnitude; at zero, or estimated near zero (below a
    tenth of its scale), by rel_step times its scale: a strength of 1e-11 would otherwise step by 1e-16."""
    from pyomo_heli.diagnosis.candidates import CANDIDATES
    from pyomo_heli.simulation.sensitivity import parameter_steps

    m = HelicopterModel(extensions=[CANDIDATES["cg_offset"]()])
    scale = m.parameters.spec("dx_fwd").scale
    assert parameter_steps(m, ["Iyy"], 1e-5)[0] == pytest.approx(1e-5 * m.parameters["Iyy"])
    for v in (0.0, 1e-11 * scale, -1e-3 * scale):
        assert parameter_steps(m.with_parameters(dx_fwd=v), ["dx_fwd"], 1e-5)[0] == pytest.approx(1e-5 * scale), v
    assert parameter_steps(m.with_parameters(dx_fwd=2 * scale), ["dx_fwd"], 1e-5)[0] == pytest.approx(2e-5 * scale)
