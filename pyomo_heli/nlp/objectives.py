"""Objectives of the identification NLP as Pyomo expressions.

J_time: output-error maximum likelihood with the residual covariance R
estimated (paper Eqs. 5-6), in concentrated form. At R's ML estimate
R = S/N, S = sum_k e_k e_k^T, Eq. 5 becomes
    J_time = N n_y / 2 + (N/2) ln det(R).
ln det R is written with a Cholesky factor R = L L^T whose entries are NLP
variables tied by equality constraints (smooth, no matrix inverse):
    ln det R = 2 sum_i ln L_ii,  so  J_time = N n_y/2 + N sum_i ln L_ii.
With ``covariance = "diagonal"`` L is diagonal: L_ii^2 = S_ii / N (the usual
output-error choice of uncorrelated output noise).

A documented relaxation: R = S/N + diag(r_floor^2), r_floor a resolution
floor per output (default about 1/300 of the sensor noise, see
``R_FLOOR``). Without it the concentrated likelihood is unbounded below on
noise-free data (one output fitted exactly drives ln det R to -inf, at any
parameter value); with it, noise-free data give a weighted least-squares fit
whose minimum is the true parameter set, and on noisy data the optimum moves
by O(r_floor^2 / sigma^2), about 1e-5 relative.

With input errors (``NLPOptions.input_errors``, errors in variables) the noise
sigmas are *known* (given, or estimated from the quiet lead-in of the records,
:func:`lead_in_sigma`) instead of estimated with the parameters:
    J_time = sum_k sum_o e_ok^2 / (2 sigma_o^2) + N sum_o ln sigma_o
           + sum_k sum_c d_ck^2 / (2 sigma_c^2) + N sum_c ln sigma_c,
the negative log-likelihood of the measured outputs o and of the measured
inputs c, whose errors d_ck are NLP variables (Eq. 5 with R known, plus the
inputs' own term). The concentrated form cannot be used there: with the
inputs free, an output that responds at once to an input (n_z to the
collective) can be fitted exactly by input errors, and ln det R of the
estimated R then falls without bound (to the floor below).

J_trim: mean square trim error (paper Eq. 7) over the configured trim
outputs, in degrees so that the unweighted sum is meaningful.
"""
from __future__ import annotations

import math

import numpy as np
import pyomo.environ as pyo

from ..dataset.schema import lead_in
from ..units import DEG

#: resolution floor of each output in the likelihood [SI units]
R_FLOOR = {"q": 1e-5, "theta": 1e-5, "n_x": 2e-5, "n_z": 3e-5, "TAS": 2e-3, "beta_0": 3e-6}


def add_time_objective(m: pyo.Block, residuals: dict, outputs: list[str], covariance: str = "diagonal",
                       init_residuals: dict | None = None, r_floor: dict | None = None) -> None:
    """Add ``m.J_time`` from residual expressions.

    residuals: output name -> list of residual expressions (all maneuvers).
    init_residuals: output name -> numpy residuals at the initial guess, to
    initialise the Cholesky factor consistently.
    """
    if covariance not in ("diagonal", "full"):
        raise ValueError(f"covariance must be 'diagonal' or 'full', got {covariance!r}")
    n_y = len(outputs)
    N = len(residuals[outputs[0]])
    if any(len(residuals[o]) != N for o in outputs):
        raise ValueError("every output needs the same number of residuals")
    m.time_outputs = pyo.Set(initialize=outputs, ordered=True)
    pairs = [(a, b) for i, a in enumerate(outputs) for b in outputs[: i + 1]]
    if covariance == "diagonal":
        pairs = [(a, a) for a in outputs]
    m.cov_pairs = pyo.Set(initialize=pairs, dimen=2, ordered=True)
    m.n_samples = pyo.Param(initialize=N)

    floor = dict(R_FLOOR, **(r_floor or {}))

    def S_rule(_, a, b):
        extra = floor[a] ** 2 if a == b else 0.0
        return sum(ea * eb for ea, eb in zip(residuals[a], residuals[b])) / N + extra

    m.R_hat = pyo.Expression(m.cov_pairs, rule=S_rule)

    R0 = None
    if init_residuals is not None:
        E = np.array([init_residuals[o] for o in outputs])
        R0 = E @ E.T / N + np.diag([floor[o] ** 2 for o in outputs])
        if covariance == "diagonal":
            R0 = np.diag(np.diag(R0))
        L0 = np.linalg.cholesky(R0 + 1e-14 * np.eye(n_y))
    idx = {o: i for i, o in enumerate(outputs)}
    m.L = pyo.Var(m.cov_pairs, initialize=lambda _, a, b: float(L0[idx[a], idx[b]]) if R0 is not None else
                  (1.0 if a == b else 0.0))
    for a in outputs:
        m.L[a, a].setlb(1e-9)

    def chol_rule(_, a, b):
        ia, ib = idx[a], idx[b]
        lhs = sum(m.L[a, c] * m.L[b, c] for c in outputs[: min(ia, ib) + 1] if (a, c) in m.cov_pairs
                  and (b, c) in m.cov_pairs)
        return lhs == m.R_hat[a, b]

    m.cholesky = pyo.Constraint(m.cov_pairs, rule=chol_rule)
    m.J_time = pyo.Expression(expr=N * n_y / 2 + N * sum(pyo.log(m.L[a, a]) for a in outputs))


