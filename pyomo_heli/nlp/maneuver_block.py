"""A maneuver as a fully discretised block of the NLP (pyomo.dae collocation).

Every sample time of the record is a finite-element boundary, so outputs are
evaluated exactly at the measurement times (never snapped). Inside each
element the Radau collocation points carry the same physics as the trim
blocks and the simulator (:func:`pyomo_heli.physics.model.evaluate`).
Inputs are the trim inputs of the block's start trim plus the measured
increments, linearly interpolated at the collocation points, and the initial
state is the model's own trim state at the start speed (model_spec.md 1.13).
"""
from __future__ import annotations

from types import SimpleNamespace
from typing import Mapping

import numpy as np
import pyomo.dae as dae
import pyomo.environ as pyo
from pyomo.core.base.var import VarData

from ..physics.model import FLAPPING, INPUTS, SHARED, STATES, HelicopterModel, evaluate
from ..physics.ops import get_ops
from .point_rows import PointRows
from .trim_block import STATE_BOUNDS, settle


def collocation_point(x: Mapping, dx: Mapping, beta, base: Mapping, du: Mapping, err: Mapping, p, ops,
                      extensions, states) -> SimpleNamespace:
    """The equations of one collocation point: the one place they are written.

    Both the Pyomo rules of :func:`build_maneuver_block` (``lhs == rhs``) and the compiled point rows
    (``lhs - rhs``, :func:`_point_rows`) are built from it, with Pyomo or casadi ``ops``.

    x, dx: state -> value and time derivative at the point; beta: the three flapping angles [rad];
    p: parameter name -> value. The inputs are u_k = base_k + du_k + err_k [rad]: the start trim's
    input, the measured increment (interpolated at the point) and the estimated input error (0
    without errors in variables).

    Returns the evaluated physics ``ctx`` (:func:`~pyomo_heli.physics.model.evaluate`) with
    ``ctx.equations``: the (lhs, rhs) pairs of the point in row order, coef_s * dx_s = f_s for every
    state in ``states``, then r_i = 0 for the three flapping residuals. The output equations
    y_k = output_k at the samples come from :func:`output_equation`.
    """
    u = {k: base[k] + du[k] + err[k] for k in INPUTS}
    ctx = evaluate(x, u, p, ops=ops, beta=beta, extensions=extensions)
    ctx.equations = ([(ctx.state_eqs[s][0] * dx[s], ctx.state_eqs[s][1]) for s in states]
                     + [(r, 0) for r in ctx.flap_residuals])
    return ctx


def output_equation(ctx, k: str, y):
    """(lhs, rhs) of output ``k`` at a sample: its variable ``y`` equals the model output."""
    return y, ctx.outputs[k]


