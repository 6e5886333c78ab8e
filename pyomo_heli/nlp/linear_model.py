"""The model's local linear model at its own trim, inside the NLP (exact derivatives).

For a trim block ``trim`` (shared with the trim data and the maneuver starts)
:func:`build_linearization` adds

- ``x0[s]``, ``u0[i]``: the linearisation point, tied to the trim block by
  equality constraints (``tie``), so the linear model moves with the shared
  parameters and is consistent with the trim by construction;
- ``A[s, j]``, ``B[s, i]``, ``C[o, s]``, ``D[o, i]``: Pyomo expressions, the
  symbolic derivatives (``pyomo.core.expr.calculus.derivatives.differentiate``,
  reverse symbolic mode) of the very expressions ``physics.model.evaluate``
  builds for the state rates and outputs. The flapping is taken in its
  closed form here (``beta=None``), which is the exact elimination of the
  three algebraic flapping equations: d(beta)/d(x) = -(dg/dbeta)^-1 dg/dx.

:func:`add_frequency_response` then defines G(j w) = C (j w I - A)^-1 B + D
at chosen frequencies through variables X = (j w I - A)^-1 B split into real
and imaginary parts and the linear equations
    -A X_re - w X_im = B,    w X_re - A X_im = 0
(no matrix inverse), and ``G_re``, ``G_im`` = C X + D as expressions.
"""
from __future__ import annotations

import numpy as np
import pyomo.environ as pyo
from pyomo.core.expr.calculus.derivatives import Modes, differentiate

from ..physics.model import INPUTS, OUTPUTS, STATES, evaluate
from ..physics.ops import get_ops


def build_linearization(blk: pyo.Block, model, pmap, trim) -> None:
    """Populate ``blk`` with the linearisation (A, B, C, D expressions) at trim block ``trim``."""
    with_states = [e.name for e in model.extensions if e.states]
    if with_states:
        raise ValueError(f"linear models: extensions with states ({', '.join(with_states)}) are not supported")
    point = {"u": trim.u, "w": trim.w, "q": 0.0, "theta": trim.theta, "lambda_i": trim.lambda_i}
    blk.x0 = pyo.Var(STATES, initialize=lambda _, s: pyo.value(point[s]))
    blk.u0 = pyo.Var(INPUTS, initialize=lambda _, i: pyo.value(getattr(trim, i)))
    blk.tie_x = pyo.Constraint(STATES, rule=lambda b, s: b.x0[s] == point[s])
    blk.tie_u = pyo.Constraint(INPUTS, rule=lambda b, i: b.u0[i] == getattr(trim, i))
    ctx = evaluate({s: blk.x0[s] for s in STATES}, {i: blk.u0[i] for i in INPUTS}, pmap, ops=get_ops("pyomo"),
                   beta=None, extensions=model.extensions)
    wrt = [blk.x0[s] for s in STATES] + [blk.u0[i] for i in INPUTS]
    n = len(STATES)

    def jac(exprs):
        rows = {}
        for k, e in exprs.items():
            d = differentiate(e, wrt_list=wrt, mode=Modes.reverse_symbolic) if not isinstance(e, (int, float)) \
                else [0.0] * len(wrt)
            rows[k] = d
        return rows

    fx = jac({s: ctx.rates[s] for s in STATES})
    gx = jac({o: ctx.outputs[o] for o in OUTPUTS})
    blk.A = pyo.Expression(STATES, STATES, rule=lambda _, s, j: fx[s][STATES.index(j)])
    blk.B = pyo.Expression(STATES, INPUTS, rule=lambda _, s, i: fx[s][n + INPUTS.index(i)])
    blk.C = pyo.Expression(OUTPUTS, STATES, rule=lambda _, o, j: gx[o][STATES.index(j)])
    blk.D = pyo.Expression(OUTPUTS, INPUTS, rule=lambda _, o, i: gx[o][n + INPUTS.index(i)])


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
    blk.X_re = pyo.Var(blk.fr_points, STATES, initialize=lambda _, r, k, s: float(x0[r, k][s].real))
    blk.X_im = pyo.Var(blk.fr_points, STATES, initialize=lambda _, r, k, s: float(x0[r, k][s].imag))

    def re_rule(b, r, k, s):
        return (-sum(b.A[s, j] * b.X_re[r, k, j] for j in STATES) - omega[r, k] * b.X_im[r, k, s]
                == b.B[s, inp[r]])

    def im_rule(b, r, k, s):
        return omega[r, k] * b.X_re[r, k, s] - sum(b.A[s, j] * b.X_im[r, k, j] for j in STATES) == 0

    blk.fr_re = pyo.Constraint(blk.fr_points, STATES, rule=re_rule)
    blk.fr_im = pyo.Constraint(blk.fr_points, STATES, rule=im_rule)
    blk.G_re = pyo.Expression(blk.fr_points, rule=lambda b, r, k: sum(b.C[out[r], s] * b.X_re[r, k, s] for s in STATES)
                              + b.D[out[r], inp[r]])
    blk.G_im = pyo.Expression(blk.fr_points, rule=lambda b, r, k: sum(b.C[out[r], s] * b.X_im[r, k, s] for s in STATES))