def add_known_noise_time_objective(m: pyo.Block, residuals: dict, outputs: list[str], sigma: dict,
                                   input_errors: dict | None = None, input_sigma: dict | None = None) -> None:
    """``m.J_time`` with known noise sigmas and, optionally, the input-error term (module docstring).

    residuals: output -> residual expressions (all maneuvers); sigma: output -> sigma [SI];
    input_errors: input channel -> list of error variables (all samples); input_sigma: channel -> sigma [SI].
    Also ``m.J_output`` and ``m.J_input``, the two parts.
    """
    missing = [o for o in outputs if o not in sigma]
    if missing:
        raise ValueError(f"no noise sigma for output(s) {missing}")
    N = len(residuals[outputs[0]])
    m.time_outputs = pyo.Set(initialize=outputs, ordered=True)
    m.n_samples = pyo.Param(initialize=N)
    errs = dict(input_errors or {})
    m.noise_sigma = pyo.Param(list(outputs) + list(errs), mutable=False,
                              initialize={**{o: float(sigma[o]) for o in outputs},
                                          **{c: float(input_sigma[c]) for c in errs}})
    # Mean squares as variables defined by one equality each (as R_hat and the Cholesky factor
    # above): J_time then depends on a handful of variables, and the squared J_time of the
    # utopia-distance objective (Eq. 11) keeps a small dense Hessian block instead of coupling
    # every residual with every other one.
    sums = {**{o: residuals[o] for o in outputs}, **errs}
    m.square_count = pyo.Param(list(sums), initialize={c: len(v) for c, v in sums.items()})
    m.sum_square = pyo.Expression(list(sums), rule=lambda _, c: sum(e * e for e in sums[c]))
    m.mean_square = pyo.Var(list(sums), initialize=lambda _, c: pyo.value(m.sum_square[c]) / len(sums[c]))
    m.mean_square_def = pyo.Constraint(list(sums), rule=lambda _, c: m.mean_square[c] * m.square_count[c]
                                       == m.sum_square[c])

    def nll(c, n):  # negative log-likelihood of n samples of channel c, without 2 pi
        s_c = float(m.noise_sigma[c])
        return n * m.mean_square[c] / (2.0 * s_c**2) + n * math.log(s_c)

    m.J_output = pyo.Expression(expr=sum(nll(o, N) for o in outputs))
    m.J_input = pyo.Expression(expr=sum(nll(c, len(errs[c])) for c in errs) if errs else 0.0)
    m.J_time = pyo.Expression(expr=m.J_output + m.J_input)


#: smallest noise sigma the lead-in estimate may give [SI]: the outputs' resolution floors, and for the
#: inputs 1e-5 rad (0.0006 deg, 1/35 of the bundled flight test's position noise)
SIGMA_MIN = dict(R_FLOOR, col=1e-5, lon=1e-5)


