"""The pilot who holds the attitude during a frequency sweep (synthetic flight test).

The bare airframe is unstable (the phugoid at 80 kt, the hover oscillation), so an open-loop sweep of a
minute or more diverges. Sweeps are flown with a pilot (or SAS) keeping the aircraft near trim
(Tischler and Remple, sec. 5.9): the recorded input at the actuator is the sweep plus the pilot's
corrections, and the frequency response from that input to the outputs is still the bare airframe's.

Pilot model, on longitudinal cyclic only (the sweep's own channel included):

    lon_pilot(t) = -K_theta (theta - theta_0) - K_q q + r(t)       [rad]

Gains from a documented rule: the short-term pitch model q' = M_q q + M_lon lon (M_q = dq'/dq,
M_lon = dq'/dlon from the truth model's linearisation at the maneuver trim) closed by the pilot gives
s^2 + (M_lon K_q - M_q) s + M_lon K_theta = 0; the pilot places it at omega_p, zeta_p:

    K_theta = omega_p^2 / M_lon,   K_q = max(0, (2 zeta_p omega_p + M_q) / M_lon)

with omega_p = 2 rad/s and zeta_p = 0.7. States of model extensions that drive q' (an actuator lag between the
cyclic and the rotor) are residualised first (quasi-steady: x_E' = 0), so M_q and M_lon are the short-term
model's through them; extension states that q' does not see change nothing.
At low frequency the loop holds theta/sweep near M_lon/omega_p^2
(about 11 deg per deg of cyclic for the Bo-105 at hover and 80 kt): a 0.2 deg sweep moves the attitude by
less than 3 deg, where the response is still linear (with omega_p = 1 rad/s it is four times that).
r(t) is the pilot's remnant: seeded white noise at 10 Hz through a first-order lag of REMNANT_TAU,
stationary standard deviation REMNANT_SIGMA, interpolated by a cubic spline (smooth for the
integrator). It makes the pilot's cyclic not a pure function of the sweep.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.interpolate import CubicSpline

from ..physics.model import STATES

#: attitude-loop natural frequency [rad/s] and damping of the pilot's gain rule
PILOT_OMEGA, PILOT_ZETA = 2.0, 0.7
#: remnant: stationary standard deviation [rad] (0.01 deg, half the recorded lon noise), lag [s], rate [Hz]
REMNANT_SIGMA, REMNANT_TAU, REMNANT_RATE = math.radians(0.01), 0.5, 10.0


@dataclass(frozen=True)
class AttitudeHold:
    """lon increment = -K_theta (theta - theta0) - K_q q + remnant(t)  [rad]."""

    K_theta: float  # [rad of lon per rad of theta]
    K_q: float  # [rad of lon per rad/s of q]
    theta0: float  # trim attitude [rad]
    remnant: Callable[[float], float] | None = None

    def __call__(self, t: float, x) -> dict:
        r = float(self.remnant(t)) if self.remnant is not None else 0.0
        return {"lon": -self.K_theta * (x["theta"] - self.theta0) - self.K_q * x["q"] + r}


def pilot_gains(lin, omega: float = PILOT_OMEGA, zeta: float = PILOT_ZETA) -> tuple[float, float]:
    """(K_theta, K_q) of the gain rule from a linear model ``lin`` (simulation.linearize.LinearModel)."""
    iq, il = lin.states.index("q"), lin.inputs.index("lon")
    M_q, M_lon = float(lin.A[iq, iq]), float(lin.B[iq, il])
    ext = [k for k, s in enumerate(lin.states) if s not in STATES]
    if ext and np.any(lin.A[iq, ext] != 0.0):  # residualise the extension states q' depends on
        A_qE = lin.A[iq, ext]
        A_EE_inv = np.linalg.inv(lin.A[np.ix_(ext, ext)])
        M_q -= float(A_qE @ A_EE_inv @ lin.A[ext, iq])
        M_lon -= float(A_qE @ A_EE_inv @ lin.B[ext, il])
    if not M_lon > 0:
        raise ValueError(f"pilot model: pitch control power dq'/dlon = {M_lon:g} 1/s^2 at {lin.V:g} m/s is not "
                         f"positive; aft cyclic must pitch the nose up")
    return omega ** 2 / M_lon, max(0.0, (2 * zeta * omega + M_q) / M_lon)


def remnant(rng: np.random.Generator, t0: float, t1: float, sigma: float = REMNANT_SIGMA,
            tau: float = REMNANT_TAU, rate: float = REMNANT_RATE) -> Callable[[float], float]:
    """Seeded first-order-lag noise on [t0, t1] [s] (stationary std ``sigma``), a smooth spline of time."""
    t = np.arange(t0, t1 + 2.0 / rate, 1.0 / rate)
    n = rng.standard_normal(len(t))
    a = math.exp(-1.0 / (rate * tau))
    r = np.empty(len(t))
    r[0] = sigma * n[0]
    for k in range(1, len(t)):
        r[k] = a * r[k - 1] + math.sqrt(1 - a * a) * sigma * n[k]
    spline = CubicSpline(t, r)
    return lambda tt: spline(np.clip(tt, t[0], t[-1]))


def attitude_hold(lin, theta0: float, rng: np.random.Generator | None = None, t0: float = 0.0,
                  t1: float = 0.0) -> AttitudeHold:
    """The pilot at one trim: gains from ``lin`` (:func:`pilot_gains`), remnant from ``rng`` on [t0, t1]
    (none without ``rng``)."""
    k_theta, k_q = pilot_gains(lin)
    return AttitudeHold(k_theta, k_q, theta0, remnant(rng, t0, t1) if rng is not None else None)
