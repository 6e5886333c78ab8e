"""The fixed-step RK4 simulation of :mod:`.integrate`, evaluated by casadi instead of Python.

Why: the sensitivities behind the standard errors and the residual diagnosis
(:mod:`.sensitivity`) simulate every maneuver 2n+1 times per estimate, and the
Python RK4 spends about 50 microseconds of interpreter time per right-hand
side: the standard errors were the largest part of a Case 2 run.

What: the same physics (:func:`pyomo_heli.physics.model.evaluate` with casadi
symbols, the parameters as inputs) becomes one RK4 step function, ``substeps``
classic Runge-Kutta steps across one sample interval with the inputs linear
inside it (as :func:`.integrate.sampled` interpolates them), accumulated over
the samples with ``Function.mapaccum``, and an output function mapped over the
samples. The arithmetic is that of ``simulate(..., method="rk4")``; the two
agree to rounding (``tests/test_simulation.py``).

The compiled functions depend only on the model's structure (its float
extensions and states), not on the parameter values, and are cached per
structure and record length.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from ..physics.model import INPUTS, HelicopterModel, evaluate
from ..physics.ops import get_ops
from .integrate import rk4_step, stable_substeps
from .trim import TrimPoint

#: (structure, substeps) -> (step function, output function, output names); structure keeps the
#: extension objects alive so that their ids stay theirs
_FUNCTIONS: dict = {}
#: (structure, substeps, number of intervals) -> the step function accumulated over the intervals
_ACCUMULATED: dict = {}


def _structure(model: HelicopterModel) -> tuple:
    """What the compiled functions depend on: the float extensions (by identity), states, parameter names."""
    return (tuple(id(e) for e in model.float_extensions), tuple(model.state_names), tuple(model.parameters))


def _symbolic_model(model: HelicopterModel):
    """casadi symbols ``x`` (the states, in ``model.state_names`` order) and ``p`` (the parameters, in
    ``model.parameters`` order), and the model evaluated with them: ``context(xv, col, lon)`` is
    :func:`evaluate`'s context, ``rates(xv, col, lon)`` the column of state rates dx/dt."""
    import casadi as ca

    ops = get_ops("casadi")
    states, names, exts = model.state_names, list(model.parameters), model.float_extensions
    x = ca.SX.sym("x", len(states))
    p = ca.SX.sym("p", len(names))
    pmap = dict(zip(names, ca.vertsplit(p)))

    def context(xv, col, lon):
        return evaluate(dict(zip(states, ca.vertsplit(xv))), {"col": col, "lon": lon}, pmap, ops=ops, extensions=exts)

    def rates(xv, col, lon):
        eqs = context(xv, col, lon).state_eqs
        return ca.vertcat(*[eqs[s][1] / eqs[s][0] for s in states])

    return x, p, context, rates


def _rk4_interval(rhs, x, dt, substeps: int):
    """``substeps`` classic RK4 steps of dy/dtau = rhs(tau, y) across one sample interval [0, dt] from y = x."""
    h, tau, y = dt / substeps, 0.0, x
    for _ in range(substeps):
        y = rk4_step(rhs, tau, y, h)
        tau = tau + h
    return y


def _functions(model: HelicopterModel, substeps: int):
    key = (_structure(model), substeps)
    if key in _FUNCTIONS:
        return _FUNCTIONS[key][:3]
    import casadi as ca

    x, p, context, rates = _symbolic_model(model)
    # one sample interval: inputs u0 at its start, u1 at its end, linear in between (tau: time into it)
    u0, u1, dt = ca.SX.sym("u0", len(INPUTS)), ca.SX.sym("u1", len(INPUTS)), ca.SX.sym("dt")

    def rhs(tau, y):
        u = u0 + tau / dt * (u1 - u0)
        return rates(y, u[0], u[1])

    step = ca.Function("rk4_interval", [x, ca.vertcat(u0, u1, dt), p], [_rk4_interval(rhs, x, dt, substeps)])

    col, lon = ca.SX.sym("col"), ca.SX.sym("lon")
    ctx = context(x, col, lon)
    out_names = list(ctx.outputs)
    outputs = ca.Function("outputs", [x, ca.vertcat(col, lon), p], [ca.vertcat(*[ctx.outputs[o] for o in out_names])])
    _FUNCTIONS[key] = (step, outputs, out_names, model.float_extensions)
    return step, outputs, out_names


