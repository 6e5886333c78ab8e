"""Rigid-body longitudinal equations of motion and measured outputs.

docs/model_forces.md sections 7-8 (model_spec.md 1.9-1.10). Body axes at the CG:
x forward, z down, theta nose-up.
"""
from __future__ import annotations

from typing import Mapping


def rigid_body_rates(X, Z, M, u, w, q, theta, p: Mapping, ops):
    """du/dt, dw/dt, dq/dt, dtheta/dt [m/s^2, m/s^2, rad/s^2, rad/s].

        du/dt = X/m - g sin(theta) - q w
        dw/dt = Z/m + g cos(theta) + q u
        dq/dt = M/Iyy,  dtheta/dt = q
    """
    du = X / p["m"] - p["g"] * ops.sin(theta) - q * w
    dw = Z / p["m"] + p["g"] * ops.cos(theta) + q * u
    dq = M / p["Iyy"]
    return du, dw, dq, q


def load_factors(X, Z, p: Mapping):
    """Body-axis specific force over g at the CG: n_x = X/(m g), n_z = -Z/(m g) [-]."""
    W = p["m"] * p["g"]
    return X / W, -Z / W
