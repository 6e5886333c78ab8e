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

#: outputs that are states too (q, theta): the frame holds the state
STATE_OUTPUTS = ("q", "theta")

Increment = Callable[[float], float]


def sampled(times, values) -> Increment:
    """Linear interpolation of sampled values (held constant outside the record)."""
    times = np.asarray(times, dtype=float)
    values = np.asarray(values, dtype=float)
    return lambda t: np.interp(t, times, values)


def rk4_step(rhs, t, y, h):
    """One classic Runge-Kutta step of dy/dt = rhs(t, y) (floats, numpy arrays or casadi symbols)."""
    k1 = rhs(t, y)
    k2 = rhs(t + h / 2, y + h / 2 * k1)
    k3 = rhs(t + h / 2, y + h / 2 * k2)
    k4 = rhs(t + h, y + h * k3)
    return y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def rk4(rhs, t_eval, y0, substeps: int = 4) -> np.ndarray:
    """Fixed-step classic Runge-Kutta, ``substeps`` steps per interval of ``t_eval``."""
    ys = np.empty((len(y0), len(t_eval)))
    y = np.array(y0, dtype=float)
    ys[:, 0] = y
    for i in range(1, len(t_eval)):
        t, h = t_eval[i - 1], (t_eval[i] - t_eval[i - 1]) / substeps
        for _ in range(substeps):
            y = rk4_step(rhs, t, y, h)
            t += h
        if not np.all(np.isfinite(y)):
            raise RuntimeError(f"simulation diverged at t = {t:.3f} s")
        ys[:, i] = y
    return ys


def stable_substeps(model: HelicopterModel, trim: TrimPoint, dt: float, substeps: int) -> int:
    """RK4 steps per sample interval ``dt`` [s]: ``substeps``, or more where a lag state of the model is faster,
    so that each step is at most the shortest time constant (:meth:`HelicopterModel.lag_rates` at the trim);
    RK4 diverges beyond about 2.8 of them."""
    rates = model.lag_rates(trim.state(), trim.inputs())
    fastest = max(rates.values(), default=0.0)
    return max(substeps, int(np.ceil(dt * fastest))) if np.isfinite(fastest) else substeps


def simulate(model: HelicopterModel, trim: TrimPoint, t_eval, increments: Mapping[str, Increment] | None = None,
             x0: Mapping | None = None, base_inputs: Mapping | None = None, rtol: float = 1e-10,
             atol: float = 1e-10, max_step: float | None = None, method: str = "DOP853",
             substeps: int = 4, feedback: Callable[[float, Mapping], Mapping] | None = None) -> pd.DataFrame:
    """Integrate the model and return states, inputs, flapping and outputs at ``t_eval``.

    The initial state is the trim state (or ``x0``); the inputs are the trim
    inputs (or ``base_inputs``) plus ``increments``. ``method="rk4"`` takes
    ``substeps`` classic Runge-Kutta steps between consecutive ``t_eval``
    points: with sampled (piecewise-linear) inputs the input is smooth inside
    every step, where an adaptive method would crawl through every kink of a
    noisy input record. ``feedback(t, x)`` (x: the state by name) returns
    increments [rad] added to the inputs, e.g. a pilot holding the attitude
    (:mod:`pyomo_heli.flighttest.pilot`); the returned inputs include them.
    Columns: t, every state,
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

    def inputs_at(t, y):
        u = {k: base[k] + (float(increments[k](t)) if k in increments else 0.0) for k in INPUTS}
        if feedback is not None:
            for k, v in feedback(t, dict(zip(names, y))).items():
                u[k] += float(v)
        return u

    def rhs(t, y):
        return model.rhs_vector(y, inputs_at(t, y))

    if method == "rk4":
        ys = rk4(rhs, t_eval, y0, substeps)
    else:
        kw = {} if max_step is None else {"max_step": max_step}
        sol = solve_ivp(rhs, (float(t_eval[0]), float(t_eval[-1])), y0, t_eval=t_eval, method=method,
                        rtol=rtol, atol=atol, **kw)
        if not sol.success:
            raise RuntimeError(f"simulation failed: {sol.message}")
        ys = sol.y
    return frame(model, t_eval, ys, inputs_at)


def frame(model: HelicopterModel, t_eval, ys: np.ndarray, inputs_at: Callable[[float, np.ndarray], Mapping]
          ) -> pd.DataFrame:
    """The frame :func:`simulate` returns, from the states ``ys`` (one column per time of ``t_eval``, in
    ``model.state_names`` order) and ``inputs_at(t, y)`` (the inputs by channel [rad])."""
    names = model.state_names
    rows = []
    for i, t in enumerate(t_eval):
        x = dict(zip(names, ys[:, i]))
        u = inputs_at(t, ys[:, i])
        ctx = model.evaluate(x, u)
        row = {"t": t, **x, **u, **dict(zip(FLAPPING, (float(b) for b in ctx.beta)))}
        for k in STATE_OUTPUTS:  # one column each: the state, so a sensor effect on the output would be lost
            if float(ctx.outputs[k]) != x[k]:
                raise ValueError(f"simulate: an extension changes the recorded {k} ({float(ctx.outputs[k]):.6g} "
                                 f"against the state {x[k]:.6g} at t = {t:g} s); the frame's {k} column is the "
                                 f"state, so sensor effects on {', '.join(STATE_OUTPUTS)} are not supported here")
        row.update({k: float(v) for k, v in ctx.outputs.items() if k not in STATE_OUTPUTS})
        rows.append(row)
    return pd.DataFrame(rows)
