"""Assembly of M0 from its parts, and the float model used by the simulator.

``evaluate`` is the one place where the physical parts are wired together.
It is called with Pyomo expressions (collocation points, trim blocks), CasADi
symbols (the compiled RK4 of simulation.compiled) or floats (simulation): see :mod:`.ops`.

States x = [u, w, q, theta, lambda_i] (+ extension states), inputs
[col, lon], algebraic flapping [beta_0, beta_1c, beta_1s], outputs
[q, theta, n_x, n_z, TAS, beta_0].
"""
from __future__ import annotations

from types import SimpleNamespace
from typing import Mapping, Sequence

import numpy as np

from ..channels import INPUTS, OUTPUTS  # noqa: F401 - re-exported: the model's vocabulary
from . import eom, fuselage, inflow, rotor, tail
from .extensions import Extension
from .ops import NUMPY
from .parameters import ParameterSet, bo105

STATES = ("u", "w", "q", "theta", "lambda_i")
FLAPPING = ("beta_0", "beta_1c", "beta_1s")
#: Intermediates that several equations of one time point use (flapping rows,
#: state rates, load factors). A back end with ``ops.share(name, expr)``
#: (the collocation blocks) gets each of them once as a named quantity, so the
#: NL file and the solver's derivative graphs hold it once instead of once per
#: equation (docs/performance.md); the other back ends use them as they are.
SHARED = ("mu", "mu_z", "lam", "c_t", "T", "X", "Z", "M")


def _share(ops, name: str, expr):
    share = getattr(ops, "share", None)
    return expr if share is None else share(name, expr)


def evaluate(x: Mapping, inputs: Mapping, p: Mapping, ops=NUMPY, beta: Sequence | None = None,
             extensions: Sequence[Extension] = ()) -> SimpleNamespace:
    """Evaluate the model once; returns a context with every intermediate.

    x: states by name (extension states included); inputs: col, lon [rad];
    p: parameter mapping (floats, Pyomo Vars or CasADi symbols).
    beta: the flapping variables (NLP form: ``ctx.flap_residuals`` must be
    zero); if None they are solved in closed form (float form).

    The returned context has ``rates`` (d/dt of every state, for extension
    states only when their coefficient is 1 - see ``state_eqs``),
    ``state_eqs`` (name -> (coef, rhs)), ``outputs`` and forces.
    """
    ctx = SimpleNamespace(x=x, p=p, ops=ops, col=inputs["col"], lon=inputs["lon"],
                          x_h=p["x_h"], l_t=p["l_t"])
    u, w, q, theta, lambda_i = (x[k] for k in STATES)
    for e in extensions:
        e.adjust_geometry(ctx)
    for e in extensions:
        e.adjust_controls(ctx)

    flow = rotor.hub_flow(u, w, q, p, ops, x_h=ctx.x_h)
    flow.mu, flow.mu_z = _share(ops, "mu", flow.mu), _share(ops, "mu_z", flow.mu_z)
    lam = _share(ops, "lam", lambda_i - flow.mu_z)
    pitch = rotor.blade_pitch(ctx.col, ctx.lon, p)
    if beta is None:
        beta = rotor.solve_flapping(flow, pitch, lam, p)
        ctx.flap_residuals = None
    else:
        ctx.flap_residuals = rotor.flapping_residuals(beta, flow, pitch, lam, p)
    ctx.flow, ctx.pitch, ctx.lam, ctx.beta = flow, pitch, lam, tuple(beta)

    # Tip-path-plane tilt that carries the thrust (quasi-steady in M0).
    ctx.beta_1c_tpp = beta[1]
    for e in extensions:
        e.tip_path_plane(ctx)

    c_t = _share(ops, "c_t", rotor.thrust_coefficient(flow, pitch, lam, p))
    disc = inflow.disc_flow(flow, lambda_i, ctx.beta_1c_tpp, ops)
    c_t_gl = inflow.glauert_thrust(lambda_i, disc, ops)
    ctx.tau_lambda = p["tau_lambda"]
    for e in extensions:
        e.adjust_inflow(ctx)
    ctx.c_t, ctx.disc, ctx.c_t_glauert = c_t, disc, c_t_gl
    dlambda = inflow.inflow_rate(c_t, c_t_gl, ctx.tau_lambda)

    T = _share(ops, "T", rotor.thrust(c_t, p))
    X_R, Z_R, M_R = rotor.rotor_forces(T, ctx.beta_1c_tpp, p, ops, x_h=ctx.x_h)
    X_F, Z_F, M_F = fuselage.fuselage_forces(u, w, p, ops)
    ctx.thrust = T
    w_dw = 0.0
    for e in extensions:
        w_dw = w_dw + e.tail_downwash(ctx)
    ctx.w_dw = w_dw
    X_T, Z_T, M_T = tail.tail_forces(u, w, q, w_dw, p, l_t=ctx.l_t)
    X, Z, M = X_R + X_F + X_T, Z_R + Z_F + Z_T, M_R + M_F + M_T
    for e in extensions:
        dX, dZ, dM = e.extra_forces(ctx)
        X, Z, M = X + dX, Z + dZ, M + dM
    X, Z, M = _share(ops, "X", X), _share(ops, "Z", Z), _share(ops, "M", M)
    ctx.forces = SimpleNamespace(X=X, Z=Z, M=M, X_R=X_R, Z_R=Z_R, M_R=M_R, X_F=X_F, Z_F=Z_F, M_F=M_F,
                                 Z_T=Z_T, M_T=M_T)

    du, dw, dq, dtheta = eom.rigid_body_rates(X, Z, M, u, w, q, theta, p, ops)
    ctx.rates = {"u": du, "w": dw, "q": dq, "theta": dtheta, "lambda_i": dlambda}
    n_x, n_z = eom.load_factors(X, Z, p)
    ctx.outputs = {"q": q, "theta": theta, "n_x": n_x, "n_z": n_z,
                   "TAS": fuselage.airspeed(u, w, p, ops), "beta_0": beta[0]}
    ctx.true_outputs = dict(ctx.outputs)  # before any sensor effect
    ctx.state_eqs = {k: (1.0, v) for k, v in ctx.rates.items()}
    for e in extensions:
        ctx.state_eqs.update(e.state_equations(ctx))
    for e in sorted(extensions, key=lambda e: getattr(e, "output_stage", 1)):  # an output's lag first, stable
        e.adjust_outputs(ctx)
    return ctx


