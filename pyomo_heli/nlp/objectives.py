"""Objectives of the identification NLP as Pyomo expressions.

J_time: output-error maximum likelihood with the residual covariance R
estimated (paper Eqs. 5-6), in concentrated form. At R's ML estimate
R = S/N, S = sum_k e_k e_k^T, Eq. 5 becomes
    J_time = N n_y / 2 + (N/2) ln det(R).
ln det R is written with a Cholesky factor R = L L^T whose entries are NLP
variables tied by equality constraints (smooth, no matrix inverse):
    ln det R = 2 sum_i ln L_ii,  so  J_time = N n_y/2 + N sum_i ln L_ii.
With ``covariance = "diagonal"`` L is diagonal: L_ii^2 = S_ii / N (the usual
output-error choice of uncorrelated output noise).

A documented relaxation: R = S/N + diag(r_floor^2), r_floor a resolution
floor per output (default about 1/300 of the sensor noise, see
``R_FLOOR``). Without it the concentrated likelihood is unbounded below on
noise-free data (one output fitted exactly drives ln det R to -inf, at any
parameter value); with it, noise-free data give a weighted least-squares fit
whose minimum is the true parameter set, and on noisy data the optimum moves
by O(r_floor^2 / sigma^2), about 1e-5 relative.

J_trim: mean square trim error (paper Eq. 7) over the configured trim
outputs, in degrees so that the unweighted sum is meaningful.
"""
from __future__ import annotations

import math

import numpy as np
import pyomo.environ as pyo

from ..units import DEG

#: resolution floor of each output in the likelihood [SI units]
R_FLOOR = {"q": 1e-5, "theta": 1e-5, "n_x": 2e-5, "n_z": 3e-5, "TAS": 2e-3, "beta_0": 3e-6}


def add_time_objective(m: pyo.Block, residuals: dict, outputs: list[str], covariance: str = "diagonal",
                       init_residuals: dict | None = None, r_floor: dict | None = None) -> None:
    """Add ``m.J_time`` from residual expressions.

    residuals: output name -> list of residual expressions (all maneuvers).
    init_residuals: output name -> numpy residuals at the initial guess, to
    initialise the Cholesky factor consistently.
    """
    if covariance not in ("diagonal", "full"):
        raise ValueError(f"covariance must be 'diagonal' or 'full', got {covariance!r}")
    n_y = len(outputs)
    N = len(residuals[outputs[0]])
    if any(len(residuals[o]) != N for o in outputs):
        raise ValueError("every output needs the same number of residuals")
    m.time_outputs = pyo.Set(initialize=outputs, ordered=True)
    pairs = [(a, b) for i, a in enumerate(outputs) for b in outputs[: i + 1]]
    if covariance == "diagonal":
        pairs = [(a, a) for a in outputs]
    m.cov_pairs = pyo.Set(initialize=pairs, dimen=2, ordered=True)
    m.n_samples = pyo.Param(initialize=N)

    floor = dict(R_FLOOR, **(r_floor or {}))

    def S_rule(_, a, b):
        extra = floor[a] ** 2 if a == b else 0.0
        return sum(ea * eb for ea, eb in zip(residuals[a], residuals[b])) / N + extra

    m.R_hat = pyo.Expression(m.cov_pairs, rule=S_rule)

    R0 = None
    if init_residuals is not None:
        E = np.array([init_residuals[o] for o in outputs])
        R0 = E @ E.T / N + np.diag([floor[o] ** 2 for o in outputs])
        if covariance == "diagonal":
            R0 = np.diag(np.diag(R0))
        L0 = np.linalg.cholesky(R0 + 1e-14 * np.eye(n_y))
    idx = {o: i for i, o in enumerate(outputs)}
    m.L = pyo.Var(m.cov_pairs, initialize=lambda _, a, b: float(L0[idx[a], idx[b]]) if R0 is not None else
                  (1.0 if a == b else 0.0))
    for a in outputs:
        m.L[a, a].setlb(1e-9)

    def chol_rule(_, a, b):
        ia, ib = idx[a], idx[b]
        lhs = sum(m.L[a, c] * m.L[b, c] for c in outputs[: min(ia, ib) + 1] if (a, c) in m.cov_pairs
                  and (b, c) in m.cov_pairs)
        return lhs == m.R_hat[a, b]

    m.cholesky = pyo.Constraint(m.cov_pairs, rule=chol_rule)
    m.J_time = pyo.Expression(expr=N * n_y / 2 + N * sum(pyo.log(m.L[a, a]) for a in outputs))


def j_time_value(residuals: dict, outputs: list[str], covariance: str = "diagonal",
                 r_floor: dict | None = None) -> float:
    """J_time of numpy residuals, computed directly from Eqs. 5-6 (an independent check).

    R = S/N + diag(r_floor^2) (the floor is the relaxation described above).
    """
    floor = dict(R_FLOOR, **(r_floor or {}))
    E = np.array([np.asarray(residuals[o], dtype=float) for o in outputs])
    N = E.shape[1]
    R = E @ E.T / N + np.diag([floor[o] ** 2 for o in outputs])
    if covariance == "diagonal":
        R = np.diag(np.diag(R))
    Rinv = np.linalg.inv(R)
    # At R's ML estimate the quadratic term of Eq. 5 is N n_y / 2 (exact without the floor).
    return float(N * len(outputs) / 2 + N / 2 * math.log(np.linalg.det(R)))


def add_trim_objective(m: pyo.Block, residuals: list) -> None:
    """``m.J_trim``: mean over trim points of the squared trim residual vector (residuals in rad)."""
    n = len(residuals)
    m.n_trims = pyo.Param(initialize=n)
    m.J_trim = pyo.Expression(expr=sum(sum((r / DEG) ** 2 for r in point) for point in residuals) / n)
