"""Output sensitivities of the float model to its parameters, by central differences.

One route shared by everything that needs d(output)/d(parameter) at an
estimate: the Cramer-Rao bounds and identifiability analysis (Fisher
information = S^T R^-1 S) and the residual diagnosis (score test of a
candidate effect, sensitivities projected off the identified parameters).

The model is the output-error model of the identification: each maneuver
starts from the model's own trim at the maneuver's start speed and is driven
by the measured input increments; a trim point is the model's trim at the
measured speed. Derivatives are central differences of the RK4 simulation
(the same integrator, sub-steps and trims as the single-shooting fit; evaluated
by casadi, :mod:`.compiled`), with a
step relative to the parameter's magnitude or, at zero, to its declared scale;
at a lower bound (a strength or time constant at zero) the difference is
one-sided. A state-adding effect with a tiny time constant is stiff for RK4:
such candidates need a step large enough for the integrator (or a
zero-strength form whose derivative is explicit).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..physics.model import HelicopterModel
from .replay import maneuver_outputs
from .trim import trim_jacobians, trim_near, trim_sweep


def trim_outputs(model: HelicopterModel, speeds, outputs, near: tuple | None = None) -> dict[str, np.ndarray]:
    """Model trim values (col, lon, theta, ... in rad) at each speed [m/s], in the order given: by continuation
    from hover, or with ``near`` = (trim points at those speeds of a model next to this one, their Jacobians) each
    from its point (:func:`~.trim.trim_near`)."""
    speeds = [float(v) for v in speeds]
    if not speeds:
        return {o: np.zeros(0) for o in outputs}
    tps = trim_near(model, *near) if near is not None else trim_sweep(model, speeds)
    return {o: np.array([getattr(tp, o) for tp in tps]) for o in outputs}


def parameter_steps(model: HelicopterModel, names, rel_step: float = 1e-5) -> np.ndarray:
    """Difference step per parameter: rel_step times its magnitude, or times its scale when the magnitude is below a
    tenth of the scale (zero, or an effect's strength estimated near zero, whose own magnitude would give a step of
    rounding size)."""
    h = []
    for n in names:
        v = model.parameters[n]
        spec = model.parameters.spec(n)
        scale = abs(spec.scale or 0.0)
        ref = abs(v) if abs(v) >= 0.1 * scale and v != 0 else (scale or 1.0)
        h.append(rel_step * ref)
    return np.array(h)


@dataclass
class Sensitivities:
    """d(output)/d(parameter) at ``values``.

    time: output -> (N samples, n parameters), maneuvers concatenated in the
    order given; trim: trim output -> (M trims, n parameters). y_time / y_trim
    are the nominal outputs (SI, radians).
    """

    names: list[str]
    values: dict
    time: dict = field(default_factory=dict)
    trim: dict = field(default_factory=dict)
    y_time: dict = field(default_factory=dict)
    y_trim: dict = field(default_factory=dict)

    def stacked_time(self, outputs=None) -> np.ndarray:
        outputs = list(outputs or self.time)
        return np.vstack([self.time[o] for o in outputs]) if outputs else np.zeros((0, len(self.names)))

    def stacked_trim(self, outputs=None) -> np.ndarray:
        outputs = list(outputs or self.trim)
        return np.vstack([self.trim[o] for o in outputs]) if outputs else np.zeros((0, len(self.names)))


def sensitivities(model: HelicopterModel, names, maneuvers=(), time_outputs=(), trim_speeds=(), trim_out=(),
                  rel_step: float = 1e-5, substeps: int = 4) -> Sensitivities:
    """Central-difference sensitivities of maneuver and trim outputs at the model's parameter values.

    ``model`` carries the values (``model.with_parameters(...)`` first);
    ``names`` may include extension strengths (declared by the model's
    extensions). Costs 2 n simulations of every maneuver and 2 n trims at each speed (each started from the
    nominal trim there, :func:`~.trim.trim_near`).
    """
    names = list(names)
    model.parameters.check_names(names)
    h = parameter_steps(model, names, rel_step)
    time_outputs, trim_out = list(time_outputs), list(trim_out)
    speeds = list(trim_speeds)

    # the nominal trims; a model a difference step away is trimmed from them (no continuation from hover)
    trims = trim_sweep(model, [float(v) for v in speeds]) if (speeds and trim_out) else []
    near = (trims, trim_jacobians(model, trims)) if trims else None

    def run(mdl):
        yt = maneuver_outputs(mdl, maneuvers, time_outputs, substeps) if (maneuvers and time_outputs) else {}
        yr = trim_outputs(mdl, speeds, trim_out, near=near) if near else {}
        return yt, yr

    y_time = maneuver_outputs(model, maneuvers, time_outputs, substeps) if (maneuvers and time_outputs) else {}
    y_trim = {o: np.array([getattr(tp, o) for tp in trims]) for o in trim_out} if trims else {}
    S_time = {o: np.zeros((len(y_time[o]), len(names))) for o in y_time}
    S_trim = {o: np.zeros((len(y_trim[o]), len(names))) for o in y_trim}
    for j, n in enumerate(names):
        v = model.parameters[n]
        bounds = model.parameters.spec(n).bounds
        if bounds is not None and v - h[j] < bounds[0]:
            # at (or next to) the lower bound, e.g. a strength or time constant at zero, where the
            # model below the bound is not defined: second-order one-sided difference
            t1, r1 = run(model.with_parameters(**{n: v + h[j]}))
            t2, r2 = run(model.with_parameters(**{n: v + 2 * h[j]}))
            for o in S_time:
                S_time[o][:, j] = (-3 * y_time[o] + 4 * t1[o] - t2[o]) / (2 * h[j])
            for o in S_trim:
                S_trim[o][:, j] = (-3 * y_trim[o] + 4 * r1[o] - r2[o]) / (2 * h[j])
            continue
        plus_t, plus_r = run(model.with_parameters(**{n: v + h[j]}))
        minus_t, minus_r = run(model.with_parameters(**{n: v - h[j]}))
        for o in S_time:
            S_time[o][:, j] = (plus_t[o] - minus_t[o]) / (2 * h[j])
        for o in S_trim:
            S_trim[o][:, j] = (plus_r[o] - minus_r[o]) / (2 * h[j])
    return Sensitivities(names=names, values={n: model.parameters[n] for n in names}, time=S_time, trim=S_trim,
                         y_time=y_time, y_trim=y_trim)