class HelicopterModel:
    """M0 (or M0 plus extensions) with a parameter set: the float-evaluation model.

    ``parameters`` holds the base table plus every extension's parameters.
    Extensions that add states and are at zero strength are dropped from the
    float model (their state equation degenerates to an algebraic identity
    that gives M0 exactly), so the ODE right-hand side stays explicit.
    """

    def __init__(self, parameters: ParameterSet | None = None, extensions: Sequence[Extension] = ()):
        base = parameters if parameters is not None else bo105()
        params = base
        for e in extensions:
            params = params.extended(e.parameters())
        self.parameters: ParameterSet = params
        self.extensions: tuple[Extension, ...] = tuple(extensions)

    # ------------------------------------------------------------------
    def with_parameters(self, **values: float) -> "HelicopterModel":
        new = HelicopterModel.__new__(HelicopterModel)
        new.parameters = self.parameters.with_values(**values)
        new.extensions = self.extensions
        return new

    @property
    def float_extensions(self) -> tuple[Extension, ...]:
        """Extensions used by the float model (see the class docstring)."""
        keep = []
        for e in self.extensions:
            if e.states and e.strength and self.parameters[e.strength] == 0.0:
                continue
            keep.append(e)
        return tuple(keep)

    @property
    def state_names(self) -> tuple[str, ...]:
        extra = tuple(s for e in self.float_extensions for s in e.states)
        return STATES + extra

    def evaluate(self, x: Mapping, inputs: Mapping, ops=NUMPY) -> SimpleNamespace:
        return evaluate(x, inputs, self.parameters, ops=ops, extensions=self.float_extensions)

    def rates(self, x: Mapping, inputs: Mapping) -> dict:
        """d/dt of every state (extension states from coef * dx/dt = rhs)."""
        ctx = self.evaluate(x, inputs)
        return {k: rhs / coef for k, (coef, rhs) in ctx.state_eqs.items()}

    def lag_rates(self, x: Mapping, inputs: Mapping, h: float = 1e-7) -> dict:
        """|d(dx_k/dt)/dx_k| [1/s] of every extension state k at ``(x, inputs)``, by a central difference: the
        inverse time constant 1/tau of a lag state (tau dx/dt = target - x). An explicit integrator's step must
        stay below about tau; a lag of a few milliseconds makes the float model stiff."""
        out = {}
        for k in self.state_names[len(STATES):]:
            hi, lo = dict(x), dict(x)
            hi[k], lo[k] = x[k] + h, x[k] - h
            out[k] = abs(self.rates(hi, inputs)[k] - self.rates(lo, inputs)[k]) / (2 * h)
        return out

    def rhs_vector(self, xvec: np.ndarray, inputs: Mapping) -> np.ndarray:
        x = dict(zip(self.state_names, xvec))
        r = self.rates(x, inputs)
        return np.array([r[k] for k in self.state_names], dtype=float)

    def outputs(self, x: Mapping, inputs: Mapping) -> dict:
        return self.evaluate(x, inputs).outputs
