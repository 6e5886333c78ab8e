"""The model's local linear model at its own trim, inside the NLP (exact derivatives).

For a trim block ``trim`` (shared with the trim data and the maneuver starts)
:func:`build_linearization` adds

- ``x0[s]``, ``u0[i]``: the linearisation point, tied to the trim block by
  equality constraints (``tie``), so the linear model moves with the shared
  parameters and is consistent with the trim by construction;
- ``A[s, j]``, ``B[s, i]``, ``C[o, s]``, ``D[o, i]``: Pyomo expressions built
  from the symbolic derivatives (``pyomo.core.expr.calculus.derivatives.differentiate``,
  reverse symbolic mode) of the very expressions ``physics.model.evaluate``
  builds for the state rates, outputs and flapping residuals (NLP form, the
  flapping as variables ``b0``). The algebraic flapping is eliminated exactly:
  ``S = d(beta)/d(x, u)`` are variables defined by ``r_beta S + r_xu = 0``, and
  ``A = f_x + f_beta S`` etc. (The closed-form flapping would give the same
  matrices but expression trees so large that writing the NL file took 40 s.)

:func:`add_frequency_response` then defines G(j w) = C (j w I - A)^-1 B + D
at chosen frequencies through variables X = (j w I - A)^-1 B split into real
and imaginary parts and the linear equations
    -A X_re - w X_im = B,    w X_re - A X_im = 0
(no matrix inverse), and ``G_re``, ``G_im`` = C X + D as expressions. The variables are
``Xn = X / X_scale``, each state's response divided by its magnitude at the start (``X_re``,
``X_im`` are expressions of them), each row divided by its state's scale.
"""
from __future__ import annotations

import numpy as np
import pyomo.environ as pyo
from pyomo.core.expr.calculus.derivatives import Modes, differentiate

from ..physics.model import FLAPPING, INPUTS, OUTPUTS, STATES, evaluate
from ..physics.ops import get_ops


def build_linearization(blk: pyo.Block, model, pmap, trim) -> None:
    """Populate ``blk`` with the linearisation (A, B, C, D expressions) at trim block ``trim``."""
    with_states = [e.name for e in model.extensions if e.states]
    if with_states:
        raise ValueError(f"linear models: extensions with states ({', '.join(with_states)}) are not supported")
    point = {"u": trim.u, "w": trim.w, "q": 0.0, "theta": trim.theta, "lambda_i": trim.lambda_i}
    blk.x0 = pyo.Var(STATES, initialize=lambda _, s: pyo.value(point[s]))
    blk.u0 = pyo.Var(INPUTS, initialize=lambda _, i: pyo.value(getattr(trim, i)))
    blk.b0 = pyo.Var(FLAPPING, initialize=lambda _, b: pyo.value(getattr(trim, b)))
    blk.tie_x = pyo.Constraint(STATES, rule=lambda b, s: b.x0[s] == point[s])
    blk.tie_u = pyo.Constraint(INPUTS, rule=lambda b, i: b.u0[i] == getattr(trim, i))
    blk.tie_b = pyo.Constraint(FLAPPING, rule=lambda b, k: b.b0[k] == getattr(trim, k))
    ctx = evaluate({s: blk.x0[s] for s in STATES}, {i: blk.u0[i] for i in INPUTS}, pmap, ops=get_ops("pyomo"),
                   beta=[blk.b0[k] for k in FLAPPING], extensions=model.extensions)
    XU = STATES + INPUTS
    wrt = [blk.x0[s] for s in STATES] + [blk.u0[i] for i in INPUTS] + [blk.b0[k] for k in FLAPPING]

    def jac(exprs):
        return {k: (differentiate(e, wrt_list=wrt, mode=Modes.reverse_symbolic)
                    if not isinstance(e, (int, float)) else [0.0] * len(wrt)) for k, e in exprs.items()}

    # Partial derivatives of the DAE  dx/dt = f(x, u, beta), y = h(x, u, beta), 0 = r(x, u, beta)
    # as named expressions (the NL writer shares them instead of repeating the trees).
    cols = list(XU) + list(FLAPPING)
    fj = jac({s: ctx.rates[s] for s in STATES})
    hj = jac({o: ctx.outputs[o] for o in OUTPUTS})
    rj = jac(dict(zip(FLAPPING, ctx.flap_residuals)))
    blk.f_d = pyo.Expression(STATES, cols, rule=lambda _, s, c: fj[s][cols.index(c)])
    blk.h_d = pyo.Expression(OUTPUTS, cols, rule=lambda _, o, c: hj[o][cols.index(c)])
    blk.r_d = pyo.Expression(FLAPPING, cols, rule=lambda _, k, c: rj[k][cols.index(c)])
    # Exact elimination of the algebraic flapping: S = d(beta)/d(x, u) from r_beta S = -r_xu,
    # S as variables defined by these linear equations (no inverse).
    rb = np.array([[pyo.value(blk.r_d[k, c]) for c in FLAPPING] for k in FLAPPING])
    rx = np.array([[pyo.value(blk.r_d[k, c]) for c in XU] for k in FLAPPING])
    S0 = -np.linalg.solve(rb, rx)
    blk.S = pyo.Var(FLAPPING, XU, initialize=lambda _, k, c: float(S0[FLAPPING.index(k), XU.index(c)]))
    blk.flap_sens = pyo.Constraint(FLAPPING, XU, rule=lambda b, k, c: sum(b.r_d[k, j] * b.S[j, c] for j in FLAPPING)
                                   + b.r_d[k, c] == 0)

    def total(E, row, c):
        return E[row, c] + sum(E[row, k] * blk.S[k, c] for k in FLAPPING)

    blk.A = pyo.Expression(STATES, STATES, rule=lambda b, s, j: total(b.f_d, s, j))
    blk.B = pyo.Expression(STATES, INPUTS, rule=lambda b, s, i: total(b.f_d, s, i))
    blk.C = pyo.Expression(OUTPUTS, STATES, rule=lambda b, o, j: total(b.h_d, o, j))
    blk.D = pyo.Expression(OUTPUTS, INPUTS, rule=lambda b, o, i: total(b.h_d, o, i))