def noise_sigmas(maneuvers, channels, given: dict | None = None, input_record: bool = False) -> dict:
    """The known noise sigma [SI] of each channel of an errors-in-variables fit: from ``given`` (the
    ``[objectives.noise_sigma]`` table, which must then cover every channel) or else from the records'
    quiet lead-in (:func:`lead_in_sigma`). The one rule the NLP, the Cramer-Rao bounds and the score test
    share, so that all three weigh the data alike. ``input_record``: an input's lead-in is taken from the samples
    its errors sit on, the recorded-rate inputs (``Maneuver.inputs_record``) where a maneuver has them (the NLP
    with ``resample_inputs = "record"``); else from ``data`` (the input sensitivities of the diagnosis and the
    Cramer-Rao bounds, which take the inputs at the samples)."""
    channels = list(channels)
    if given is None:
        return lead_in_sigma(maneuvers, channels, input_record)
    missing = [c for c in channels if c not in given]
    if missing:
        raise ValueError(f"noise_sigma has no value for {missing}")
    return {c: float(given[c]) for c in channels}


def _lead_in(mv, channel: str, input_record: bool, what: str, remedy: str) -> np.ndarray:
    """A record's samples of ``channel`` over its quiet lead-in (t <= t0 + ``input_reference_s``): from
    ``inputs_record`` when ``input_record`` and the maneuver has it, else from ``data``. ``what`` and ``remedy``
    word the error of a record without a lead-in."""
    if mv.input_reference_s <= 0:
        raise ValueError(f"maneuver {mv.name}: {what} from the quiet lead-in, but no lead-in is set: {remedy}")
    rec = mv.inputs_record if input_record else None
    src = rec if rec is not None and channel in rec else mv.data
    return src[channel].to_numpy(dtype=float)[lead_in(src["t"], mv.input_reference_s)]


def lead_in_ar(maneuvers, channel: str, order: int, input_record: bool = False) -> tuple[np.ndarray, float]:
    """An autoregressive model of a channel's noise from the quiet lead-in of the records (no model involved).

    The autocovariances at lags 0..``order`` are pooled over the lead-ins (t <= t0 + ``input_reference_s``, each
    about its own mean; ``input_record`` as in :func:`lead_in_sigma`) and solved by Yule-Walker. Returns ``(a,
    ratio)``: the coefficients of ``d_k = sum_j a_j d_{k-1-j} + w_k`` and the innovation sigma over the noise
    sigma, sqrt(var w / var d). Raises ValueError when a lead-in is missing or shorter than ``order + 2`` samples.
    """
    from scipy.linalg import solve_toeplitz

    r, n = np.zeros(order + 1), np.zeros(order + 1)
    for mv in maneuvers:
        x = _lead_in(mv, channel, input_record, "the input errors' autoregressive model comes",
                     "give [data] input_reference_s > 0")
        if len(x) < order + 2:
            raise ValueError(f"maneuver {mv.name}: {len(x)} sample(s) in the {mv.input_reference_s} s lead-in; an "
                             f"autoregressive model of order {order} of '{channel}' needs at least {order + 2}")
        x = x - x.mean()
        for lag in range(order + 1):
            r[lag] += float(np.dot(x[: len(x) - lag], x[lag:]))
            n[lag] += len(x) - lag
    r = r / n
    if not r[0] > 0:
        raise ValueError(f"channel '{channel}' shows no noise in the lead-in of the maneuvers: no autoregressive "
                         f"model of it")
    if order == 0:
        return np.zeros(0), 1.0
    a = solve_toeplitz(r[:-1], r[1:])
    return a, math.sqrt(max(float(r[0] - a @ r[1:]), 0.0) / r[0])


