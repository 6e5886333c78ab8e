"""Horizontal tail (docs/model_forces.md section 6; model_spec.md 1.8)."""
from __future__ import annotations

from typing import Mapping


def tail_forces(u, w, q, w_dw, p: Mapping, l_t=None):
    """Horizontal stabiliser lift in product form, smooth through hover [N, N, N m].

    u_t = u, w_t = w + q l_t - w_dw (w_dw: rotor downwash at the tail, 0 in M0)
        Z_T = -0.5 rho eta_t S_t CL_alpha_HT (u_t^2 alpha_t0 + u_t w_t)
        X_T = 0,  M_T = l_t Z_T   (upward lift gives a nose-down moment)
    """
    l_t = p["l_t"] if l_t is None else l_t
    u_t = u
    w_t = w + q * l_t - w_dw
    Z = -0.5 * p["rho"] * p["eta_t"] * p["S_t"] * p["CL_alpha_HT"] * (u_t**2 * p["alpha_t0"] + u_t * w_t)
    return 0.0 * Z, Z, l_t * Z
