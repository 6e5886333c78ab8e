"""Cramer-Rao standard errors and correlations of an estimate.

The information of each objective comes from the output sensitivities of
:mod:`pyomo_heli.simulation.sensitivity` at the estimate, with every residual
covariance *as estimated* from the residuals there:

- J_time (output-error ML, paper Eqs. 5-6): Fisher information
  ``F_time = sum_o S_o^T S_o / R_o`` with ``R_o = mean(e_o^2) + r_floor_o^2``,
  the same diagonal R the NLP estimates (nlp/objectives.py). It is also the
  Gauss-Newton Hessian of J_time, and the covariance of its gradient.
- J_trim (paper Eq. 7, mean square in degrees): the trim residual covariance
  ``Sigma_o = mean(r_o^2)`` per trim output; Fisher information
  ``F_trim = sum_o S_o^T S_o / Sigma_o``.

A front point of the epsilon-constraint method minimises J_time subject to
J_trim <= eps; by its KKT conditions it is a stationary point of the weighted
sum ``a J_time + b J_trim`` (b/a = the constraint multiplier). Its covariance
is the sandwich (M-estimator) covariance of that weighted sum,

    cov = H^-1 G H^-1,   H = a F_time + b H_trim,   G = a^2 F_time + b^2 G_trim,

with ``H_trim`` the Gauss-Newton Hessian of J_trim and ``G_trim`` the
covariance of its gradient under the estimated trim noise. The weights (a, b)
of an epsilon point are its solve's: b/a = -dJ_time/dJ_trim from the J_trim bound's multiplier (front.csv
``multiplier_trim``). Without one (a parameter set from elsewhere, a front.csv written before the column) they
are found from the two gradients at the point (``a g_time + b g_trim = 0``; b/a is the least-squares multiplier in
the metric of the inverse information, so no parameter's nominal scale enters); on the small Case 1 front the two
agree to 1e-5 (tests/test_identification.py). Point A has (1, 0) (pure ML: cov = F_time^-1), the trim anchor B the
limit b >> a, an interior point its own ratio. A point whose
Newton step towards one objective's optimum is below ``STATIONARY_SE``
standard errors counts as that objective's optimum (weights (1, 0) or
(0, 1)): on a degenerate front (noise-free data, every point the same
estimate) both gradients are rounding noise and their directions would pick
arbitrary weights.

With errors in variables (``[objectives] input_errors``) the NLP also estimates one error per
measured input sample, with known noise sigmas for outputs and inputs (nlp/objectives.py). The
time-domain information is then the information of the parameters *and* those errors with the
errors eliminated (Schur complement, per maneuver, with exact input sensitivities from
:func:`pyomo_heli.simulation.compiled.input_sensitivities`):

    F_time = F_tt - sum_m F_te,m F_ee,m^-1 F_et,m,   F_ee,m = S_e,m^T W S_e,m + Sigma_u^-1,

W = diag(1 / sigma_o^2); the gradient is that of J_time with the errors profiled out (Gauss-Newton).
Without the elimination the bounds would treat the noisy inputs as exact and come out several times
too small for a parameter the input noise hides (docs/uncertainty.md).

Parameters at an active bound are reported as such and projected out: their
rows and columns are removed before the inversion (they are treated as known),
so they get no standard error instead of a meaningless one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.linalg import cho_factor, cho_solve

from ..nlp.objectives import R_FLOOR, ar_precision, input_error_models, noise_sigmas
from ..simulation.compiled import input_sensitivities
from ..simulation.sensitivity import sensitivities
from ..simulation.trim import trim_float
from ..units import DEG

#: a parameter counts as at a bound when it is this many scales (or less) from it
BOUND_TOL = 1e-4
#: ... or when it is this many scales (or less) from it and the Newton step of the objective the point is stationary
#: for goes past it (the interior-point solver stops about mu / z inside an active bound, which can exceed
#: BOUND_TOL when the bound's multiplier z is small)
NEAR_BOUND_TOL = 1e-2
#: trim residual variance floor [rad^2], so noise-free data give huge, finite information
TRIM_FLOOR = (1e-6) ** 2
#: an epsilon point whose Newton step towards one objective's optimum is below this many standard
#: errors is that objective's optimum (objective_weights)
STATIONARY_SE = 1e-3


def active_bounds(values: dict, free, tol: float = BOUND_TOL, step: dict | None = None) -> dict:
    """name -> "lower", "upper" or "" for each free parameter (FreeParameter list): within ``tol`` scales of
    the bound, or, with ``step`` (name -> the unconstrained Newton step [SI] of the objective), within
    NEAR_BOUND_TOL scales and the step goes past the bound (the objective pushes against it)."""
    out = {}
    for f in free:
        v, d = values[f.name], (step or {}).get(f.name, 0.0)
        near = NEAR_BOUND_TOL * f.scale
        if v - f.lower <= tol * f.scale or (v - f.lower <= near and v + d < f.lower):
            out[f.name] = "lower"
        elif f.upper - v <= tol * f.scale or (f.upper - v <= near and v + d > f.upper):
            out[f.name] = "upper"
        else:
            out[f.name] = ""
    return out


def _bounds_held(info: "PointInformation", free, kind: str, multiplier: float | None, weights) -> dict:
    """:func:`active_bounds` at ``info``'s estimate, the near-bound test made with the Gauss-Newton step of the
    weighted objective the point is stationary for (over the parameters not at a bound; repeated until no
    parameter is added)."""
    names = info.names
    bounds = active_bounds(info.values, free)
    for _ in range(len(names)):
        idx = [i for i, n in enumerate(names) if not bounds[n]]
        if not idx:
            break
        a, b = weights if weights is not None else objective_weights(info, kind, idx, multiplier)
        H = a * info.fisher_time()[np.ix_(idx, idx)] + b * info.hessian_trim()[np.ix_(idx, idx)]
        g = a * info.grad_time()[idx] + b * info.grad_trim()[idx]
        d = -_pseudo_inverse(H) @ g
        new = active_bounds(info.values, free, step={names[i]: float(d[k]) for k, i in enumerate(idx)})
        new = {n: bounds[n] or new[n] for n in names}
        if new == bounds:
            break
        bounds = new
    return bounds


@dataclass
class PointInformation:
    """Sensitivities, residuals and residual covariances at one estimate (SI units).

    S_time[o]: (N, n) output sensitivities of time output o (maneuvers
    concatenated); e_time[o]: measured minus model; R_time[o]: its estimated
    variance. The same with ``trim`` for the trim outputs (M trim points).
    """

    names: list
    values: dict
    scale: np.ndarray
    S_time: dict = field(default_factory=dict)
    e_time: dict = field(default_factory=dict)
    R_time: dict = field(default_factory=dict)
    S_trim: dict = field(default_factory=dict)
    e_trim: dict = field(default_factory=dict)
    R_trim: dict = field(default_factory=dict)
    #: errors in variables: per maneuver ((first row, end row) in the concatenated time outputs,
    #: output -> (rows, channels x samples) input sensitivities); empty for output error
    S_input: list = field(default_factory=list)
    #: noise sigma [SI] of each input channel whose errors are estimated (order of S_input's columns)
    input_sigma: dict = field(default_factory=dict)
    #: the input errors' AR models, channel -> (coefficients, innovation over noise sigma); {}: independent errors
    input_models: dict = field(default_factory=dict)

    @property
    def n_trims(self) -> int:
        return len(next(iter(self.e_trim.values()))) if self.e_trim else 0

    def _input_elimination(self) -> tuple[np.ndarray, np.ndarray]:
        """(sum_m F_te F_ee^-1 F_et, sum_m F_te F_ee^-1 b_e): what eliminating the input errors takes
        from the information and adds to the gradient (module docstring); zeros for output error."""
        n = len(self.names)
        info, grad = np.zeros((n, n)), np.zeros(n)
        for (a, b), S_e in self.S_input:
            n_e = next(iter(S_e.values())).shape[1]
            per = n_e // len(self.input_sigma)
            F_ee = np.zeros((n_e, n_e))  # the errors' prior information (the inverse of their covariance)
            for i, (c, s) in enumerate(self.input_sigma.items()):
                blk = slice(i * per, (i + 1) * per)
                if c in self.input_models:
                    coef, ratio = self.input_models[c]
                    F_ee[blk, blk] = ar_precision(per, coef, s * ratio)
                else:
                    F_ee[blk, blk] = np.eye(per) / s**2
            F_te, b_e = np.zeros((n, n_e)), np.zeros(n_e)
            for o, Se in S_e.items():
                w = 1.0 / self.R_time[o]
                F_ee += w * Se.T @ Se
                F_te += w * self.S_time[o][a:b].T @ Se
                b_e += w * Se.T @ self.e_time[o][a:b]
            c, low = cho_factor(F_ee)
            info += F_te @ cho_solve((c, low), F_te.T)
            grad += F_te @ cho_solve((c, low), b_e)
        return info, grad

    def fisher_time(self) -> np.ndarray:
        n = len(self.names)
        F = sum((S.T @ S / self.R_time[o] for o, S in self.S_time.items()), np.zeros((n, n)))
        return F - self._input_elimination()[0] if self.S_input else F

    def fisher_trim(self) -> np.ndarray:
        n = len(self.names)
        return sum((S.T @ S / self.R_trim[o] for o, S in self.S_trim.items()), np.zeros((n, n)))

    def grad_time(self) -> np.ndarray:
        """Gradient of J_time (concentrated, R at its estimate)."""
        n = len(self.names)
        g = sum((-S.T @ self.e_time[o] / self.R_time[o] for o, S in self.S_time.items()), np.zeros(n))
        return g + self._input_elimination()[1] if self.S_input else g

    def grad_trim(self) -> np.ndarray:
        """Gradient of J_trim = (1/M) sum (r/DEG)^2."""
        n, M = len(self.names), max(self.n_trims, 1)
        return sum((-2.0 / (M * DEG**2) * S.T @ self.e_trim[o] for o, S in self.S_trim.items()), np.zeros(n))

    def hessian_trim(self) -> np.ndarray:
        """Gauss-Newton Hessian of J_trim."""
        n, M = len(self.names), max(self.n_trims, 1)
        return sum((2.0 / (M * DEG**2) * S.T @ S for S in self.S_trim.values()), np.zeros((n, n)))

    def gradient_covariance_trim(self) -> np.ndarray:
        """Covariance of J_trim's gradient when trim output o has noise variance R_trim[o]."""
        n, M = len(self.names), max(self.n_trims, 1)
        c = (2.0 / (M * DEG**2)) ** 2
        return sum((c * self.R_trim[o] * S.T @ S for o, S in self.S_trim.items()), np.zeros((n, n)))

    def scaled_time(self) -> np.ndarray:
        """Noise-normalised sensitivities of the time outputs, per unit of each parameter's scale."""
        if self.S_input:
            # a square root of the (input-error-eliminated) information: same singular values and
            # directions as the information itself
            w, V = np.linalg.eigh(self.scale[:, None] * self.fisher_time() * self.scale[None, :])
            return np.sqrt(np.clip(w, 0.0, None))[:, None] * V.T
        rows = [S / math.sqrt(self.R_time[o]) for o, S in self.S_time.items()]
        return (np.vstack(rows) if rows else np.zeros((0, len(self.names)))) * self.scale

    def scaled_trim(self) -> np.ndarray:
        rows = [S / math.sqrt(self.R_trim[o]) for o, S in self.S_trim.items()]
        return (np.vstack(rows) if rows else np.zeros((0, len(self.names)))) * self.scale


