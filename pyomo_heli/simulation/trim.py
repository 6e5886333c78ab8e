"""Float trim of the model (scipy root finding), with continuation in speed.

The Pyomo trim block (:mod:`pyomo_heli.nlp.trim_block`) solves the same
equations as an NLP; this float route serves the simulator and the truth
model, and is the second, independent route the tests compare against.

Level flight at true airspeed V and flight-path angle gamma_fp:
unknowns col, lon, theta, lambda_i (+ extension states), with q = 0,
u = V cos(theta - gamma_fp), w = V sin(theta - gamma_fp), and
du/dt = dw/dt = dq/dt = dlambda_i/dt = 0 (+ extension states at rest).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.optimize import root

from ..physics.model import HelicopterModel, rotor


class TrimError(RuntimeError):
    """The trim equations could not be solved."""


@dataclass
class TrimPoint:
    """A trimmed flight condition (SI, radians)."""

    V: float
    gamma_fp: float
    col: float
    lon: float
    theta: float
    lambda_i: float
    beta_0: float
    beta_1c: float
    beta_1s: float
    u: float
    w: float
    extra_states: dict = field(default_factory=dict)

    def state(self) -> dict:
        return {"u": self.u, "w": self.w, "q": 0.0, "theta": self.theta, "lambda_i": self.lambda_i,
                **self.extra_states}

    def inputs(self) -> dict:
        return {"col": self.col, "lon": self.lon}

    def to_dict(self) -> dict:
        return asdict(self)


def hover_guess(model: HelicopterModel) -> dict:
    """Closed-form hover trim (model_spec.md section 3), good start for Newton."""
    p = model.parameters
    _, sigma, _ = rotor.rotor_constants(p)
    v_tip = p["Omega"] * p["R"]
    c_t = p["m"] * p["g"] / (p["rho"] * math.pi * p["R"] ** 2 * v_tip**2)
    lam = math.sqrt(c_t / 2)
    theta_tw = p["theta_twist"] * p["R"]
    col = 6 * c_t / (p["a"] * sigma) + 1.5 * lam - 3 * theta_tw * (0.25 - p["r_ref"] / 3)
    return {"col": col, "lon": 0.0, "theta": p["gamma_s"], "lambda_i": lam}


def _unpack(model, V, gamma_fp, z):
    col, lon, theta, lam = z[:4]
    extra = dict(zip(model.state_names[5:], z[4:]))
    a = theta - gamma_fp
    x = {"u": V * math.cos(a), "w": V * math.sin(a), "q": 0.0, "theta": theta, "lambda_i": lam, **extra}
    return x, {"col": col, "lon": lon}


def trim_float(model: HelicopterModel, V: float, gamma_fp: float = 0.0, guess: dict | None = None,
               tol: float = 1e-12) -> TrimPoint:
    """Solve the trim equations with scipy's hybrid Powell method."""
    if V < 0:
        raise ValueError(f"speed must be non-negative, got {V} m/s")
    g = dict(hover_guess(model)) if guess is None else dict(guess)
    names = model.state_names
    z0 = [g["col"], g["lon"], g["theta"], g["lambda_i"]] + [g.get(n, 0.0) for n in names[5:]]

    residual = _residual(model, V, gamma_fp)
    sol = root(residual, np.array(z0, dtype=float), method="hybr", tol=tol)
    # hybr may report 'no good progress' once it sits at machine precision: judge by the residual.
    # Its own message judges only its step size ('The solution converged.' can come with equations far from
    # balanced), so the error states what failed: non-finite unknowns or the largest equation residual.
    if not np.all(np.isfinite(sol.x)):
        raise TrimError(f"trim at V = {V:.3f} m/s failed: the root finder (scipy hybr) returned non-finite "
                        f"col/lon/theta/lambda_i (its status: {sol.message.strip()})")
    res = residual(sol.x)
    if not np.all(np.isfinite(res)) or np.max(np.abs(res)) > 1e-9:
        eqs = ["du/dt", "dw/dt", "10 dq/dt", "0.1 dlambda_i/dt"] + [f"d{n}/dt" for n in names[5:]]
        k = int(np.argmax(np.where(np.isfinite(res), np.abs(res), np.inf)))
        raise TrimError(f"trim at V = {V:.3f} m/s failed: the trim equations are not satisfied at the root "
                        f"finder's end point (largest residual {eqs[k]} = {res[k]:.3g}, tolerance 1e-09; scipy "
                        f"hybr stopped with status {sol.status}: {sol.message.strip()!r}); check the model "
                        f"parameters (e.g. an implausible mass, inertia or rotor constant)")
    return _trim_point(model, V, gamma_fp, sol.x)


def _residual(model: HelicopterModel, V: float, gamma_fp: float):
    """The trim equations at ``V``, ``gamma_fp`` as a function of the unknowns z = (col, lon, theta, lambda_i,
    extension states): du/dt, dw/dt, 10 dq/dt, 0.1 dlambda_i/dt and the extension states' rates."""
    names = model.state_names

    def residual(z):
        x, u = _unpack(model, V, gamma_fp, z)
        r = model.rates(x, u)
        return np.array([r["u"], r["w"], r["q"] * 10.0, r["lambda_i"] * 0.1] + [r[n] for n in names[5:]])

    return residual


