"""Fuselage drag and Munk moment (docs/model_forces.md section 5; model_spec.md 1.7)."""
from __future__ import annotations

from typing import Mapping


def airspeed(u, w, p: Mapping, ops):
    """V = sqrt(u^2 + w^2 + eps_v^2) [m/s]; eps_v keeps derivatives finite in hover."""
    return ops.sqrt(u**2 + w**2 + p["eps_v"] ** 2)


def fuselage_forces(u, w, p: Mapping, ops):
    """Drag along the airflow and a destabilising Munk moment [N, N, N m].

        X_F = -0.5 rho f_e V u,  Z_F = -0.5 rho f_e V w,  M_F = rho (K_f Vol_f) u w
    """
    V = airspeed(u, w, p, ops)
    X = -0.5 * p["rho"] * p["f_e"] * V * u
    Z = -0.5 * p["rho"] * p["f_e"] * V * w
    M = p["rho"] * p["KfVf"] * u * w
    return X, Z, M