def build_maneuver_block(blk: pyo.Block, model: HelicopterModel, pmap, t_samples, increments: Mapping[str, np.ndarray],
                         start, ncp: int = 3, scheme: str = "LAGRANGE-RADAU",
                         initial_guess=None, input_errors: tuple = (), input_times=None) -> None:
    """Populate ``blk`` with one maneuver.

    t_samples: increasing sample times [s] (element boundaries).
    increments: channel -> input increment [rad] at each sample, or at each of ``input_times`` [s] when
    given (the inputs at a finer rate than the outputs, ``resample_inputs = "record"``).
    start: an object with ``col, lon, u, w, theta, lambda_i`` (floats or
    Pyomo components, e.g. a trim block) giving the initial state and the
    base inputs.
    initial_guess: optional DataFrame (t + state/flap columns) used to
    initialise the variables, e.g. a simulation.
    input_errors: input channels whose measurement error is estimated (errors in
    variables): ``blk.u_err[k, t_i]`` at every input sample ``blk.input_samples``, added to the measured
    input and, like it, linearly interpolated between the input samples (the likelihood term is
    :func:`.objectives.add_known_noise_time_objective`).
    """
    ops = get_ops("pyomo")
    t_samples = np.asarray(t_samples, dtype=float)
    unknown = set(increments) - set(INPUTS)
    if unknown:
        raise ValueError(f"unknown input channel(s) {sorted(unknown)}")
    states = STATES + tuple(s for e in model.extensions for s in e.states)
    blk.t = dae.ContinuousSet(initialize=list(t_samples))
    blk.samples = pyo.Set(initialize=list(t_samples), ordered=True)
    blk.x = pyo.Var(states, blk.t, initialize=0.0)
    blk.dx = dae.DerivativeVar(blk.x, wrt=blk.t)
    blk.beta = pyo.Var(FLAPPING, blk.t, initialize=0.0)
    pyo.TransformationFactory("dae.collocation").apply_to(blk, wrt=blk.t, nfe=len(t_samples) - 1, ncp=ncp,
                                                          scheme=scheme)
    times = list(blk.t)
    t0 = times[0]
    for (s, t), v in blk.x.items():
        if s in STATE_BOUNDS:
            v.setlb(STATE_BOUNDS[s][0])
            v.setub(STATE_BOUNDS[s][1])
    blk.beta["beta_1c", :].setlb(STATE_BOUNDS["beta_1c"][0])
    blk.beta["beta_1c", :].setub(STATE_BOUNDS["beta_1c"][1])
    # Radau uses no derivative at t0; fixing it keeps the model free of dangling variables.
    for s in states:
        blk.dx[s, t0].fix(0.0)

    t_in = t_samples if input_times is None else np.asarray(input_times, dtype=float)
    if input_times is not None and (t_in[0] > t_samples[0] + 1e-9 or t_in[-1] < t_samples[-1] - 1e-9):
        raise ValueError(f"input times {t_in[0]:g}-{t_in[-1]:g} s do not cover the samples "
                         f"{t_samples[0]:g}-{t_samples[-1]:g} s")
    blk.input_samples = pyo.Set(initialize=list(t_in), ordered=True)
    inc = {k: np.interp(times, t_in, np.asarray(increments.get(k, np.zeros_like(t_in)), dtype=float))
           for k in INPUTS}
    blk.du = pyo.Param(INPUTS, blk.t, mutable=True,
                       initialize={(k, t): float(inc[k][i]) for k in INPUTS for i, t in enumerate(times)})
    u_err, err_where = _input_error_terms(blk, t_in, times, input_errors)

    # Named intermediates (rotor flow, thrust coefficient, total forces) of each
    # time point: the NL writer exports them once as defined variables instead
    # of inlining them in every equation that uses them (physics.model.SHARED).
    blk.shared = pyo.Expression(SHARED, blk.t, initialize=0.0)
    ctxs: dict = {}

    def share_at(t):
        def share(name, expr):
            blk.shared[name, t].set_value(expr)
            return blk.shared[name, t]
        return share

    def ctx_at(t):
        if t not in ctxs:
            ctxs[t] = collocation_point({s: blk.x[s, t] for s in states}, {s: blk.dx[s, t] for s in states},
                                        [blk.beta[b, t] for b in FLAPPING], {k: getattr(start, k) for k in INPUTS},
                                        {k: blk.du[k, t] for k in INPUTS}, {k: u_err(k, t) for k in INPUTS}, pmap,
                                        SimpleNamespace(**vars(ops), share=share_at(t)), model.extensions, states)
        return ctxs[t]

    def equation(t, row):
        lhs, rhs = ctx_at(t).equations[row]
        return lhs == rhs

    index = {s: j for j, s in enumerate(states)}
    blk.ode = pyo.Constraint(states, blk.t, rule=lambda _, s, t: pyo.Constraint.Skip if t == t0
                             else equation(t, index[s]))
    blk.flapping = pyo.Constraint(range(3), blk.t, rule=lambda _, i, t: equation(t, len(states) + i))
    init = {"u": start.u, "w": start.w, "q": 0.0, "theta": start.theta, "lambda_i": start.lambda_i}
    for e in model.extensions:
        for s in e.states:
            init[s] = getattr(start, s)
    blk.initial = pyo.Constraint(states, rule=lambda _, s: blk.x[s, t0] == init[s])
    # Outputs at the samples are variables defined by equalities, not expressions:
    # the likelihood sums squares over thousands of samples, and with output
    # variables that sum is a plain quadratic (diagonal Hessian) instead of a
    # row that inlines the whole force model at every sample.
    out_names = list(ctx_at(t0).outputs)
    blk.y = pyo.Var(out_names, blk.samples, initialize=0.0)

    def output_rule(_, k, t):
        lhs, rhs = output_equation(ctx_at(t), k, blk.y[k, t])
        return lhs == rhs

    blk.output_eq = pyo.Constraint(out_names, blk.samples, rule=output_rule)
    blk.point_rows = _point_rows(blk, model, pmap, start, states, out_names, input_errors, err_where)
    if initial_guess is not None:
        initialise_from(blk, initial_guess, states)