def point_information(model, free, values: dict, maneuvers, trims, time_outputs, trim_outputs,
                      rel_step: float = 1e-5, input_errors=(), noise_sigma: dict | None = None,
                      input_error_ar: int = 0) -> PointInformation:
    """Sensitivities and estimated residual covariances at ``values`` (free parameter values, SI).

    maneuvers: dataset Maneuver objects (as in the NLP: resampled, cropped);
    trims: DataFrame with V and the trim outputs (or None).
    input_errors, noise_sigma: the NLP's errors-in-variables settings (``NLPOptions``); with input
    errors the time outputs get the known noise sigmas of the NLP (given, or from the records'
    lead-in as the NLP takes them) instead of the residuals' variance, and the input errors are
    eliminated from the information (module docstring); ``input_error_ar``: their prior is the NLP's AR model of
    that order (fitted to the maneuvers' lead-ins at their samples), not independent errors.
    """
    names = [f.name for f in free]
    mdl = model.with_parameters(**{n: float(values[n]) for n in names})
    time_outputs, trim_outputs = list(time_outputs), list(trim_outputs)
    has_trims = trims is not None and len(trims) and trim_outputs
    s = sensitivities(mdl, names, maneuvers=list(maneuvers), time_outputs=time_outputs,
                      trim_speeds=list(trims["V"]) if has_trims else [], trim_out=trim_outputs if has_trims else [],
                      rel_step=rel_step)
    info = PointInformation(names=names, values={n: float(values[n]) for n in names},
                            scale=np.array([f.scale for f in free]))
    input_errors = tuple(input_errors)
    if input_errors and s.time:
        # at the NLP's input samples (the recorded-rate ones with resample_inputs = "record")
        sigma = noise_sigmas(maneuvers, (*s.time, *input_errors), noise_sigma, input_record=True)
        info.input_sigma = {c: float(sigma[c]) for c in input_errors}
        info.input_models = input_error_models(maneuvers, input_errors, input_error_ar, input_record=True)
        start = 0
        for mv in maneuvers:
            t_in, inc, idx = mv.input_grid()
            _, S_e = input_sensitivities(mdl, trim_float(mdl, mv.trim_speed), t_in, inc, list(s.time),
                                         input_errors, keep=idx)
            info.S_input.append(((start, start + len(idx)), S_e))
            start += len(idx)
    for o in s.time:
        meas = np.concatenate([mv.data[o].to_numpy() for mv in maneuvers])
        e = meas - s.y_time[o]
        info.S_time[o], info.e_time[o] = s.time[o], e
        info.R_time[o] = (float(sigma[o]) ** 2 if info.S_input else float(np.mean(e**2) + R_FLOOR[o] ** 2))
    for o in s.trim:
        e = trims[o].to_numpy(dtype=float) - s.y_trim[o]
        info.S_trim[o], info.e_trim[o] = s.trim[o], e
        info.R_trim[o] = float(np.mean(e**2) + TRIM_FLOOR)
    return info


