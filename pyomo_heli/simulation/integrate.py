"""Time simulation of the float model from a trim (scipy.integrate.solve_ivp).

Inputs are increments on the trim inputs, given per channel either as a
callable of time or as sampled values (linearly interpolated, exactly as the
collocation model interpolates them).
"""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

from ..physics.model import FLAPPING, INPUTS, HelicopterModel
from .trim import TrimPoint

Increment = Callable[[float], float]


def sampled(times, values) -> Increment:
    """Linear interpolation of sampled values (held constant outside the record)."""
    times = np.asarray(times, dtype=float)
    values = np.asarray(values, dtype=float)
    return lambda t: np.interp(t, times, values)


def simulate(model: HelicopterModel, trim: TrimPoint, t_eval, increments: Mapping[str, Increment] | None = None,
             x0: Mapping | None = None, base_inputs: Mapping | None = None, rtol: float = 1e-10,
             atol: float = 1e-10, max_step: float | None = None, method: str = "DOP853") -> pd.DataFrame:
    """Integrate the model and return states, inputs, flapping and outputs at ``t_eval``.

    The initial state is the trim state (or ``x0``); the inputs are the trim
    inputs (or ``base_inputs``) plus ``increments``. Columns: t, every state,
    col, lon, beta_0, beta_1c, beta_1s and every output (n_x, n_z, TAS, ...).
    """
    increments = dict(increments or {})
    unknown = set(increments) - set(INPUTS)
    if unknown:
        raise ValueError(f"unknown input channel(s) {sorted(unknown)}; choose from {', '.join(INPUTS)}")
    t_eval = np.asarray(t_eval, dtype=float)
    base = dict(trim.inputs() if base_inputs is None else base_inputs)
    names = model.state_names
    start = dict(trim.state())
    if x0 is not None:
        start.update(x0)
    y0 = np.array([start[n] for n in names], dtype=float)

    def inputs_at(t):
        return {k: base[k] + (float(increments[k](t)) if k in increments else 0.0) for k in INPUTS}

    def rhs(t, y):
        return model.rhs_vector(y, inputs_at(t))

    kw = {} if max_step is None else {"max_step": max_step}
    sol = solve_ivp(rhs, (float(t_eval[0]), float(t_eval[-1])), y0, t_eval=t_eval, method=method,
                    rtol=rtol, atol=atol, **kw)
    if not sol.success:
        raise RuntimeError(f"simulation failed: {sol.message}")
    rows = []
    for i, t in enumerate(sol.t):
        x = dict(zip(names, sol.y[:, i]))
        u = inputs_at(t)
        ctx = model.evaluate(x, u)
        row = {"t": t, **x, **u, **dict(zip(FLAPPING, (float(b) for b in ctx.beta)))}
        row.update({k: float(v) for k, v in ctx.outputs.items() if k not in ("q", "theta")})
        rows.append(row)
    return pd.DataFrame(rows)
