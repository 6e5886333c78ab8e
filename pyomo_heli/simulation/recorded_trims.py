"""The model's trims as a flight test records them: the float trims (scipy, continuation over speed) taken
to the recorded conventions (:func:`pyomo_heli.physics.conventions.recorded_trim`: collective station,
cyclic sign, pitch-attitude datum), and their derivatives with respect to the model's parameters."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..physics.conventions import recorded_trim
from ..physics.model import HelicopterModel
from .trim import trim_sweep

#: relative central-difference step of the float Jacobian (of max(|value|, scale))
JAC_STEP = 1e-5


def predict(model: HelicopterModel, conventions, V, channels) -> np.ndarray:
    """Recorded trim value [rad] of ``channels[i]`` at speed ``V[i]`` [m/s] (float trims, continuation)."""
    V = np.asarray(V, dtype=float)
    speeds = sorted(set(V.tolist()))
    tps = dict(zip(speeds, trim_sweep(model, speeds)))
    p = model.parameters
    rec = {v: recorded_trim(tp.col, tp.lon, tp.theta, p, conventions) for v, tp in tps.items()}
    return np.array([rec[v][c] for v, c in zip(V, channels)], dtype=float)


def parameter_step(model: HelicopterModel, name: str) -> tuple[float, float]:
    """The two values of parameter ``name`` a central difference takes: its value -+ :data:`JAC_STEP` x max(|value|,
    scale), the value itself on a side that would cross a bound (one-sided there)."""
    spec = model.parameters.spec(name)
    v = model.parameters[name]
    h = JAC_STEP * max(abs(v), spec.scale or 1.0)
    lo, hi = spec.bounds or (-np.inf, np.inf)
    return (v if v - h < lo else v - h), (v if v + h > hi else v + h)


def jacobian(model: HelicopterModel, conventions, pts: pd.DataFrame, names) -> np.ndarray:
    """d(recorded trims)/d(parameter) [rad per SI unit], central differences of the float trims."""
    cols = []
    for n in names:
        a, b = parameter_step(model, n)
        ya = predict(model.with_parameters(**{n: a}), conventions, pts["V"], pts["channel"])
        yb = predict(model.with_parameters(**{n: b}), conventions, pts["V"], pts["channel"])
        cols.append((yb - ya) / (b - a))
    return np.array(cols).T if cols else np.zeros((len(pts), 0))