@dataclass
class ParameterUncertainty:
    """Standard errors [SI] and correlations of one estimate; at-bound parameters projected out."""

    names: list
    values: dict
    se: dict  # name -> standard error (nan when at a bound)
    at_bound: dict  # name -> "lower" / "upper" / ""
    correlation: list  # n x n, nan rows/columns for at-bound parameters
    combination: str  # "time", "trim" or "weighted"
    weights: tuple = (1.0, 0.0)  # (a, b) of a J_time + b J_trim

    def correlation_frame(self) -> pd.DataFrame:
        return pd.DataFrame(np.array(self.correlation, dtype=float), index=self.names, columns=self.names)

    def row(self) -> dict:
        """Columns for front.csv: se_<name> and at_bound (e.g. 'theta_twist:upper')."""
        d = {f"se_{n}": self.se[n] for n in self.names}
        d["at_bound"] = ";".join(f"{n}:{b}" for n, b in self.at_bound.items() if b)
        return d

    def to_dict(self) -> dict:
        def clean(x):
            return None if (isinstance(x, float) and not math.isfinite(x)) else x

        # an infinite SE (a direction the data do not determine) is null as a missing one, and named apart
        undetermined = [k for k, v in self.se.items() if v == math.inf]
        return {"names": list(self.names), "values": self.values, "se": {k: clean(v) for k, v in self.se.items()},
                **({"undetermined": undetermined} if undetermined else {}),
                "at_bound": self.at_bound, "correlation": [[clean(float(x)) for x in r] for r in self.correlation],
                "combination": self.combination, "weights": list(self.weights)}

    @classmethod
    def from_dict(cls, d: dict) -> "ParameterUncertainty":
        nan = float("nan")
        return cls(names=d["names"], values=d["values"],
                   se={k: (math.inf if k in d.get("undetermined", ()) else nan) if v is None else v
                       for k, v in d["se"].items()},
                   at_bound=d["at_bound"], correlation=[[nan if x is None else x for x in r] for r in d["correlation"]],
                   combination=d["combination"], weights=tuple(d["weights"]))

    def table(self) -> pd.DataFrame:
        rows = []
        for n in self.names:
            v, s = self.values[n], self.se[n]
            rows.append({"parameter": n, "estimate": v,
                         "standard error": s if math.isfinite(s) else float("nan"),
                         "relative %": 100 * s / abs(v) if (math.isfinite(s) and v != 0) else float("nan"),
                         "note": f"at {self.at_bound[n]} bound, projected out" if self.at_bound[n] else
                         "not determined by the data (infinite standard error)" if s == math.inf else ""})
        return pd.DataFrame(rows)

    def __str__(self) -> str:
        return (self.table().to_string(index=False, float_format=lambda x: f"{x:.4g}") + "\n\ncorrelation:\n"
                + self.correlation_frame().to_string(float_format=lambda x: f"{x:+.3f}"))