def matrices(blk: pyo.Block) -> dict[str, np.ndarray]:
    """Current numerical values of A, B, C, D of a linearisation block."""
    def mat(E, rows, cols):
        return np.array([[pyo.value(E[r, c]) for c in cols] for r in rows], dtype=float)

    return {"A": mat(blk.A, STATES, STATES), "B": mat(blk.B, STATES, INPUTS), "C": mat(blk.C, OUTPUTS, STATES),
            "D": mat(blk.D, OUTPUTS, INPUTS)}


def add_frequency_response(blk: pyo.Block, responses: list[tuple[str, str, np.ndarray]]) -> None:
    """G(j w) of each (output, input, omegas) in ``responses`` as NLP variables/expressions on ``blk``.

    Index of ``blk.G_re``/``blk.G_im``: (r, k) = (response number, frequency number).
    """
    points = [(r, k) for r, (_, _, w) in enumerate(responses) for k in range(len(w))]
    blk.fr_points = pyo.Set(initialize=points, dimen=2, ordered=True)
    omega = {(r, k): float(responses[r][2][k]) for r, k in points}
    inp = {r: responses[r][1] for r in range(len(responses))}
    out = {r: responses[r][0] for r in range(len(responses))}
    # initial values from the current A, B (the linear solve the constraints encode)
    M = matrices(blk)
    x0 = {}
    for r, k in points:
        x = np.linalg.solve(1j * omega[r, k] * np.eye(len(STATES)) - M["A"], M["B"][:, INPUTS.index(inp[r])])
        x0[r, k] = dict(zip(STATES, x))
    # X = sc * Xn: each state's response scaled by its magnitude at the start, so the variables are O(1)
    # (the sweep band's low frequencies give |X| up to 1e4 for u at hover, its high ones 1e-5 for lambda_i;
    # unscaled, the cold anchor A took 283 Ipopt iterations instead of 23). A magnitude below 1e-3 of the
    # point's largest is raised to that, so a state near a zero of its response keeps a sensible scale.
    sc = {}
    for r, k in points:
        mag = np.abs(np.array([x0[r, k][s] for s in STATES]))
        floor = max(1e-3 * float(mag.max()), 1e-12)
        sc.update({(r, k, s): float(max(v, floor)) for s, v in zip(STATES, mag)})
    blk.X_scale = pyo.Param(blk.fr_points, STATES, initialize=lambda _, r, k, s: sc[r, k, s])
    blk.Xn_re = pyo.Var(blk.fr_points, STATES, initialize=lambda _, r, k, s: float(x0[r, k][s].real) / sc[r, k, s])
    blk.Xn_im = pyo.Var(blk.fr_points, STATES, initialize=lambda _, r, k, s: float(x0[r, k][s].imag) / sc[r, k, s])
    blk.X_re = pyo.Expression(blk.fr_points, STATES, rule=lambda b, r, k, s: sc[r, k, s] * b.Xn_re[r, k, s])
    blk.X_im = pyo.Expression(blk.fr_points, STATES, rule=lambda b, r, k, s: sc[r, k, s] * b.Xn_im[r, k, s])

    def re_rule(b, r, k, s):  # row divided by the state's scale: O(1) coefficients on its own variable
        return (-sum(b.A[s, j] * sc[r, k, j] * b.Xn_re[r, k, j] for j in STATES)
                - omega[r, k] * sc[r, k, s] * b.Xn_im[r, k, s] - b.B[s, inp[r]]) / sc[r, k, s] == 0

    def im_rule(b, r, k, s):
        return (omega[r, k] * sc[r, k, s] * b.Xn_re[r, k, s]
                - sum(b.A[s, j] * sc[r, k, j] * b.Xn_im[r, k, j] for j in STATES)) / sc[r, k, s] == 0

    blk.fr_re = pyo.Constraint(blk.fr_points, STATES, rule=re_rule)
    blk.fr_im = pyo.Constraint(blk.fr_points, STATES, rule=im_rule)
    blk.G_re = pyo.Expression(blk.fr_points, rule=lambda b, r, k: sum(b.C[out[r], s] * sc[r, k, s] * b.Xn_re[r, k, s]
                                                                      for s in STATES) + b.D[out[r], inp[r]])
    blk.G_im = pyo.Expression(blk.fr_points, rule=lambda b, r, k: sum(b.C[out[r], s] * sc[r, k, s] * b.Xn_im[r, k, s]
                                                                      for s in STATES))


