"""Uniform inflow: Glauert momentum theory with first-order dynamics.

docs/model_forces.md section 4 (model_spec.md 1.5). The flow is rotated into the
tip-path-plane (disc) frame by the forward TPP tilt beta_1c.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .rotor import HubFlow


@dataclass
class DiscFlow:
    """mu_d in-plane and lambda_d total (downward) inflow through the disc [-]."""

    mu_d: Any
    mu_zd: Any
    lambda_d: Any


def disc_flow(flow: HubFlow, lambda_i, beta_1c, ops) -> DiscFlow:
    """mu_d = mu cos(b1c) + mu_z sin(b1c); mu_zd = -mu sin(b1c) + mu_z cos(b1c);
    lambda_d = lambda_i - mu_zd."""
    cb, sb = ops.cos(beta_1c), ops.sin(beta_1c)
    mu_d = flow.mu * cb + flow.mu_z * sb
    mu_zd = -flow.mu * sb + flow.mu_z * cb
    return DiscFlow(mu_d=mu_d, mu_zd=mu_zd, lambda_d=lambda_i - mu_zd)


def glauert_thrust(lambda_i, disc: DiscFlow, ops):
    """Momentum-theory thrust coefficient C_T,Gl = 2 lambda_i sqrt(mu_d^2 + lambda_d^2) [-]."""
    return 2 * lambda_i * ops.sqrt(disc.mu_d**2 + disc.lambda_d**2)


def inflow_rate(c_t, c_t_glauert, tau_lambda):
    """d(lambda_i)/dt = (C_T - C_T,Gl) / tau_lambda [1/s]."""
    return (c_t - c_t_glauert) / tau_lambda