def _point_rows(blk, model, pmap, start, states, out_names, channels, err_where) -> PointRows:
    """The block's ode, flapping and output rows as one casadi function per point (nlp/point_rows.py).

    Leaves of a point: states, their derivatives, flapping angles, outputs (samples only; 0 elsewhere),
    the start trim's inputs, the two input-error samples around the point per error channel, the
    free parameters (scaled Vars). Data: the measured input increments and the error weights. The
    function is :func:`collocation_point` with casadi symbols, the equations the Pyomo rules are built from.
    """
    times, samples = list(blk.t), set(blk.samples)
    t0 = times[0]
    free = [n for n in pmap if not isinstance(pmap[n], (int, float))]
    linear = getattr(pmap, "free", {})  # name -> (Var, scale) for the ParameterMap of add_parameters
    if set(free) - set(linear) or not all(isinstance(getattr(start, k), (int, float, VarData)) for k in INPUTS):
        return None  # a parameter or start input that is neither a number nor (scale times) a Var: NL route only
    leaf_names = (tuple(f"x:{s}" for s in states) + tuple(f"dx:{s}" for s in states)
                  + tuple(f"beta:{b}" for b in FLAPPING) + tuple(f"y:{k}" for k in out_names)
                  + tuple(f"base:{k}" for k in INPUTS) + tuple(f"err_{a}:{k}" for k in channels for a in "ab")
                  + tuple(f"p:{n}" for n in free))
    data_names = tuple(f"du:{k}" for k in INPUTS) + tuple(f"w:{k}" for k in channels)
    fixed = {n: float(pmap[n]) for n in pmap if n not in free}
    scale = {n: linear[n][1] for n in free}
    extensions = model.extensions

    def make_function(ca):
        ops = get_ops("casadi")
        z, d = ca.SX.sym("z", len(leaf_names)), ca.SX.sym("d", len(data_names))
        leaf = dict(zip(leaf_names, ca.vertsplit(z)))
        dat = dict(zip(data_names, ca.vertsplit(d)))
        err = {k: (dat[f"w:{k}"] * leaf[f"err_a:{k}"] + (1.0 - dat[f"w:{k}"]) * leaf[f"err_b:{k}"]
                   if k in channels else 0.0) for k in INPUTS}
        p = {**fixed, **{n: scale[n] * leaf[f"p:{n}"] for n in free}}
        ctx = collocation_point({s: leaf[f"x:{s}"] for s in states}, {s: leaf[f"dx:{s}"] for s in states},
                                [leaf[f"beta:{b}"] for b in FLAPPING], {k: leaf[f"base:{k}"] for k in INPUTS},
                                {k: dat[f"du:{k}"] for k in INPUTS}, err, p, ops, extensions, states)
        eqs = ctx.equations + [output_equation(ctx, k, leaf[f"y:{k}"]) for k in out_names]
        rows = [lhs - rhs for lhs, rhs in eqs]
        return ca.Function("collocation_point", [z, d], [ca.vertcat(*rows)], ["z", "d"], ["r"])

    pr = PointRows(leaf_names=leaf_names, data_names=data_names, make_function=make_function)
    error_samples = list(blk.input_samples)
    ns = len(states)
    for i, t in enumerate(times):
        errs = []
        for k in channels:
            a, b, w = err_where[t]
            errs += [blk.u_err[k, error_samples[a]], blk.u_err[k, error_samples[a if b is None else b]]]
        pr.leaves.append([blk.x[s, t] for s in states] + [blk.dx[s, t] for s in states]
                         + [blk.beta[b, t] for b in FLAPPING]
                         + [blk.y[k, t] if t in samples else 0.0 for k in out_names]
                         + [getattr(start, k) for k in INPUTS] + errs + [linear[n][0] for n in free])
        pr.data_values.append([blk.du[k, t] for k in INPUTS] + [err_where[t][2] for k in channels])
        if t != t0:
            pr.rows += [(blk.ode[s, t], i, j) for j, s in enumerate(states)]
        pr.rows += [(blk.flapping[j, t], i, ns + j) for j in range(3)]
        if t in samples:
            pr.rows += [(blk.output_eq[k, t], i, ns + 3 + j) for j, k in enumerate(out_names)]
    return pr