def ar_precision(n: int, a, sigma_w: float) -> np.ndarray:
    """The precision (inverse covariance) of ``n`` errors of one record under an autoregressive model: coefficients
    ``a`` (:func:`lead_in_ar`), innovation sigma ``sigma_w``, the errors before the record's first taken as zero.
    ``A^T A / sigma_w^2``, A the lower-triangular map of the errors to their innovations (1 on the diagonal, -a_j
    on the (j+1)-th subdiagonal), so that ``e^T P e / 2`` is the NLP's J_input of those errors (less its constant)."""
    A = np.eye(n)
    for j, aj in enumerate(np.asarray(a, float)):
        A -= aj * np.eye(n, k=-(j + 1))
    return A.T @ A / sigma_w**2


def input_error_models(maneuvers, channels, order: int, input_record: bool = False) -> dict:
    """Channel -> (coefficients, innovation over noise sigma) of the AR(``order``) model of each input channel's
    errors from the records' lead-ins (:func:`lead_in_ar`), as the NLP takes them with ``[objectives]
    input_error_ar``; {} for order 0 (independent errors)."""
    return {c: lead_in_ar(maneuvers, c, order, input_record) for c in channels} if order else {}


def input_error_covariance(n: int, channels, sigma: dict, models: dict | None = None) -> np.ndarray:
    """The covariance of one record's input errors, ``n`` samples of each channel (channel blocks in ``channels``
    order; ``sigma``: each channel's noise sigma [SI]; ``models``: :func:`input_error_models`). Independent errors:
    the vector of their variances (the diagonal); AR errors: the block-diagonal matrix, each block the inverse of
    :func:`ar_precision` with innovation sigma ``sigma x ratio``."""
    models = models or {}
    if not any(c in models for c in channels):
        return np.repeat([float(sigma[c]) ** 2 for c in channels], n)
    out = np.zeros((len(channels) * n, len(channels) * n))
    for i, c in enumerate(channels):
        blk = slice(i * n, (i + 1) * n)
        if c in models:
            a, ratio = models[c]
            out[blk, blk] = np.linalg.inv(ar_precision(n, a, float(sigma[c]) * ratio))
        else:
            out[blk, blk] = np.eye(n) * float(sigma[c]) ** 2
    return out