def newton_step_in_standard_errors(H: np.ndarray, G: np.ndarray, g: np.ndarray) -> float:
    """Largest |H^-1 g| / standard error (sandwich H^-1 G H^-1) over the parameters, or 0 without any.

    How far, in its own standard errors, minimising one objective alone would move the point: a
    value far below 1 means the point already is that objective's optimum for every statistical
    purpose, whatever the direction of the (numerically tiny) gradient."""
    if len(g) == 0:
        return 0.0
    Hi = np.linalg.pinv(H)
    step = Hi @ g
    se = np.sqrt(np.clip(np.diag(Hi @ G @ Hi), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(se > 0, np.abs(step) / se, np.where(step == 0, 0.0, np.inf))
    return float(np.max(ratio))


def objective_weights(info: PointInformation, kind: str, free_idx, multiplier: float | None = None
                      ) -> tuple[float, float]:
    """(a, b) with the point stationary for a J_time + b J_trim; see the module docstring.

    ``multiplier``: an epsilon point's b/a as its solve found it (-dJ_time/dJ_trim from the J_trim bound's
    multiplier, front.csv ``multiplier_trim``), used instead of the least-squares estimate when finite."""
    if kind == "A" or not info.S_trim:
        return 1.0, 0.0
    if not info.S_time:
        return 0.0, 1.0
    Ft, Hr = info.fisher_time()[np.ix_(free_idx, free_idx)], info.hessian_trim()[np.ix_(free_idx, free_idx)]
    if kind != "B":
        # An epsilon point that is already J_time's (or J_trim's) optimum to a thousandth of a standard
        # error: both gradients are rounding noise (a degenerate front, e.g. noise-free data, where
        # every point is the same estimate), and their directions would give arbitrary weights.
        gt, gr = info.grad_time()[free_idx], info.grad_trim()[free_idx]
        if newton_step_in_standard_errors(Ft, Ft, gt) < STATIONARY_SE:
            return 1.0, 0.0
        Gr = info.gradient_covariance_trim()[np.ix_(free_idx, free_idx)]
        if newton_step_in_standard_errors(Hr, Gr, gr) < STATIONARY_SE:
            return 0.0, 1.0
    if kind == "eps" and multiplier is not None and math.isfinite(multiplier) and multiplier >= 0:
        return 1.0 / (1.0 + multiplier), multiplier / (1.0 + multiplier)
    if kind == "B":
        # lexicographic trim anchor: J_trim dominates; J_time only decides what trims cannot see
        return 1e-6 * np.linalg.norm(Hr) / max(np.linalg.norm(Ft), 1e-300), 1.0
    # b/a: the least-squares multiplier, the k >= 0 that brings g_time + k g_trim closest to zero, with gradients
    # compared in the metric of the combined information's inverse (a step in standard errors): exact when the
    # gradients are anti-parallel (a g_time + b g_trim = 0), continuous in them otherwise, and independent of the
    # parameters' nominal scales. Only the part of g_time along g_trim is balanced: what the float model's J_time
    # gradient keeps along a parameter the trims cannot see (its optimum is the collocation NLP's only to within
    # a fraction of a standard error) is left out instead of setting the ratio. A balance in nominal scales let
    # that part dominate through an inertia's scale, and a sign picked by rounding then gave time-only or
    # trim-only standard errors.
    F = info.fisher_time()[np.ix_(free_idx, free_idx)] + info.fisher_trim()[np.ix_(free_idx, free_idx)]
    Fi = _pseudo_inverse(F)
    gt, gr = info.grad_time()[free_idx], info.grad_trim()[free_idx]
    rr = float(gr @ Fi @ gr)
    k = max(-float(gt @ Fi @ gr) / rr, 0.0) if rr > 0 else 0.0
    return 1.0 / (1.0 + k), k / (1.0 + k)


def _pseudo_inverse(F: np.ndarray) -> np.ndarray:
    """F^-1, with directions F does not see floored at 1e-12 of its largest eigenvalue (after scaling F to a unit
    diagonal, so that no parameter's unit decides what counts as unseen)."""
    d = np.sqrt(np.clip(np.diag(F), 0.0, None))
    d = np.where(d > 0, d, 1.0)
    w, V = np.linalg.eigh(F / np.outer(d, d))
    w = np.maximum(w, 1e-12 * max(w.max(), 1e-300))
    return (V / w) @ V.T / np.outer(d, d)


def cramer_rao(info: PointInformation, free, kind: str = "A", weights: tuple | None = None,
               multiplier: float | None = None) -> ParameterUncertainty:
    """Standard errors and correlations at ``info``'s estimate for a front point of ``kind``.

    kind "A" (time domain): F_time^-1. "B" / "eps" / "direct": the sandwich
    covariance of the weighted sum it is stationary for (module docstring).
    ``weights`` (a, b) overrides the weights found from the gradients; ``multiplier``, an epsilon point's
    b/a from its solve (:func:`objective_weights`).
    """
    names = info.names
    bounds = _bounds_held(info, free, kind, multiplier, weights)
    idx = [i for i, n in enumerate(names) if not bounds[n]]
    n = len(names)
    a, b = weights if weights is not None else objective_weights(info, kind, idx, multiplier)
    Ft = info.fisher_time()[np.ix_(idx, idx)]
    H = a * Ft + b * info.hessian_trim()[np.ix_(idx, idx)]
    G = a * a * Ft + b * b * info.gradient_covariance_trim()[np.ix_(idx, idx)]
    cov_free = np.full((len(idx), len(idx)), np.nan)
    if idx:
        # H singular along some direction: the data do not determine it; the parameters taking part
        # in it get an infinite standard error instead of the zero a pseudo-inverse would give. The test is made
        # in the parameters' nominal scales (info.scale), so that a parameter of large SI value (K_beta, 1e5) next
        # to a small one (the twist) is not read as a null direction
        d = np.asarray(info.scale, dtype=float)[idx]
        w, V = np.linalg.eigh(H * np.outer(d, d))
        null = w <= 1e-12 * max(w.max(), 1e-300)
        Hi = ((V[:, ~null] / w[~null]) @ V[:, ~null].T) * np.outer(d, d)
        cov_free = Hi @ G @ Hi
        blind = np.abs(V[:, null]).max(axis=1) > 1e-6 if null.any() else np.zeros(len(idx), bool)
        cov_free[blind, :] = cov_free[:, blind] = np.nan
        cov_free[blind, blind] = np.inf
    cov = np.full((n, n), np.nan)
    cov[np.ix_(idx, idx)] = cov_free
    se_arr = np.sqrt(np.clip(np.diag(cov), 0, None))  # nan (at a bound) and inf (not determined) pass
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se_arr, se_arr)
    combination = "time" if b == 0 else ("trim" if a == 0 else "weighted")
    return ParameterUncertainty(names=list(names), values=dict(info.values),
                                se={nm: float(se_arr[i]) for i, nm in enumerate(names)}, at_bound=bounds,
                                correlation=corr.tolist(), combination=combination, weights=(float(a), float(b)))
