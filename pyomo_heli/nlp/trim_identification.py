"""The trim-only identification: J_trim over measured trim points minimised by Ipopt, and the least-squares
standard errors of its estimate from the float model (the second route).

One Pyomo trim block per distinct identification speed
(:func:`pyomo_heli.nlp.trim_block.build_trim_block`), the free parameters shared, the model's trims taken to
the recorded conventions (:func:`pyomo_heli.physics.conventions.recorded_trim`), and

    J_trim = (1/N) sum_rows sum_(measured channels c) ((y_c - y_c,model) / 1 deg)^2

(paper Eq. 7; a row carries the channels it measured, N = number of rows).
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from ..physics.conventions import recorded_trim
from ..physics.model import HelicopterModel
from ..physics.parameters import DEG
from ..simulation.recorded_trims import jacobian, predict
from ..simulation.trim import trim_sweep


class TrimIdentificationFailed(RuntimeError):
    """The J_trim minimisation did not converge (a failed solve, not bad input)."""


def build_trim_nlp(model: HelicopterModel, free, pts: pd.DataFrame, conventions):
    """The trim-only identification NLP: trim blocks per distinct speed, J_trim over ``pts`` as objective."""
    import pyomo.environ as pyo

    from .objectives import add_trim_objective
    from .parameters import add_parameters
    from .trim_block import build_trim_block

    m = pyo.ConcreteModel(name="trim_identification")
    pmap = add_parameters(m, model.parameters, free)
    speeds = sorted(set(pts["V"].tolist()))
    init = model.with_parameters(**{f.name: f.initial for f in free}) if free else model
    guesses = trim_sweep(init, speeds)
    m.trim = pyo.Block(range(len(speeds)))
    rec = []
    for i, (V, tp) in enumerate(zip(speeds, guesses)):
        build_trim_block(m.trim[i], model, pmap, V, guess={**tp.to_dict(), **tp.extra_states})
        blk = m.trim[i]
        rec.append(recorded_trim(blk.col, blk.lon, blk.theta, pmap, conventions))
    index = {v: i for i, v in enumerate(speeds)}
    residuals = [[float(r.value) - rec[index[r.V]][r.channel] for r in grp.itertuples()]
                 for _, grp in pts.groupby("row", sort=True)]
    add_trim_objective(m, residuals)
    m.J_time = pyo.Expression(expr=0.0)  # no maneuvers: the front's other objective does not exist
    m.objective = pyo.Objective(expr=m.J_trim)
    m.speeds = speeds
    return m


def identify_trims(model: HelicopterModel, free, pts: pd.DataFrame, conventions, solver: str = "casadi-ipopt",
                   options: dict | None = None) -> tuple[dict, dict]:
    """Minimise J_trim over the free parameters; returns (values SI, solve info). RuntimeError on failure."""
    import pyomo.environ as pyo

    from .parameters import free_parameter_values
    from ..solvers import make_solver

    m = build_trim_nlp(model, free, pts, conventions)
    res = make_solver(m, solver, options).solve(warm_start="none")
    info = {"status": res.status, "iterations": res.iterations, "J_trim": float(pyo.value(m.J_trim)),
            "wall_time_s": res.wall_time, "solver": res.solver}
    if not res.success:
        raise TrimIdentificationFailed(f"trim identification failed: Ipopt status {res.status} ({res.message})")
    return free_parameter_values(m), info


#: a parameter whose trim sensitivity (scaled) is below this share of the largest is not seen by the trims
BLIND_RTOL = 1e-8


def standard_errors(model: HelicopterModel, conventions, pts: pd.DataFrame, names) -> dict:
    """Least-squares standard errors of ``names`` at ``model`` (its values are the estimate).

    e = data - model [deg]; J [deg per SI unit]; s^2 = e.e / (n - p); cov = s^2 (J^T J)^-1, computed on J's columns
    scaled to unit norm. A parameter the trims do not see (its column, or its share of a direction of the scaled
    J^T J, below ``BLIND_RTOL`` of the largest) has an infinite standard error, and ``cond`` is then infinite: the
    inverse would otherwise drop that direction and report a standard error of about zero.
    """
    y = predict(model, conventions, pts["V"], pts["channel"])
    e = (pts["value"].to_numpy(dtype=float) - y) / DEG
    J = jacobian(model, conventions, pts, names) / DEG
    n, p = J.shape
    dof = max(n - p, 1)
    s2 = float(e @ e) / dof
    if p == 0:
        return {"se": {}, "se_robust": {}, "corr": [], "s_deg": math.sqrt(s2), "dof": dof, "cond": 0.0}
    norms = np.linalg.norm(J, axis=0)
    seen = norms > BLIND_RTOL * max(float(norms.max()), np.finfo(float).tiny)
    Js = J[:, seen] / norms[seen]
    _, sv, vt = np.linalg.svd(Js, full_matrices=False)
    keep = sv > BLIND_RTOL * sv[0] if sv.size else np.zeros(0, bool)
    blind = ~seen
    if not keep.all():  # a combination of the seen columns the trims do not see: its parameters are blind too
        loads = np.abs(vt[~keep]).max(axis=0)
        blind[np.flatnonzero(seen)[loads > 1e-3]] = True
    inv_s = (vt[keep].T / sv[keep] ** 2) @ vt[keep]  # (Js^T Js)^-1 on the seen directions
    inv = np.full((p, p), np.nan)
    inv[np.ix_(seen, seen)] = inv_s / np.outer(norms[seen], norms[seen])
    inv[np.ix_(blind, blind)] = np.nan
    cov = s2 * inv
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    se[blind] = np.inf
    # sandwich (heteroscedasticity-robust, HC1) covariance: does not assume one variance for every point
    meat = (J * (e**2)[:, None]).T @ J * n / dof
    ok = ~blind
    se_rob = np.full(p, np.inf)
    sub = inv[np.ix_(ok, ok)]
    se_rob[ok] = np.sqrt(np.maximum(np.diag(sub @ meat[np.ix_(ok, ok)] @ sub), 0.0))
    d = np.where((se > 0) & np.isfinite(se), se, np.nan)
    corr = cov / np.outer(d, d)
    cond = float(sv[0] ** 2 / sv[-1] ** 2) if not blind.any() and sv.size else math.inf
    return {"se": dict(zip(names, se.tolist())), "se_robust": dict(zip(names, se_rob.tolist())),
            "corr": corr.tolist(), "s_deg": math.sqrt(s2), "dof": dof, "cond": cond}
