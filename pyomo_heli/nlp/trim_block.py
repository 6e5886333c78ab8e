"""A trim point as an algebraic block of the NLP (model_spec.md section 3).

Unknowns: col, lon, theta, lambda_i, beta_0, beta_1c, beta_1s (+ extension
states). Fixed: q = 0, u = V cos(theta - gamma_fp), w = V sin(theta - gamma_fp).
Equations: du/dt = dw/dt = dq/dt = 0, the inflow and extension state
equations at rest, and the three flapping equations.

The speed enters through a variable ``V`` pinned by ``V_spec: V == V_target``
with ``V_target`` a mutable Param: changing it moves only a constraint bound,
so a solver adapter can re-solve (continuation in speed) without rebuilding.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import pyomo.environ as pyo

from ..physics.model import FLAPPING, HelicopterModel, evaluate
from ..physics.ops import get_ops

#: bounds that keep the NLP in the model's valid region (model_spec.md 1.13)
STATE_BOUNDS = {"lambda_i": (0.002, 0.2), "theta": (-0.6, 0.6), "beta_1c": (-0.3, 0.3),
                "col": (-0.2, 0.5), "lon": (-0.4, 0.4)}


def build_trim_block(blk: pyo.Block, model: HelicopterModel, pmap, V: float, gamma_fp: float = 0.0,
                     guess: dict | None = None) -> SimpleNamespace:
    """Populate ``blk`` with the trim equations at airspeed V [m/s]; returns the context."""
    ops = get_ops("pyomo")
    g = guess or {}
    blk.V_target = pyo.Param(initialize=float(V), mutable=True)
    blk.gamma_fp = pyo.Param(initialize=float(gamma_fp), mutable=True)
    blk.V = pyo.Var(initialize=float(V), bounds=(0.0, 100.0))
    blk.V_spec = pyo.Constraint(expr=blk.V == blk.V_target)

    def var(name, init):
        v = pyo.Var(initialize=init, bounds=STATE_BOUNDS.get(name))
        blk.add_component(name, v)
        return v

    col = var("col", g.get("col", 0.15))
    lon = var("lon", g.get("lon", 0.0))
    theta = var("theta", g.get("theta", 0.05))
    lam = var("lambda_i", g.get("lambda_i", 0.05))
    beta = [var(b, g.get(b, 0.0)) for b in FLAPPING]
    extra = {s: var(s, g.get(s, 0.0)) for e in model.extensions for s in e.states}
    a = theta - blk.gamma_fp
    x = {"u": blk.V * ops.cos(a), "w": blk.V * ops.sin(a), "q": 0.0, "theta": theta, "lambda_i": lam, **extra}
    ctx = evaluate(x, {"col": col, "lon": lon}, pmap, ops=ops, beta=beta, extensions=model.extensions)
    rest = [k for k in ctx.state_eqs if k != "theta"]  # dtheta/dt = q = 0 holds by construction
    blk.equilibrium = pyo.Constraint(rest, rule=lambda _, k: ctx.state_eqs[k][1] == 0)
    for s, v in extra.items():
        if s not in g:
            settle(v, ctx.state_eqs[s][1])
    blk.flapping = pyo.Constraint(range(3), rule=lambda _, i: ctx.flap_residuals[i] == 0)
    blk.outputs = pyo.Expression(list(ctx.outputs), rule=lambda _, k: ctx.outputs[k])
    blk.u = pyo.Expression(expr=x["u"])
    blk.w = pyo.Expression(expr=x["w"])
    return ctx


def trim_block_values(blk: pyo.Block) -> dict:
    """The solved trim as floats (SI, radians)."""
    out = {k: pyo.value(getattr(blk, k)) for k in ("V", "col", "lon", "theta", "lambda_i") + FLAPPING}
    out["u"], out["w"] = pyo.value(blk.u), pyo.value(blk.w)
    return out


def settle(var, rhs) -> None:
    """Start ``var`` where ``rhs``, the right side of its own state equation (linear in it), is zero.

    For an extension state the float start does not hold: a delay term's lag state at c = 0, which the float
    model leaves out (it adds the state only when c is not zero); it then starts at what it follows.
    ``rhs`` is evaluated at var = 0 and 1; var is left at 0 when it does not move the equation.
    """
    def at(x):
        var.set_value(x, skip_validation=True)
        r = pyo.value(rhs, exception=False)
        return float(r) if r is not None else math.nan

    r0, r1 = at(0.0), at(1.0)
    x = -r0 / (r1 - r0) if math.isfinite(r0) and math.isfinite(r1) and r1 != r0 else 0.0
    lo, hi = var.bounds
    var.set_value(min(max(x, lo if lo is not None else x), hi if hi is not None else x), skip_validation=True)