def add_linear_information(m: pyo.ConcreteModel, model, pmap, responses, speeds: list, trim_blocks) -> None:
    """Linearisations, model frequency responses and ``m.J_linear`` for the data ``responses``.

    responses: FrequencyResponse objects already restricted to their coherent band.
    speeds, trim_blocks: the NLP's trim speeds [m/s] and trim blocks; a response at a speed
    without a trim block gets its own (``m.lin_trim``), built from a float trim at the
    model's current parameters.
    """
    from ..simulation.trim import trim_float
    from .objectives import add_linear_objective, linear_terms
    from .trim_block import build_trim_block

    responses = [r for r in responses if len(r.omega)]
    if not responses:
        raise ValueError("J_linear: no frequency response has a coherent band; relax [linear] coherence_min "
                         "or input_power_min")
    lin_speeds = sorted({round(float(r.speed), 6) for r in responses})
    extra = [V for V in lin_speeds if not any(abs(V - s) < 1e-6 for s in speeds)]
    m.lin_trim = pyo.Block(range(len(extra)))
    current = model.with_parameters(**{n: pyo.value(pmap[n]) for n in m.free_parameters}) \
        if len(m.free_parameters) else model
    for j, V in enumerate(extra):
        build_trim_block(m.lin_trim[j], model, pmap, V, guess=trim_float(current, V).to_dict())

    def trim_at(V):
        for s, blk in zip(speeds, trim_blocks):
            if abs(V - s) < 1e-6:
                return blk
        return m.lin_trim[extra.index(V)]

    m.lin_speeds = pyo.Set(initialize=range(len(lin_speeds)), ordered=True)
    m.lin = pyo.Block(m.lin_speeds)
    m.lin_speed_values = list(lin_speeds)
    m.lin_responses = []  # (speed index, response index in that block, response)
    terms = []
    for i, V in enumerate(lin_speeds):
        blk = m.lin[i]
        build_linearization(blk, model, pmap, trim_at(V))
        mine = [r for r in responses if abs(round(float(r.speed), 6) - V) < 1e-6]
        add_frequency_response(blk, [(r.output, r.input, np.asarray(r.omega, float)) for r in mine])
        for k, r in enumerate(mine):
            m.lin_responses.append((i, k, r))
            terms.append([linear_terms(blk.G_re[k, j], blk.G_im[k, j], complex(r.T[j]), float(r.coherence[j]))
                          for j in range(len(r.omega))])
    add_linear_objective(m, terms)


def model_responses(m: pyo.ConcreteModel) -> list[tuple]:
    """(data response, model complex response at its bins) for every response of ``m.lin``."""
    out = []
    for i, k, r in m.lin_responses:
        blk = m.lin[i]
        G = np.array([pyo.value(blk.G_re[k, j]) + 1j * pyo.value(blk.G_im[k, j]) for j in range(len(r.omega))])
        out.append((r, G))
    return out
