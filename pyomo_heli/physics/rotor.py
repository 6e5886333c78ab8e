"""Main rotor: hub kinematics, blade pitch, quasi-steady flapping, thrust, forces.

Equations of docs/model.md section 3 (model_spec.md 1.3, 1.4, 1.6). Rigid
blades with a centre-spring equivalent hingeless hub, uniform inflow, small
angles, no reverse flow, tip loss or root cut-out. Azimuth is measured from
the tail in the direction of rotation; ``beta_1c > 0`` tilts the tip-path
plane forward; ``lon = theta_1s > 0`` is aft stick.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping


@dataclass
class HubFlow:
    """Non-dimensional flow at the hub in shaft axes.

    mu: advance ratio u_s/V_tip [-]; mu_z: w_s/V_tip, positive with air coming
    up through the disc [-]; qbar: q/Omega [-]; v_tip: Omega R [m/s].
    """

    mu: Any
    mu_z: Any
    qbar: Any
    v_tip: Any


@dataclass
class BladePitch:
    """theta_0 root collective, theta_tw total twist over R, theta_1s [rad]."""

    theta_0: Any
    theta_tw: Any
    theta_1s: Any


def hub_flow(u, w, q, p: Mapping, ops, x_h=None) -> HubFlow:
    """Velocity of the hub in shaft axes, non-dimensionalised by the tip speed.

    u, w [m/s] body velocities at the CG, q [rad/s]. The hub sits x_h forward
    and h above the CG; the shaft is tilted forward by gamma_s.
        u_h = u - q h,  w_h = w - q x_h
        u_s = u_h cos(gamma_s) + w_h sin(gamma_s)
        w_s = -u_h sin(gamma_s) + w_h cos(gamma_s)
    """
    x_h = p["x_h"] if x_h is None else x_h
    v_tip = p["Omega"] * p["R"]
    u_h = u - q * p["h"]
    w_h = w - q * x_h
    cg, sg = ops.cos(p["gamma_s"]), ops.sin(p["gamma_s"])
    u_s = u_h * cg + w_h * sg
    w_s = -u_h * sg + w_h * cg
    return HubFlow(mu=u_s / v_tip, mu_z=w_s / v_tip, qbar=q / p["Omega"], v_tip=v_tip)


def blade_pitch(col, lon, p: Mapping) -> BladePitch:
    """Collective ``col`` is measured at r_ref: theta_0 = col - r_ref theta_tw [rad]."""
    theta_tw = p["theta_twist"] * p["R"]
    return BladePitch(theta_0=col - p["r_ref"] * theta_tw, theta_tw=theta_tw, theta_1s=lon)


def rotor_constants(p: Mapping) -> tuple[Any, Any, Any]:
    """Lock number gamma, solidity sigma and non-rotating-frame flap frequency^2.

        gamma = rho a c R^4 / I_beta,  sigma = N_b c / (pi R),
        lambda_b2 = 1 + K_beta / (I_beta Omega^2)
    """
    import math

    lock = p["rho"] * p["a"] * p["c"] * p["R"] ** 4 / p["I_beta"]
    sigma = p["Nb"] * p["c"] / (math.pi * p["R"])
    lambda_b2 = 1 + p["K_beta"] / (p["I_beta"] * p["Omega"] ** 2)
    return lock, sigma, lambda_b2


def flapping_system(flow: HubFlow, pitch: BladePitch, lam, p: Mapping):
    """Harmonic balance of the flap equation: A [beta_0, beta_1c, beta_1s] = b.

    lam is the net inflow through the hub plane, lambda_i - mu_z [-].
    Returns (A, b) as nested lists of expressions (3x3 and 3).
    """
    lock, _, lb2 = rotor_constants(p)
    mu, qb = flow.mu, flow.qbar
    th0, thtw, th1s = pitch.theta_0, pitch.theta_tw, pitch.theta_1s
    A = [
        [lb2, 0.0, 0.0],
        [lock * mu / 6, lb2 - 1, lock * (1 / 8 + mu**2 / 16)],
        [0.0, -lock * (1 / 8 - mu**2 / 16), lb2 - 1],
    ]
    b = [
        (lb2 - 1) * p["beta_p"]
        + lock * (th0 * (1 + mu**2) / 8 + thtw * (1 / 10 + mu**2 / 12) + mu * th1s / 6 - lam / 6),
        lock * qb / 8,  # theta_1c = 0 in the longitudinal model
        lock * (th1s * (1 / 8 + 3 * mu**2 / 16) + mu * th0 / 3 + mu * thtw / 4 - mu * lam / 4) - 2 * qb,
    ]
    return A, b


def flapping_residuals(beta, flow: HubFlow, pitch: BladePitch, lam, p: Mapping) -> list:
    """A beta - b for beta = (beta_0, beta_1c, beta_1s): three equalities (NLP form)."""
    A, b = flapping_system(flow, pitch, lam, p)
    return [sum(A[i][j] * beta[j] for j in range(3)) - b[i] for i in range(3)]


def solve_flapping(flow: HubFlow, pitch: BladePitch, lam, p: Mapping) -> tuple:
    """Closed-form solution of the same 3x3 system (float/simulator form).

    Row 0 is diagonal; rows 1-2 are a 2x2 system in (beta_1c, beta_1s).
    """
    A, b = flapping_system(flow, pitch, lam, p)
    beta_0 = b[0] / A[0][0]
    r1 = b[1] - A[1][0] * beta_0
    r2 = b[2] - A[2][0] * beta_0
    det = A[1][1] * A[2][2] - A[1][2] * A[2][1]
    beta_1c = (r1 * A[2][2] - A[1][2] * r2) / det
    beta_1s = (A[1][1] * r2 - A[2][1] * r1) / det
    return beta_0, beta_1c, beta_1s


def thrust_coefficient(flow: HubFlow, pitch: BladePitch, lam, p: Mapping):
    """Blade-element thrust coefficient in the hub frame [-].

    C_T = (a sigma/2) [theta_0 (1/3 + mu^2/2) + theta_tw (1 + mu^2)/4 + mu theta_1s/2 - lam/2]
    """
    _, sigma, _ = rotor_constants(p)
    mu = flow.mu
    return (p["a"] * sigma / 2) * (
        pitch.theta_0 * (1 / 3 + mu**2 / 2)
        + pitch.theta_tw * (1 + mu**2) / 4
        + mu * pitch.theta_1s / 2
        - lam / 2
    )


def thrust(c_t, p: Mapping):
    """T = C_T rho pi R^2 (Omega R)^2 [N]."""
    import math

    return c_t * p["rho"] * math.pi * p["R"] ** 2 * (p["Omega"] * p["R"]) ** 2


def rotor_forces(T, beta_1c, p: Mapping, ops, x_h=None):
    """Rotor force and pitching moment at the CG in body axes [N, N, N m].

    Thrust is normal to the tip-path plane, tilted forward by beta_1c + gamma_s:
        X_R = T sin(beta_1c + gamma_s),  Z_R = -T cos(beta_1c + gamma_s)
        M_R = -h X_R - x_h Z_R - (N_b/2) K_beta beta_1c   (hub spring moment)
    """
    x_h = p["x_h"] if x_h is None else x_h
    tilt = beta_1c + p["gamma_s"]
    X = T * ops.sin(tilt)
    Z = -T * ops.cos(tilt)
    M = -p["h"] * X - x_h * Z - (p["Nb"] / 2) * p["K_beta"] * beta_1c
    return X, Z, M
