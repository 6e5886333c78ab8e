"""Standard errors at anchor A from the NLP itself: the inverse reduced Hessian of J_time.

J_time is a negative log-likelihood (concentrated output error, or with input errors the
likelihood of outputs and inputs, nlp/objectives.py). At its minimum subject to the model
equations c(x) = 0, the observed information of the free parameters is the Hessian of J_time
reduced to the manifold c = 0 with every other variable (states, outputs, Cholesky factor, input
errors) eliminated; its inverse is the parameter block of the inverse KKT matrix

    K = [[H, A^T], [A, 0]],   cov(theta) = (K^-1)_theta,theta,

H the Hessian of the Lagrangian and A the Jacobian of the equality rows, both at the solution,
with fixed variables and variables at an active bound removed (treated as known). This is the
NLP-sensitivity route of parmest's reduced Hessian and k_aug, written with the casadi adapter's own
derivative functions and scipy's sparse LU (there is no PyNumero here).

Against :mod:`.cramer_rao` (Gauss-Newton information from simulated sensitivities, expected
information) it is a second method: observed information, exact second derivatives, and with
input errors it accounts for their elimination, which the simulated sensitivities cannot.
"""
from __future__ import annotations

import numpy as np
import pyomo.environ as pyo
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def _sparse(ca_matrix) -> sp.csc_matrix:
    """A casadi DM (any sparsity) as a scipy CSC matrix."""
    s = ca_matrix.sparsity()
    return sp.csc_matrix((np.array(ca_matrix.nonzeros(), dtype=float), np.array(s.row()), np.array(s.colind())),
                         shape=(s.size1(), s.size2()))


def reduced_hessian_covariance(m, solver, objective_weight: float, bound_tol: float = 1e-6,
                               permc_spec: str = "MMD_AT_PLUS_A") -> dict:
    """Covariance of the free parameters (SI units) at the solution loaded in ``m``.

    m: the identification NLP after a successful min-J_time solve by ``solver`` (a
    ``CasadiIpoptSolver``; its multipliers are read from the model's ``dual`` suffix).
    objective_weight: the factor w of the solved objective w * J_time (the Pareto layer's
    1/s_time), so that the covariance is that of J_time as a negative log-likelihood.
    Returns {"names", "cov" (SI), "se" (SI dict)}.
    """
    ca = solver._ca
    if not hasattr(solver, "_jac_g"):
        raise TypeError("the reduced Hessian needs the casadi-ipopt adapter (solver 'casadi-ipopt')")
    args = solver._numeric_inputs()
    x = np.array([v.value for v in solver.variables], dtype=float)
    lam_g = solver._multipliers_from_model()["lam_g0"]
    hess_lag, jac_g = solver.unscaled_derivative_functions()
    if hess_lag is None:  # no dense columns: casadi's own Hessian of the Lagrangian
        lf, lg = ca.SX.sym("lf"), ca.SX.sym("lg", len(solver.constraints))
        xs, f, g = solver._nlp["x"], solver._nlp["f"], solver._nlp["g"]
        hess = ca.Function("h", [xs, lf, lg], [ca.triu(ca.hessian(lf * f + ca.dot(lg, g), xs)[0])])
        H = _sparse(hess(x, 1.0, lam_g))
    else:
        H = _sparse(hess_lag(x, [], 1.0, lam_g))
    H = H + sp.triu(H, k=1).T  # the adapter gives the upper triangle
    if jac_g is None:
        jac = ca.Function("j", [solver._nlp["x"]], [ca.jacobian(solver._nlp["g"], solver._nlp["x"])])
        A = _sparse(jac(x))
        g = np.asarray(ca.Function("g", [solver._nlp["x"]], [solver._nlp["g"]])(x)).ravel()
    else:
        g_dm, jac_dm = jac_g(x, [])
        A, g = _sparse(jac_dm), np.asarray(g_dm).ravel()

    lbx, ubx, lbg, ubg = args["lbx"], args["ubx"], args["lbg"], args["ubg"]
    scale_x = 1.0 + np.abs(x)
    at_bound = (np.abs(x - lbx) <= bound_tol * scale_x) | (np.abs(x - ubx) <= bound_tol * scale_x)
    free = np.flatnonzero(~at_bound)
    scale_g = 1.0 + np.abs(g)
    active = (np.abs(g - lbg) <= bound_tol * scale_g) | (np.abs(g - ubg) <= bound_tol * scale_g)
    rows = np.flatnonzero(active)

    index = {id(v): i for i, v in enumerate(solver.variables)}
    names = list(m.free_parameters)
    cols = [index[id(m.theta_s[k])] for k in names]
    pos = {c: k for k, c in enumerate(free)}
    missing = [k for k, c in zip(names, cols) if c not in pos]
    if missing:
        raise ValueError(f"parameter(s) {missing} at a bound: no reduced-Hessian standard error")
    Hf = H[free][:, free]
    Af = A[rows][:, free]
    # rows left without a variable (e.g. a trim block's V == V_target when V is pinned by its bounds)
    # say nothing about the free variables; keeping them would make K singular
    keep = np.flatnonzero(np.abs(Af).sum(axis=1).A.ravel() > 0)
    Af = Af[keep]
    K = sp.bmat([[Hf, Af.T], [Af, None]], format="csc")
    rhs = np.zeros((K.shape[0], len(cols)))
    for j, c in enumerate(cols):
        rhs[pos[c], j] = 1.0
    lu = spla.splu(K, permc_spec=permc_spec)  # K is structurally symmetric: minimum degree on A^T + A
    Z = lu.solve(rhs)
    cov_s = Z[[pos[c] for c in cols], :] * objective_weight
    scales = np.array([pyo.value(m.theta_scale[k]) for k in names])
    cov = cov_s * np.outer(scales, scales)
    return {"names": names, "cov": cov, "se": {k: float(np.sqrt(cov[i, i])) for i, k in enumerate(names)}}
