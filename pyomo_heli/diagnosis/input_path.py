"""What the measured inputs miss: the control-path equation error of the records, with no library of effects.

A control-path effect (a cross-feed of collective into cyclic, a gearing error, an unrecorded feedback, a lag)
makes the rotor see something other than the recorded control. When the identification estimates the input
errors (``[objectives] input_errors``), their noise model is white; a control-path effect is an input error that
follows a signal of the flight instead. The residual analysis asks which signal, by regression on a small generic
dictionary, the input-path counterpart of estimation before modelling (Klein and Morelli, *Aircraft System
Identification*):

    input error of channel c  =  a * (s(t) - s_ref),     s in SIGNALS,

each term's effect on the outputs taken to first order through the exact output sensitivities to every input
sample (S_u, :func:`pyomo_heli.simulation.compiled.input_sensitivities`), in the whitened coordinates of the
innovations (:mod:`.innovations`: covariance R + S_u Sigma_u S_u^T, rows at the test rate). The reference s_ref
of a record is absorbed by its nuisance (a bias per output, a constant offset per input), so the regression sees
only how the error changes within a record; a shift of the identified parameters (their output sensitivities) is
projected out too. The regressors carry the measured inputs' noise, which is also in the residual; corrected least
squares subtracts its expected share of the sums (:func:`record_block`).

Selection is forward with a backward check, as SIDPAC's stepwise regression: at each step the term with the
largest |z| over the whole dictionary enters when its two-sided p is below ``alpha / (dictionary size)``
(Bonferroni over the dictionary: the family-wise false-alarm rate on a right model is at most ``alpha`` per
step); a term already in that is no longer below the level leaves. The residual variance is estimated from the
whitened rows (F-type scale), so a noise level off by a constant factor does not make terms significant.

The dictionary is generic: each input channel against the measured inputs, the model's pitch rate, attitude and
airspeed (the replay's, not the measurements, whose noise is in the residual), and the inputs' rates; the extended
dictionary (``[diagnosis] input_path_family = "extended"``) adds each input's free play and dead zone, the
control-path nonlinearities no linear signal describes. It names no effect; the held-out truth effects of the
discovery study are never imported here.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy import stats

from ..nlp.objectives import times_covariance

#: the dictionary's signals: name -> (how it is taken, SI unit)
SIGNALS = {
    "col": ("measured collective (increment)", "rad"),
    "lon": ("measured longitudinal cyclic (increment)", "rad"),
    "q": ("model pitch rate", "rad/s"),
    "theta": ("model pitch attitude", "rad"),
    "TAS": ("model true airspeed", "m/s"),
    "col_rate": ("rate of the measured collective", "rad/s"),
    "lon_rate": ("rate of the measured longitudinal cyclic", "rad/s"),
    "col_play": ("free play of the measured collective: the side of its play, times half its width", "rad"),
    "lon_play": ("free play of the measured longitudinal cyclic: the side of its play, times half its width", "rad"),
    "col_zone": ("dead zone of the measured collective about its reference: its side beyond the zone, times half its "
                 "width", "rad"),
    "lon_zone": ("dead zone of the measured longitudinal cyclic about its reference: its side beyond the zone, times "
                 "half its width", "rad"),
}
#: the width of the play operator of the ``*_play`` signals, in input noise sigmas: the narrowest play that the
#: recorded input's noise alone (within +-3 sigma) does not move
PLAY_WIDTH_SIGMAS = 6.0
#: the centred moving average [s] the measured input gets before its play or dead zone is taken (the rigid-body
#: band: the noise is no movement of the stick)
PLAY_SMOOTH_S = 0.2
#: most terms the selection takes
MAX_TERMS = 3


def play_widths(sigma: dict) -> dict:
    """Input channel -> the width [rad] of its ``*_play`` signal's play operator, from the input noise ``sigma``
    [rad] (PLAY_WIDTH_SIGMAS); a channel ``sigma`` does not hold has no play signal."""
    return {c: PLAY_WIDTH_SIGMAS * float(sigma[c]) for c in ("col", "lon") if c in sigma}


def play(u: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """The play (backlash) operator of ``width`` [rad] on the input ``u``: a follower that starts at ``u[0]`` and
    moves only when ``u`` pushes it, staying within ``width / 2`` of it. Returns ``(p, j)``: the follower, and for
    each sample the index of the input sample it rests on (``p[k] = u[j[k]] +- width / 2``, or ``u[0]`` before
    the first push): the exact linear map of a small change of ``u`` into ``p``.

    ``p - u`` is the control error of a free play in the linkage (the follower lags the input by half the play
    on every movement and keeps its side when the input reverses within the play): a control-path nonlinearity
    that no linear signal of the dictionary describes."""
    u = np.asarray(u, float)
    p, j = np.empty_like(u), np.zeros(len(u), dtype=int)
    if not len(u):
        return p, j
    h = 0.5 * width
    p[0] = u[0]
    for k in range(1, len(u)):
        if u[k] - h > p[k - 1]:
            p[k], j[k] = u[k] - h, k
        elif u[k] + h < p[k - 1]:
            p[k], j[k] = u[k] + h, k
        else:
            p[k], j[k] = p[k - 1], j[k - 1]
    return p, j


def smoothing(t: np.ndarray, span_s: float = PLAY_SMOOTH_S) -> np.ndarray:
    """The (n x n) matrix of the centred moving average over ``span_s`` [s] at the samples ``t`` (an odd number of
    samples; shorter, still centred, at the ends)."""
    n = len(t)
    half = int(round(span_s / float(np.median(np.diff(t))) / 2)) if n > 1 else 0
    S = np.zeros((n, n))
    for k in range(n):
        r = min(half, k, n - 1 - k)
        S[k, k - r:k + r + 1] = 1.0 / (2 * r + 1)
    return S


def play_signal(t: np.ndarray, u: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """The free-play signal of one input: ``-(width / 2) x side``, the side the play operator's follower was last
    pushed from (+1 from below, -1 from above, 0 before the first push; :func:`play` of the input smoothed over
    PLAY_SMOOTH_S, :func:`smoothing`): the control error ``play(u) - u`` of a free play of ``width`` where the stick
    moves more than the play, without its traverse. The input's noise does not enter it (its map is zero): the side
    turns only when the input comes back the whole width, which its smoothed noise does not; within a hold the
    noise ratchets the follower (its rest sample is picked by the noise, so ``play(u) - u`` itself is not linear in
    it), never across."""
    us = smoothing(t) @ np.asarray(u, float)
    p, j = play(us, width)
    side = np.sign(np.round((us[j] - p) / (0.5 * width))) if width > 0 else np.zeros_like(us)
    return -0.5 * width * side, np.zeros((len(us), len(us)))


def zone_signal(t: np.ndarray, u: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """The dead-zone signal of one input increment: ``-(width / 2) x sign(u_s)`` where the increment smoothed over
    PLAY_SMOOTH_S is beyond ``width / 2`` from the reference, 0 within: the control error of a linkage that passes
    nothing within ``width / 2`` of the reference and the rest less that (``dz(u) - u``) where the stick is beyond
    the zone. Within it that error is ``-u``, the input's own noise in the quiet parts: left out, the signal does not
    carry the noise (its map is zero; the smoothed noise does not reach the zone's edge). Taken with the noise in,
    corrected least squares under independent errors under-subtracts the share a smoothed signal has of the
    filtered input noise, and on M0 + noise the exact model's input errors follow their own channel's zone."""
    S = smoothing(t)
    us = S @ np.asarray(u, float)
    h = 0.5 * width
    return -h * np.sign(us) * (np.abs(us) > h), np.zeros_like(S)


def signal_values(t: np.ndarray, increments: dict, y: dict, widths: dict | None = None) -> dict:
    """The dictionary's signals of one record at its samples ``t`` [s] (SI): the measured input ``increments``, the
    model outputs ``y`` (q, theta, TAS; one ``y`` does not carry is left out), the inputs' rates and, for each
    channel in ``widths`` (:func:`play_widths`), its free play and dead zone."""
    out = {c: np.asarray(increments[c], float) for c in ("col", "lon")}
    out.update({o: np.asarray(y[o], float) for o in ("q", "theta", "TAS") if o in y})
    for c in ("col", "lon"):
        out[f"{c}_rate"] = np.gradient(out[c], t) if len(t) > 1 else np.zeros_like(out[c])
    for c, w in (widths or {}).items():
        out[f"{c}_play"] = play_signal(t, out[c], w)[0]
        out[f"{c}_zone"] = zone_signal(t, out[c], w)[0]
    return {k: out[k] for k in SIGNALS if k in out}


def input_error(terms: list, signals: dict, n: int) -> dict:
    """The input error the selected ``terms`` give along a record: {channel: sum of estimate x signal} [rad]."""
    out = {"col": np.zeros(n), "lon": np.zeros(n)}
    for t in terms:
        out[t["channel"]] = out[t["channel"]] + t["estimate"] * signals[t["signal"]]
    return out


def signals_of(model, mv, y: dict, channels, substeps: int = 2, widths: dict | None = None) -> dict:
    """The dictionary's signals of one prepared record at its samples, each with the linear map of the input noise
    into it: ``{name: (x, A)}``, x the signal (SI) and A (n x len(channels) n) its part due to the measured inputs'
    errors (the columns of every input sample, channel blocks in ``channels`` order). The measured inputs carry their
    own noise, the replay's outputs that noise through the dynamics (their exact sensitivities); the regression takes
    it out (corrected least squares), or a channel the pilot held still would be found to follow its own noise.
    ``y``: the replay's outputs at every sample; a model output it does not carry is left out. ``widths``: the play
    signals' widths (:func:`play_widths`; none without). The signals are taken at the input samples (``input_grid``:
    an input error is one of each); where those are the recorded-rate ones, the model outputs are the replay's there.
    """
    from ..simulation.compiled import input_sensitivities
    from ..simulation.trim import trim_float

    t, inc, idx = mv.input_grid()
    n = len(t)
    model_outs = [o for o in ("q", "theta", "TAS") if o in y]
    S, y_in = {}, y
    if model_outs:
        y_in, S = input_sensitivities(model, trim_float(model, mv.trim_speed), t, inc, model_outs, list(channels),
                                      substeps)
        if len(idx) == n:  # the maneuver's own samples: the outputs as given (e.g. the record-rate replay's)
            y_in = y
    values = signal_values(t, inc, y_in, widths)
    block = {c: slice(i * n, (i + 1) * n) for i, c in enumerate(channels)}
    grad = np.gradient(np.eye(n), t, axis=0) if n > 1 else np.zeros((n, n))
    noise = {}
    for c in ("col", "lon"):
        A = np.zeros((n, len(channels) * n))
        R = np.zeros_like(A)
        F, Z = np.zeros_like(A), np.zeros_like(A)
        if c in block:
            A[:, block[c]] = np.eye(n)
            R[:, block[c]] = grad
            if c in (widths or {}):
                F[:, block[c]] = play_signal(t, inc[c], widths[c])[1]
                Z[:, block[c]] = zone_signal(t, inc[c], widths[c])[1]
        noise[c], noise[f"{c}_rate"], noise[f"{c}_play"], noise[f"{c}_zone"] = A, R, F, Z
    noise.update({o: S[o] for o in model_outs})
    return {k: (x, noise[k]) for k, x in values.items()}


def expected_inputs(mv, rw: np.ndarray, Su: np.ndarray, L: np.ndarray, cov_u: np.ndarray, channels):
    """The record's inputs with the part of their noise the residual reveals taken out: the measured input minus
    the conditional mean of its error given the residual, ``E[du | e] = Sigma_u Su^T V^-1 e`` (``rw``: the whitened
    residual ``L^-1 e``, e = model - data at the kept rows, with the record's nuisance projected out; ``V = L L^T``;
    ``cov_u``: the covariance of the input samples' errors, channel blocks in ``channels`` order, or the vector of
    their variances when independent; :func:`~pyomo_heli.nlp.objectives.input_error_covariance`). Returns the
    maneuver with those inputs at its input samples (``Maneuver.input_grid``: ``inputs_record`` where it has them).

    Why: the parameter columns (:func:`parameter_columns`) are differences of replays driven by the inputs. Driven
    by the measured ones they carry the input noise's response scaled by the parameter, ``d(S_u du)/dtheta``, which
    lies along the residual's own noise; projecting it out leaves a share of that noise in every regressor and
    shifts every term's z upward (on the exact model about +0.14 on average at the sensor's noise, up to +1.5 for
    one term at four times it). When the model is right, what is left of the error once its conditional mean is
    removed is independent of the residual (jointly Gaussian), so columns driven by these inputs do not carry it
    (``tests/test_input_path.py``)."""
    from scipy.linalg import solve_triangular

    du = times_covariance(solve_triangular(L.T, rw, lower=False) @ Su, cov_u)
    n = Su.shape[1] // len(channels)
    src = "data" if mv.inputs_record is None else "inputs_record"  # where the input samples are
    df = getattr(mv, src)
    quiet = df.assign(**{c: df[c].to_numpy(dtype=float) - du[i * n:(i + 1) * n] for i, c in enumerate(channels)})
    return dataclasses.replace(mv, **{src: quiet})


def parameter_columns(model, mv, outputs, keep, names, substeps: int = 2) -> np.ndarray:
    """The output sensitivities of one prepared record's rows (``keep``, time order) to the parameters ``names``,
    by central differences of the replay from each perturbed model's own trim (the NLP starts every record at its
    model's trim). Nuisance of the input-path regression: the chosen point of a front trades the time fit against
    the trims, so its parameters leave a residual along these directions that is not a missing effect
    (:func:`pyomo_heli.simulation.sensitivity.sensitivities`, rows reordered)."""
    from ..simulation.sensitivity import sensitivities

    keep = np.asarray(keep, dtype=int)
    names = list(names)
    if not names:
        return np.zeros((len(keep) * len(outputs), 0))
    S = sensitivities(model, names, maneuvers=[mv], time_outputs=list(outputs), substeps=substeps).time
    return np.stack([S[o][keep] for o in outputs], axis=1).reshape(len(keep) * len(outputs), len(names))


def record_block(e: np.ndarray, Su: np.ndarray, N: np.ndarray, L: np.ndarray, signals: dict, channels,
                 cov_u: np.ndarray, t: np.ndarray, maneuver: str = "") -> dict:
    """One record's sums for the regression, in whitened rows with its nuisance projected out (Frisch-Waugh).

    ``e``: data - model at the kept rows (time order, every output of a row together); ``Su``: their sensitivities
    to every input sample (channel blocks in ``channels`` order, :func:`.innovations.input_noise_factor`); ``N``:
    the nuisance columns; ``L``: the lower Cholesky factor of the rows' covariance; ``signals``:
    :func:`signals_of`; ``cov_u``: the covariance of the input samples' errors (:func:`expected_inputs`).

    Returns ``DtD``, ``Dte``, ``ete`` (the least-squares sums), ``B`` and ``b``: their expectation due to the
    input noise in the regressors (what corrected least squares subtracts), ``rows``, ``nuisance`` and ``labels``;
    for the figure, ``asked``: the input errors the residual asks for (:func:`asked_errors`), ``signals``
    (name -> x), ``t`` (the record's sample times [s]) and ``maneuver`` (its name).
    """
    from scipy.linalg import solve_triangular

    n = Su.shape[1] // len(channels)
    Q, _ = np.linalg.qr(solve_triangular(L, N, lower=True))

    def whiten(a):
        a = solve_triangular(L, a, lower=True)
        return a - Q @ (Q.T @ a)

    ew, Z = whiten(e), whiten(Su)
    cols, noise, labels = [], [], []
    for ci, c in enumerate(channels):
        Zc = Z[:, ci * n:(ci + 1) * n]
        for s, (x, A) in signals.items():
            cols.append(Zc @ x)
            noise.append(Zc @ A)
            labels.append((c, s))
    D = np.column_stack(cols)
    Zs = times_covariance(Z, cov_u)
    b = -np.array([np.sum(U * Zs) for U in noise])  # E[d_j . e] from the noise both share (e = data - model)
    Us = [times_covariance(U, cov_u) for U in noise]
    B = np.array([[np.sum(U * V) for V in Us] for U in noise])
    return {"DtD": D.T @ D, "Dte": D.T @ ew, "ete": float(ew @ ew), "B": B, "b": b, "rows": len(ew),
            "nuisance": N.shape[1], "labels": labels, "asked": asked_errors(Z, ew, t, channels),
            "signals": {s: x for s, (x, _) in signals.items()}, "t": t, "maneuver": maneuver}


#: the time step [s] of the input-error history the residual asks for (a piecewise-constant error per channel)
ASKED_STEP_S = 0.5


def asked_errors(Z: np.ndarray, ew: np.ndarray, t: np.ndarray, channels) -> np.ndarray:
    """The input error each channel would need, alone, to explain the record's whitened residual ``ew``: least
    squares of a piecewise-constant error (steps of ASKED_STEP_S) through the channel's whitened sensitivities
    (its block of ``Z``): estimation before modelling, with no dictionary. Every input sample, channel blocks."""
    n = len(t)
    bins = np.minimum(((t - t[0]) / ASKED_STEP_S).astype(int), max(int((t[-1] - t[0]) / ASKED_STEP_S) - 1, 0))
    Bin = np.zeros((n, int(bins.max()) + 1))
    Bin[np.arange(n), bins] = 1.0
    out = []
    for i in range(len(channels)):
        A = Z[:, i * n:(i + 1) * n] @ Bin
        out.append(Bin @ np.linalg.lstsq(A, ew, rcond=None)[0])
    return np.concatenate(out)


@dataclass
class InputPathTest:
    """The stepwise regression of the records' input errors on the dictionary (plain data; SI)."""

    terms: list = field(default_factory=list)  # selected: channel, signal, estimate, se, z, p
    screen: list = field(default_factory=list)  # the last step: every term not selected, as if added alone
    first: list = field(default_factory=list)  # the first step: every term alone (the level studies' null statistic)
    level: float = float("nan")  # per-term level alpha / dictionary size
    alpha: float = 0.01
    scale: float = float("nan")  # residual standard deviation of the whitened rows (1 when the noise model holds)
    rows: int = 0
    records: int = 0
    problems: list = field(default_factory=list)
    histories: list = field(default_factory=list)  # a few records: t, input error asked for and fitted (rad)
    play_widths: dict = field(default_factory=dict)  # channel -> width of the play signals' operator (rad)

    @property
    def consistent(self) -> bool:
        """True when no term is selected: the input errors look like the white noise the NLP assumes."""
        return not self.terms

    def describe(self) -> str:
        if self.consistent:
            best = max(self.screen, key=lambda r: abs(r["z"]), default=None)
            tail = (f"; strongest: {best['channel']} error vs {best['signal']}, p = {best['p']:.2g}" if best else "")
            return (f"input path: no signal explains the input errors (level {self.level:.2g} per term over "
                    f"{len(self.screen)} terms){tail}")
        parts = [f"{t['estimate']:+.3g} +- {t['se']:.2g}{_unit(t)} x {t['signal']} (p = {t['p']:.1e})"
                 for t in self.terms]
        return ("input path: the input errors follow the flight: "
                + "; ".join(f"{t['channel']} += {p}" for t, p in zip(self.terms, parts))
                + f" (stepwise regression on {len(self.screen) + len(self.terms)} generic terms, level "
                  f"{self.level:.2g}): the rotor does not see the recorded input, or a missing force acts as if "
                  "it did; not explained by any library effect")

    def to_dict(self) -> dict:
        return {**asdict(self), "consistent": self.consistent}

    @classmethod
    def from_dict(cls, d: dict) -> "InputPathTest":
        return cls(**{k: v for k, v in d.items() if k != "consistent"})


def _unit(t: dict) -> str:
    """The unit of a term's estimate (input rad per signal unit), with a leading space; none for rad per rad."""
    su = SIGNALS[t["signal"]][1]
    return "" if su == "rad" else " s" if su == "rad/s" else f" rad/({su})"


#: records whose input-error histories the result keeps (those the selected terms move most), and at what rate [Hz]
HISTORY_RECORDS = 3
HISTORY_RATE_HZ = 10.0


def histories(test: InputPathTest, blocks: list, channels, keep: int = HISTORY_RECORDS) -> list:
    """The input-error histories of the ``keep`` records the selected terms move most: per record its ``maneuver``,
    ``t`` [s] and, per channel c, ``asked_<c>`` (the error the residual asks for, :func:`asked_errors`)
    and ``fitted_<c>`` (the selected terms' sum), each record's mean removed (the nuisance takes any constant)."""
    if not test.terms:
        return []
    out = []
    for blk in blocks:
        t, n = blk["t"], len(blk["t"])
        k = slice(None, None, max(int(round(1.0 / (HISTORY_RATE_HZ * float(np.median(np.diff(t)))))), 1)
                  if n > 1 else 1)
        row = {"maneuver": blk["maneuver"], "t": [float(v) for v in t[k]]}
        size = 0.0
        fitted = input_error(test.terms, blk["signals"], n)
        for i, c in enumerate(channels):
            fit = fitted[c]
            asked = blk["asked"][i * n:(i + 1) * n]
            row[f"asked_{c}"] = [float(v) for v in (asked - asked.mean())[k]]
            row[f"fitted_{c}"] = [float(v) for v in (fit - fit.mean())[k]]
            size += float(np.std(fit))
        out.append((size, row))
    return [r for _, r in sorted(out, key=lambda x: -x[0])[:keep]]


def _fit(st: dict, idx: list) -> tuple[np.ndarray, np.ndarray, float, int] | None:
    """Corrected least squares on the terms ``idx`` of the pooled sums ``st``: estimates, standard errors,
    residual variance and its degrees of freedom; None when the noise-free part of the terms' information is not
    positive definite (a signal that is mostly input noise carries nothing)."""
    dof = max(st["rows"] - st["nuisance"] - len(idx), 1)
    if not idx:
        return np.zeros(0), np.zeros(0), st["ete"] / dof, dof
    ix = np.ix_(idx, idx)
    M, G, h = st["DtD"][ix], st["DtD"][ix] - st["B"][ix], st["Dte"][idx] - st["b"][idx]
    try:
        np.linalg.cholesky(G)
    except np.linalg.LinAlgError:
        return None
    coef = np.linalg.solve(G, h)
    rss = st["ete"] - 2 * coef @ st["Dte"][idx] + coef @ M @ coef
    s2 = max(float(rss), 1e-300) / dof
    Gi = np.linalg.inv(G)
    cov = s2 * Gi @ M @ Gi
    return coef, np.sqrt(np.maximum(np.diag(cov), 0.0)), s2, dof


def input_path_test(blocks: list, alpha: float = 0.01, max_terms: int = MAX_TERMS) -> InputPathTest:
    """Forward selection with a backward check over the dictionary of every record in ``blocks``
    (:func:`record_block`), pooled."""
    if not blocks:
        return InputPathTest(alpha=alpha, problems=["no record to test"])
    labels = blocks[0]["labels"]
    st = {k: sum(b[k] for b in blocks) for k in ("DtD", "Dte", "ete", "B", "b", "rows", "nuisance")}
    level = alpha / len(labels)

    def pvals(fit):
        coef, se, _, dof = fit
        z = np.where(se > 0, coef / np.where(se > 0, se, 1.0), 0.0)
        return z, 2 * stats.t.sf(np.abs(z), dof)

    def table(chosen):
        out = {}
        for j in range(len(labels)):
            if j in chosen:
                continue
            fit = _fit(st, chosen + [j])
            if fit is None:
                continue
            z, p = pvals(fit)
            out[j] = (float(fit[0][-1]), float(fit[1][-1]), float(z[-1]), float(p[-1]))
        return out

    def rows(tab):
        return [{"channel": labels[j][0], "signal": labels[j][1], "estimate": v[0], "se": v[1], "z": v[2], "p": v[3]}
                for j, v in tab.items()]

    chosen: list = []
    first = rows(table([]))
    for _ in range(max_terms):
        tab = table(chosen)
        if not tab:
            break
        j = max(tab, key=lambda k: abs(tab[k][2]))
        if tab[j][3] >= level:
            break
        chosen.append(j)
        while len(chosen) > 1:  # backward check: a term the new one made redundant leaves
            fit = _fit(st, chosen)
            p = pvals(fit)[1] if fit is not None else np.ones(len(chosen))
            worst = int(np.argmax(p))
            if p[worst] < level or chosen[worst] == j:
                break
            chosen.pop(worst)
    terms = []
    fit = _fit(st, chosen)
    if chosen:
        z, p = pvals(fit)
        terms = [{"channel": labels[j][0], "signal": labels[j][1], "estimate": float(fit[0][k]),
                  "se": float(fit[1][k]), "z": float(z[k]), "p": float(p[k])} for k, j in enumerate(chosen)]
    return InputPathTest(terms=terms, screen=rows(table(chosen)), first=first, level=level, alpha=alpha,
                         scale=math.sqrt(fit[2]), rows=st["rows"], records=len(blocks))