def times_covariance(X: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``X @ Sigma`` for a covariance given as :func:`input_error_covariance` returns it (a vector of variances or
    a symmetric matrix)."""
    return X * cov if cov.ndim == 1 else X @ cov


def lead_in_sigma(maneuvers, channels, input_record: bool = False) -> dict:
    """Noise sigma of each channel from the quiet lead-in of the records (no model involved).

    Over the samples with t <= t0 + ``input_reference_s`` (the aircraft in trim, before the first
    input) each record's channel is constant up to its noise: sigma^2 is the pooled variance about
    each lead-in's own mean. ``input_record``: an input channel from ``Maneuver.inputs_record`` where a maneuver
    has one. Raises ValueError when the maneuvers have no lead-in set or too short a one,
    or when a channel shows no noise there (sigma below ``SIGMA_MIN``).
    """
    out = {}
    for ch in channels:
        ss, dof = 0.0, 0
        for mv in maneuvers:
            x = _lead_in(mv, ch, input_record, "the noise sigmas come",
                         "give [data] input_reference_s > 0 or [objectives.noise_sigma]")
            if len(x) < 3:
                raise ValueError(f"maneuver {mv.name}: only {len(x)} sample(s) in the {mv.input_reference_s} s "
                                 f"lead-in; the noise sigma of '{ch}' needs at least 3")
            ss += float(np.sum((x - x.mean()) ** 2))
            dof += len(x) - 1
        out[ch] = math.sqrt(ss / dof)
        least = SIGMA_MIN.get(ch, 0.0)
        if not out[ch] > least:
            raise ValueError(f"channel '{ch}' shows no noise in the lead-in of the maneuvers (sigma {out[ch]:.3g} "
                             f"<= {least:.3g} in SI units): with sigmas that small the input errors make the NLP "
                             f"ill-conditioned (measured: a solve converged to twist -450 % of truth); drop "
                             f"input_errors for exact inputs, or give [objectives.noise_sigma]")
    return out


def j_time_value(residuals: dict, outputs: list[str], covariance: str = "diagonal",
                 r_floor: dict | None = None) -> float:
    """J_time of numpy residuals, computed directly from Eqs. 5-6 (an independent check).

    R = S/N + diag(r_floor^2) (the floor is the relaxation described above).
    """
    floor = dict(R_FLOOR, **(r_floor or {}))
    E = np.array([np.asarray(residuals[o], dtype=float) for o in outputs])
    N = E.shape[1]
    R = E @ E.T / N + np.diag([floor[o] ** 2 for o in outputs])
    if covariance == "diagonal":
        R = np.diag(np.diag(R))
    # At R's ML estimate the quadratic term of Eq. 5 is N n_y / 2 (exact without the floor).
    return float(N * len(outputs) / 2 + N / 2 * math.log(np.linalg.det(R)))


def add_trim_objective(m: pyo.Block, residuals: list) -> None:
    """``m.J_trim``: mean over trim points of the squared trim residual vector (residuals in rad)."""
    n = len(residuals)
    m.n_trims = pyo.Param(initialize=n)
    m.J_trim = pyo.Expression(expr=sum(sum((r / DEG) ** 2 for r in point) for point in residuals) / n)


# ---------------------------------------------------------------- J_linear (paper Eq. 9)
#: gain weight [1/dB^2] and phase weight [1/deg^2] of Eq. 9, Tischler & Remple's values, which
#: make 1 dB of gain error count like 7.57 deg of phase error
W_GAIN, W_PHASE = 1.0, 0.01745
DB_PER_NEPER2 = 10.0 / math.log(10.0)  # 10 log10(|G|^2) = DB_PER_NEPER2 * ln(|G|^2)


def coherence_weight(coherence) -> np.ndarray:
    """W_gamma = [1.58 (1 - exp(-gamma^2))]^2 (Tischler & Remple), gamma^2 = the coherence."""
    return (1.58 * (1.0 - np.exp(-np.asarray(coherence, float)))) ** 2


def linear_terms(G_re, G_im, T: complex, coherence: float, ops=None):
    """Weighted squared gain [dB] and phase [deg] errors of one frequency (Eq. 9 summand).

    The phase error is the angle of G / T, written as 2 atan(Im / (|z| + Re)) with
    z = G conj(T)/|T|: smooth everywhere except at exactly 180 deg, no atan2 branch cut.
    ``ops`` supplies log, sqrt, atan (Pyomo or numpy).
    """
    ops = ops or pyo
    c, s = math.cos(np.angle(T)), math.sin(np.angle(T))
    re = G_re * c + G_im * s
    im = G_im * c - G_re * s
    gain_err = DB_PER_NEPER2 * ops.log(G_re**2 + G_im**2) - 20 * math.log10(abs(T))
    phase_err = 2 * ops.atan(im / (ops.sqrt(re**2 + im**2) + re)) * (180.0 / math.pi)
    return float(coherence_weight(coherence)) * (W_GAIN * gain_err**2 + W_PHASE * phase_err**2)


def add_linear_objective(m: pyo.Block, terms: list[list]) -> None:
    """``m.J_linear``: Eq. 9 per frequency response, averaged over the responses.

    terms: one list per frequency response of the Eq. 9 summands (``linear_terms``);
    J_r = 20/n_omega sum_k summand_k, J_linear = mean_r J_r.
    """
    n = len(terms)
    m.n_linear_responses = pyo.Param(initialize=n)
    m.J_linear = pyo.Expression(expr=sum(20.0 / len(t) * sum(t) for t in terms) / n)


def j_linear_value(responses, model_T) -> float:
    """J_linear of data responses against complex model responses (numpy; an independent check).

    responses: FrequencyResponse objects restricted to the bins used (``.band()``);
    model_T: one complex array per response at the same bins.
    """
    total = 0.0
    for r, G in zip(responses, model_T):
        G = np.asarray(G)
        gain = 20 * np.log10(np.abs(G)) - 20 * np.log10(np.abs(r.T))
        phase = np.degrees(np.angle(G / r.T))
        total += 20.0 / len(r.omega) * np.sum(coherence_weight(r.coherence) * (W_GAIN * gain**2 + W_PHASE * phase**2))
    return total / len(responses)