def _input_error_terms(blk: pyo.Block, t_samples: np.ndarray, times: list, channels: tuple):
    """``blk.u_err`` (one variable per channel and input sample ``blk.input_samples``, at ``t_samples``) and a
    function (k, t) -> its value at t.

    The error at a collocation point is the linear interpolation of the errors at the two input samples
    around it, as the measured input there is the interpolation of the measured samples.
    """
    unknown = set(channels) - set(INPUTS)
    if unknown:
        raise ValueError(f"unknown input channel(s) {sorted(unknown)} for input errors; choose from {INPUTS}")
    if not channels:
        return (lambda k, t: 0.0), {}
    blk.u_err = pyo.Var(list(channels), blk.input_samples, initialize=0.0)
    samples = list(blk.input_samples)
    where = {}
    for t in times:
        i = min(int(np.searchsorted(t_samples, t, side="right")) - 1, len(samples) - 1)
        if i < 0 or abs(t - samples[i]) < 1e-12 or i == len(samples) - 1:
            where[t] = (max(i, 0), None, 1.0)
        else:
            w = (t - samples[i]) / (samples[i + 1] - samples[i])
            where[t] = (i, i + 1, 1.0 - w)

    def u_err(k, t):
        if k not in channels:
            return 0.0
        i, j, w = where[t]
        if j is None:
            return blk.u_err[k, samples[i]]
        return w * blk.u_err[k, samples[i]] + (1.0 - w) * blk.u_err[k, samples[j]]

    return u_err, where


def initialise_from(blk: pyo.Block, df, states) -> None:
    """Set variable values by interpolating a simulation DataFrame at every point of ``blk.t``; a state of the
    block that ``df`` does not hold starts at rest (:func:`_settle_missing_states`)."""
    tt = df["t"].to_numpy()
    times = list(blk.t)
    for s in states:
        if s in df:
            vals = np.interp(times, tt, df[s].to_numpy())
            for t, v in zip(times, vals):
                blk.x[s, t].set_value(float(v), skip_validation=True)
    for k in sorted({k for k, _ in blk.y.keys()}):
        if k in df:
            for t in blk.samples:
                blk.y[k, t].set_value(float(np.interp(t, tt, df[k].to_numpy())), skip_validation=True)
    for b in FLAPPING:
        if b in df:
            vals = np.interp(times, tt, df[b].to_numpy())
            for t, v in zip(times, vals):
                blk.beta[b, t].set_value(float(v), skip_validation=True)
    # derivatives from finite differences of the same interpolant
    for s in states:
        if s in df:
            d = np.gradient(df[s].to_numpy(), tt)
            for t, v in zip(times[1:], np.interp(times[1:], tt, d)):
                blk.dx[s, t].set_value(float(v), skip_validation=True)
    _settle_missing_states(blk, [s for s in dict.fromkeys(s for s, _ in blk.x.keys()) if s not in df])


def _settle_missing_states(blk: pyo.Block, states) -> None:
    """Start each of ``states`` at the block's start trim value, then at every collocation point where its own
    equation is at rest, its derivative zero (:func:`.trim_block.settle`)."""
    times = list(blk.t)
    for s in states:
        x0 = blk.x[s, times[0]]
        a, b = blk.initial[s].expr.args  # x0 == the start trim's state (Pyomo may put either side first)
        x0.set_value(pyo.value(b if a is x0 else a), skip_validation=True)
        for t in times[1:]:
            blk.dx[s, t].set_value(0.0, skip_validation=True)  # at rest: the equation's body is then its rhs
            settle(blk.x[s, t], blk.ode[s, t].body)