def _substeps(model: HelicopterModel, trim: TrimPoint, t_eval: np.ndarray, substeps: int) -> int:
    """``substeps``, or more for a fast lag state (:func:`~.integrate.stable_substeps`)."""
    return stable_substeps(model, trim, float(np.max(np.diff(t_eval))), substeps) if len(t_eval) > 1 else substeps


def simulate_outputs(model: HelicopterModel, trim: TrimPoint, t_eval, increments: Mapping[str, np.ndarray],
                     outputs, substeps: int = 4) -> dict[str, np.ndarray]:
    """Outputs at ``t_eval`` of ``simulate(model, trim, t_eval, sampled increments, method="rk4")``.

    increments: channel -> input increment at each time of ``t_eval`` [rad] (missing channels are 0).
    Raises RuntimeError if the simulation diverges, like the Python RK4.
    """
    t_eval = np.asarray(t_eval, dtype=float)
    unknown = set(increments) - set(INPUTS)
    if unknown:
        raise ValueError(f"unknown input channel(s) {sorted(unknown)}; choose from {', '.join(INPUTS)}")
    substeps = _substeps(model, trim, t_eval, substeps)
    _, out_fun, out_names = _functions(model, substeps)
    missing = [o for o in outputs if o not in out_names]
    if missing:
        raise ValueError(f"unknown output(s) {missing}; the model gives {', '.join(out_names)}")
    xs, u = simulate_states(model, trim, t_eval, increments, substeps)
    bad = ~np.all(np.isfinite(xs), axis=0)
    if bad.any():
        raise RuntimeError(f"simulation diverged at t = {t_eval[np.argmax(bad)]:.3f} s")
    n = len(t_eval)
    p = np.array([model.parameters[name] for name in model.parameters], dtype=float)
    ys = np.asarray(out_fun.map(n)(xs, u, np.tile(p[:, None], (1, n))))
    return {o: ys[out_names.index(o)].copy() for o in outputs}


