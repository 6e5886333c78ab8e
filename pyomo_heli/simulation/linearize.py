"""Local linear model of the float simulator at a trim point, by central differences.

This is the independent route: it perturbs the explicit ODE right-hand side
(``HelicopterModel.rhs_vector``, flapping solved in closed form) and the
outputs around the float trim (``trim_float``), one state or input at a time.
The NLP builds its linearisation by symbolic differentiation of the Pyomo
expressions instead (:mod:`pyomo_heli.nlp.linear_model`); the tests compare
the two.

    dx/dt = A dx + B du,   dy = C dx + D du
    x = (u, w, q, theta, lambda_i), u = (col, lon), y = model outputs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..physics.model import INPUTS, OUTPUTS, HelicopterModel
from .trim import TrimPoint, trim_float

#: perturbation sizes (SI) per state/input: about 1e-6 of the natural scale of each
#: (central differences: truncation ~ h^2, rounding ~ 1e-16/h; both far below 1e-5)
FD_STEPS = {"u": 1e-4, "w": 1e-4, "q": 1e-6, "theta": 1e-6, "lambda_i": 1e-8, "col": 1e-6, "lon": 1e-6}


@dataclass
class LinearModel:
    """A, B, C, D (SI, radians) of the model at one trim point."""

    V: float
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    states: tuple
    inputs: tuple = INPUTS
    outputs: tuple = OUTPUTS
    trim: dict = field(default_factory=dict)

    def poles(self) -> np.ndarray:
        """Eigenvalues of A, sorted by real part then imaginary part [1/s]."""
        ev = np.linalg.eigvals(self.A)
        return ev[np.lexsort((ev.imag, ev.real))]

    def frequency_response(self, output: str, input: str, omega) -> np.ndarray:
        """G(j w) = C (j w I - A)^-1 B + D for one output/input pair (complex, SI per SI)."""
        o, i = self.outputs.index(output), self.inputs.index(input)
        n = len(self.states)
        out = []
        for w in np.atleast_1d(omega):
            x = np.linalg.solve(1j * w * np.eye(n) - self.A, self.B[:, i])
            out.append(self.C[o] @ x + self.D[o, i])
        return np.array(out)


def linearize_float(model: HelicopterModel, V: float, trim: TrimPoint | None = None,
                    steps: dict | None = None) -> LinearModel:
    """Central-difference linearisation of the float model at its own trim at airspeed V [m/s] (``trim``: that
    trim, already solved; a trim at another speed is refused, as it would label its model with V)."""
    if trim is not None and not math.isclose(trim.V, V, rel_tol=1e-9, abs_tol=1e-9):
        raise ValueError(f"linearize_float: the trim given is at V = {trim.V:g} m/s, not at V = {V:g} m/s")
    tp = trim if trim is not None else trim_float(model, V)
    h = dict(FD_STEPS, **(steps or {}))
    names = model.state_names
    x0 = np.array([tp.state()[k] for k in names], dtype=float)
    u0 = tp.inputs()

    def f(xv, uv):
        x = dict(zip(names, xv))
        y = model.outputs(x, uv)
        return model.rhs_vector(xv, uv), np.array([y[o] for o in OUTPUTS], dtype=float)

    n, m, p = len(names), len(INPUTS), len(OUTPUTS)
    A, C = np.zeros((n, n)), np.zeros((p, n))
    B, D = np.zeros((n, m)), np.zeros((p, m))
    for j, s in enumerate(names):
        d = np.zeros(n)
        d[j] = h.get(s, 1e-6)
        (fp, yp), (fm, ym) = f(x0 + d, u0), f(x0 - d, u0)
        A[:, j], C[:, j] = (fp - fm) / (2 * d[j]), (yp - ym) / (2 * d[j])
    for j, k in enumerate(INPUTS):
        up, um = dict(u0), dict(u0)
        up[k] += h[k]
        um[k] -= h[k]
        (fp, yp), (fm, ym) = f(x0, up), f(x0, um)
        B[:, j], D[:, j] = (fp - fm) / (2 * h[k]), (yp - ym) / (2 * h[k])
    return LinearModel(V=float(V), A=A, B=B, C=C, D=D, states=tuple(names), trim=tp.to_dict())