def _unknowns(tp: TrimPoint) -> np.ndarray:
    return np.array([tp.col, tp.lon, tp.theta, tp.lambda_i, *tp.extra_states.values()], dtype=float)


def _trim_point(model: HelicopterModel, V: float, gamma_fp: float, z) -> TrimPoint:
    x, u = _unpack(model, V, gamma_fp, z)
    ctx = model.evaluate(x, u)
    b0, b1c, b1s = (float(b) for b in ctx.beta)
    return TrimPoint(V=V, gamma_fp=gamma_fp, col=float(z[0]), lon=float(z[1]), theta=float(z[2]),
                     lambda_i=float(z[3]), beta_0=b0, beta_1c=b1c, beta_1s=b1s, u=x["u"], w=x["w"],
                     extra_states={n: float(v) for n, v in zip(model.state_names[5:], z[4:])})


def trim_sweep(model: HelicopterModel, speeds, gamma_fp: float = 0.0, step: float = 2.5) -> list[TrimPoint]:
    """Trim at each speed [m/s], by continuation from hover in steps of ``step`` m/s.

    Continuation matters: Newton from the hover guess can fail at high speed.
    """
    speeds = [float(v) for v in speeds]
    results: dict[float, TrimPoint] = {}
    guess = None
    v_cur = 0.0
    for target in sorted(set(speeds)):
        path = list(np.arange(v_cur, target, step)[1:]) + [target] if target > v_cur else [target]
        for v in path:
            tp = trim_float(model, v, gamma_fp, guess)
            guess = {"col": tp.col, "lon": tp.lon, "theta": tp.theta, "lambda_i": tp.lambda_i, **tp.extra_states}
        results[target] = tp
        v_cur = target
    return [results[v] for v in speeds]


def trim_jacobians(model: HelicopterModel, points: list[TrimPoint], rel_step: float = 1e-7) -> list[np.ndarray]:
    """The trim equations' Jacobian with respect to the unknowns at each of ``points`` (a trim of ``model``), by
    central differences: the fixed Jacobian of :func:`trim_near`'s Newton steps."""
    out = []
    for tp in points:
        residual, z = _residual(model, tp.V, tp.gamma_fp), _unknowns(tp)
        J = np.empty((len(z), len(z)))
        for j in range(len(z)):
            h = rel_step * max(abs(z[j]), 1e-2)
            e = np.zeros(len(z))
            e[j] = h
            J[:, j] = (residual(z + e) - residual(z - e)) / (2 * h)
        out.append(J)
    return out


#: trim_near's Newton steps: at most this many, until a step moves no unknown by more than NEAR_STEP_TOL [rad]
NEAR_MAX_STEPS, NEAR_STEP_TOL = 8, 1e-14


def trim_near(model: HelicopterModel, points: list[TrimPoint], jacobians: list[np.ndarray] | None = None
              ) -> list[TrimPoint]:
    """Trim ``model`` at the speed and flight-path angle of each of ``points``, each started from that point: the
    trims of a model next to the one that gave ``points`` (a parameter a difference step away), with no
    continuation from hover. Newton steps with the fixed Jacobian ``jacobians`` (:func:`trim_jacobians` at
    ``points``; computed here when not given), which converge in two or three steps that close to the root; where
    they do not, the point is trimmed by :func:`trim_float` from its start, then by continuation (:func:`trim_sweep`).
    A model whose states differ from the points' (an extension's lag state exists only at a non-zero time constant)
    is trimmed by continuation at every speed.
    """
    if any(tuple(tp.extra_states) != model.state_names[5:] for tp in points):
        if len({tp.gamma_fp for tp in points}) == 1:
            return trim_sweep(model, [tp.V for tp in points], points[0].gamma_fp)
        return [trim_sweep(model, [tp.V], tp.gamma_fp)[0] for tp in points]
    jacobians = trim_jacobians(model, points) if jacobians is None else jacobians
    out = []
    for tp, J in zip(points, jacobians):
        residual, z, dz = _residual(model, tp.V, tp.gamma_fp), _unknowns(tp), np.array([np.inf])
        try:
            for _ in range(NEAR_MAX_STEPS):
                dz = np.linalg.solve(J, residual(z))
                z = z - dz
                if not np.all(np.isfinite(z)) or np.max(np.abs(dz)) <= NEAR_STEP_TOL:
                    break
        except np.linalg.LinAlgError:  # a singular Jacobian: the root finder below
            dz = np.array([np.inf])
        if (np.all(np.isfinite(z)) and np.max(np.abs(dz)) <= NEAR_STEP_TOL
                and np.max(np.abs(residual(z))) <= 1e-9):
            out.append(_trim_point(model, tp.V, tp.gamma_fp, z))
            continue
        guess = {"col": tp.col, "lon": tp.lon, "theta": tp.theta, "lambda_i": tp.lambda_i, **tp.extra_states}
        try:
            out.append(trim_float(model, tp.V, tp.gamma_fp, guess))
        except TrimError:
            out.append(trim_sweep(model, [tp.V], tp.gamma_fp)[0])
    return out