def simulate_states(model: HelicopterModel, trim: TrimPoint, t_eval, increments: Mapping[str, np.ndarray],
                    substeps: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """The states (rows: ``model.state_names``; columns: the times of ``t_eval``) and the inputs (rows: col, lon)
    of ``simulate(model, trim, t_eval, sampled increments, method="rk4")``, by the compiled RK4. Not checked:
    a diverging record holds non-finite values from where it diverged."""
    t_eval = np.asarray(t_eval, dtype=float)
    substeps = _substeps(model, trim, t_eval, substeps)
    step, _, _ = _functions(model, substeps)
    n = len(t_eval)
    base = trim.inputs()
    u = np.vstack([base[k] + np.asarray(increments.get(k, np.zeros(n)), dtype=float) for k in INPUTS])
    p = np.array([model.parameters[name] for name in model.parameters], dtype=float)
    x0 = np.array([trim.state()[s] for s in model.state_names], dtype=float)
    if n > 1:
        key = (_structure(model), substeps, n - 1)
        if key not in _ACCUMULATED:
            _ACCUMULATED[key] = step.mapaccum("rk4_record", n - 1)
        intervals = np.vstack([u[:, :-1], u[:, 1:], np.diff(t_eval)[None, :]])
        with np.errstate(all="ignore"):
            xs = np.asarray(_ACCUMULATED[key](x0, intervals, np.tile(p[:, None], (1, n - 1))))
        xs = np.hstack([x0[:, None], xs])
    else:
        xs = x0[:, None]
    return xs, u


#: (structure, substeps) -> (step Jacobian function, output Jacobian function)
_JACOBIANS: dict = {}


def _jacobian_functions(model: HelicopterModel, substeps: int):
    """d(next state)/d(state, interval inputs) of one RK4 interval and d(outputs)/d(state, inputs)."""
    key = (_structure(model), substeps)
    if key not in _JACOBIANS:
        import casadi as ca

        step, out_fun, _ = _functions(model, substeps)
        x = ca.SX.sym("x", step.size1_in(0))
        iv = ca.SX.sym("iv", step.size1_in(1))
        u = ca.SX.sym("u", out_fun.size1_in(1))
        p = ca.SX.sym("p", step.size1_in(2))
        y = step(x, iv, p)
        step_jac = ca.Function("rk4_interval_jac", [x, iv, p], [ca.densify(ca.jacobian(y, x)),
                                                                 ca.densify(ca.jacobian(y, iv))])
        out = out_fun(x, u, p)
        out_jac = ca.Function("outputs_jac", [x, u, p], [ca.densify(ca.jacobian(out, x)),
                                                         ca.densify(ca.jacobian(out, u))])
        _JACOBIANS[key] = (step_jac, out_jac)
    return _JACOBIANS[key]


def input_sensitivities(model: HelicopterModel, trim: TrimPoint, t_eval, increments: Mapping[str, np.ndarray],
                        outputs, channels, substeps: int = 4, keep=None) -> tuple[dict, dict]:
    """Outputs and their derivatives with respect to every sample of the input ``channels``.

    The errors-in-variables counterpart of the parameter sensitivities: how each output sample moves
    when one measured input sample moves (the input is linear between samples, as in the simulation
    and the NLP's ``u_err``). Exact derivatives of the RK4 arithmetic of :func:`simulate_outputs`, from
    the Jacobians of one interval and of the outputs (casadi) chained along the record (numpy):
    with G_k = dx_k/dU, G_0 = 0 (the start is the model's trim, not the measured inputs) and
    G_{k+1} = A_k G_k + B0_k E_k + B1_k E_{k+1}.

    Returns ``(y, S)``: output -> values at ``t_eval``; output -> (N, len(channels) * N) matrix whose
    column ``c * N + k`` is d(output)/d(input ``channels[c]`` at sample k). ``keep``: sample indices
    whose rows of S are wanted (in that order; default all), so that a long record's S stays small.
    """
    t_eval = np.asarray(t_eval, dtype=float)
    bad = [c for c in channels if c not in INPUTS]
    if bad:
        raise ValueError(f"unknown input channel(s) {bad}; choose from {', '.join(INPUTS)}")
    y = simulate_outputs(model, trim, t_eval, increments, outputs, substeps)  # checks outputs, divergence
    substeps = _substeps(model, trim, t_eval, substeps)
    step, out_fun, out_names = _functions(model, substeps)
    step_jac, out_jac = _jacobian_functions(model, substeps)
    n, ni, nc = len(t_eval), len(INPUTS), len(channels)
    base = trim.inputs()
    u = np.vstack([base[k] + np.asarray(increments.get(k, np.zeros(n)), dtype=float) for k in INPUTS])
    p = np.array([model.parameters[name] for name in model.parameters], dtype=float)
    x0 = np.array([trim.state()[s] for s in model.state_names], dtype=float)
    nx = len(x0)
    P = np.tile(p[:, None], (1, n))
    if n > 1:
        intervals = np.vstack([u[:, :-1], u[:, 1:], np.diff(t_eval)[None, :]])
        xs = np.hstack([x0[:, None], np.asarray(_ACCUMULATED[(_structure(model), substeps, n - 1)](
            x0, intervals, P[:, :-1]))])
        A, B = (np.asarray(v) for v in step_jac.map(n - 1)(xs[:, :-1], intervals, P[:, :-1]))
        A = A.reshape(nx, n - 1, nx).transpose(1, 0, 2)  # (interval, next state, state)
        B = B.reshape(nx, n - 1, 2 * ni + 1).transpose(1, 0, 2)
    else:
        xs = x0[:, None]
    C, D = (np.asarray(v) for v in out_jac.map(n)(xs, u, P))
    C = C.reshape(len(out_names), n, nx).transpose(1, 0, 2)  # (sample, output, state)
    D = D.reshape(len(out_names), n, ni).transpose(1, 0, 2)
    ch = [INPUTS.index(c) for c in channels]
    rows = [out_names.index(o) for o in outputs]
    keep = np.arange(n) if keep is None else np.asarray(keep, dtype=int)
    where = {int(k): i for i, k in enumerate(keep)}
    S = {o: np.zeros((len(keep), nc * n)) for o in outputs}
    G = np.zeros((nx, nc * n))
    cols = np.arange(nc) * n
    for k in range(n):
        if k in where:
            out_k = C[k][rows] @ G
            out_k[:, cols + k] += D[k][np.ix_(rows, ch)]
            for r, o in enumerate(outputs):
                S[o][where[k]] = out_k[r]
        if k < n - 1:
            G = A[k] @ G
            G[:, cols + k] += B[k][:, ch]
            G[:, cols + k + 1] += B[k][:, [ni + c for c in ch]]
    return y, S


#: (structure, substeps) -> (step function with state feedback, output function, output names, extensions)
_FEEDBACK: dict = {}


def _feedback_functions(model: HelicopterModel, substeps: int):
    """As :func:`_functions`, with linear state feedback inside the interval: u = u_lin(tau) + K (x - x_ref)."""
    key = (_structure(model), substeps)
    if key in _FEEDBACK:
        return _FEEDBACK[key][:2]
    import casadi as ca

    x, p, _, rates = _symbolic_model(model)
    exts = model.float_extensions
    nx, ni = len(model.state_names), len(INPUTS)
    fb = ca.SX.sym("fb", ni * nx + nx)  # K row by row, then x_ref
    K = ca.reshape(fb[:ni * nx], nx, ni).T
    x_ref = fb[ni * nx:]
    u0, u1, dt = ca.SX.sym("u0", ni), ca.SX.sym("u1", ni), ca.SX.sym("dt")

    def rhs(tau, y):
        u = u0 + tau / dt * (u1 - u0) + K @ (y - x_ref)
        return rates(y, u[0], u[1])

    step = ca.Function("rk4_interval_feedback", [x, ca.vertcat(u0, u1, dt), p, fb],
                       [_rk4_interval(rhs, x, dt, substeps)])
    _FEEDBACK[key] = (step, exts)
    return step, exts


def simulate_with_feedback(model: HelicopterModel, trim: TrimPoint, t_eval, increments: Mapping[str, np.ndarray],
                           gain: Mapping[str, Mapping[str, float]], x_ref: Mapping[str, float] | None = None,
                           substeps: int = 4) -> dict[str, np.ndarray]:
    """States, inputs and outputs at ``t_eval`` of the RK4 simulation with linear state feedback

        u(t) = u_trim + increment(t) + sum_s gain[input][s] (x_s - x_ref_s)      [rad]

    (the increments linear between samples, as in :func:`simulate_outputs`; the feedback acts at every RK4
    stage). ``x_ref`` defaults to the trim state. Returns every state, ``col``, ``lon`` (the total inputs,
    feedback included, as an actuator records them) and every output, by name.
    ``pyomo_heli.simulation.integrate.simulate(..., feedback=...)`` is the Python counterpart.
    """
    t_eval = np.asarray(t_eval, dtype=float)
    unknown = (set(increments) | set(gain)) - set(INPUTS)
    if unknown:
        raise ValueError(f"unknown input channel(s) {sorted(unknown)}; choose from {', '.join(INPUTS)}")
    states = model.state_names
    bad = sorted({s for g in gain.values() for s in g} - set(states))
    if bad:
        raise ValueError(f"feedback from unknown state(s) {bad}; the model's states are {', '.join(states)}")
    step, _ = _feedback_functions(model, substeps)
    _, out_fun, out_names = _functions(model, substeps)
    n = len(t_eval)
    base = trim.inputs()
    u = np.vstack([base[k] + np.asarray(increments.get(k, np.zeros(n)), dtype=float) for k in INPUTS])
    p = np.array([model.parameters[name] for name in model.parameters], dtype=float)
    x0 = np.array([trim.state()[s] for s in states], dtype=float)
    xr = x0 if x_ref is None else np.array([x_ref.get(s, trim.state()[s]) for s in states], dtype=float)
    K = np.array([[float(gain.get(i, {}).get(s, 0.0)) for s in states] for i in INPUTS])
    fb = np.concatenate([K.ravel(), xr])
    if n > 1:
        acc = step.mapaccum("rk4_record_feedback", n - 1)
        intervals = np.vstack([u[:, :-1], u[:, 1:], np.diff(t_eval)[None, :]])
        xs = np.hstack([x0[:, None], np.asarray(acc(x0, intervals, np.tile(p[:, None], (1, n - 1)),
                                                    np.tile(fb[:, None], (1, n - 1))))])
    else:
        xs = x0[:, None]
    bad_t = ~np.all(np.isfinite(xs), axis=0)
    if bad_t.any():
        raise RuntimeError(f"simulation diverged at t = {t_eval[np.argmax(bad_t)]:.3f} s")
    u_total = u + K @ (xs - xr[:, None])
    ys = np.asarray(out_fun.map(n)(xs, u_total, np.tile(p[:, None], (1, n))))
    out = {s: xs[j].copy() for j, s in enumerate(states)}
    out.update({k: u_total[j].copy() for j, k in enumerate(INPUTS)})
    out.update({o: ys[j].copy() for j, o in enumerate(out_names)})
    return out
