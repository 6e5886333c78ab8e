"""Attribution: which candidate extension explains the residual of an identified model?

The method is a score (Lagrange-multiplier) test of each candidate's strength
kappa_j at zero, with the candidate's sensitivities projected off those of the
already-identified parameters (model_spec.md section 4.8):

    residuals e = data - model at the estimate: every configured time output
        of every maneuver and every trim channel of every trim point (SI);
    weights W = diag(1/R_o) per time output and diag(1/s_c^2) per trim
        channel, both *as estimated* (mean square residual per output /
        channel, the diagonal ML estimate of the output-error likelihood);
    S = d(outputs)/d(identified parameters), s_j = d(outputs)/d(kappa_j)
        (central differences of the float model, simulation.sensitivity);
    s~_j = s_j - S (S^T W S)^-1 S^T W s_j   (what the identified parameters
        cannot absorb), g_j = s~_j^T W e, F_j = s~_j^T W s~_j,
    LM_j = g_j^2 / F_j ~ chi-square(1) if the effect is absent,
    kappa_j,hat = g_j / F_j (one Gauss-Newton step from zero).

For a strength that is physical with one sign only (a time constant or a
downwash factor, lower bound 0) the test is one-sided: a score of the wrong
sign gives p = 1, otherwise p = chi2.sf(LM)/2.

Decision rule (documented in docs/model.md):
- significant: p < alpha / n_candidates (Bonferroni over the library,
  alpha = 0.01 by default: with 10 candidates and the white test LM > 10.8);
- accepted: the top candidate (by LM) is significant and its LM is at least
  ``ratio`` (default 2) times the runner-up's;
- robust (default): the score's variance by batch means over segments
  instead of F; that estimate has few degrees of freedom on short records
  (about one per segment the candidate's signal occupies), so LM is referred
  to F(1, df) with Satterthwaite's df = F^2 / sum_s F_s^2 - 1 (F_s: segment
  s's share of F) instead of chi-square(1). The df decides significance only;
  the ranking and the ratio rule stay on LM, the squared signal-to-noise of
  the one-step estimate (far in the tail, F(1, df) would rank a strong effect
  measured over few segments below a weaker one measured over many);
- confounded: top and runner-up within that ratio and their projected
  sensitivity directions correlate (|rho| >= ``confound_corr``, 0.7): the
  data cannot separate them, both are reported, none is picked;
- ambiguous: within the ratio but not correlated: reported, none picked;
- none: nothing significant; the residual's signature is reported.
A candidate whose sensitivity is mostly absorbed by an identified parameter
(projected energy F_j below 10 % of the raw one) is flagged with the
parameter it looks like (e.g. flapping lag vs Iyy).

The residuals used here are those of the same float simulation the
sensitivities linearise (``Sensitivities.y_time`` / ``y_trim``), so that the
test is consistent; the residual *analysis* (shapes, spectra) belongs to
:mod:`pyomo_heli.diagnosis.residuals`.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import pandas as pd
from scipy import stats
from scipy.linalg import solve_triangular

from ..physics.model import HelicopterModel
from ..nlp.objectives import input_error_models, noise_sigmas
from ..simulation.compiled import simulate_outputs
from ..simulation.sensitivity import sensitivities
from ..simulation.trim import trim_float
from ..settings.identification import ALPHA, CONFOUND_CORR, RATIO  # noqa: F401 - the [loop] defaults, declared there
from .candidates import CANDIDATES, as_candidate
from .innovations import input_noise_factor


ABSORBED = 0.10
SEGMENT_S = 1.0


@dataclass
class Attribution:
    """The outcome of one attribution: a score table and a decision.

    ``scores``: one row per candidate (name, strength, LM, df = degrees of
    freedom of the batch-means variance (inf for the white test), LM_needed =
    the LM at which it would be significant, p_value, significant,
    kappa_hat, kept = F_proj/F_raw, like = the identified parameter its raw
    sensitivity correlates with most, like_corr, trim_share = part of F_proj
    coming from the trims), sorted by LM (wrong-sign one-sided scores last).
    ``decision``: accepted | confounded | ambiguous | none.
    """

    scores: pd.DataFrame
    decision: str
    accepted: str | None
    threshold: float
    alpha: float
    ratio: float
    confound_corr: float
    confounded_pairs: list = field(default_factory=list)
    message: str = ""
    signature: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["scores"] = self.scores.to_dict(orient="records")
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "Attribution":
        d = dict(d)
        d["scores"] = pd.DataFrame(d["scores"])
        return cls(**d)

    def accepted_row(self) -> dict | None:
        if self.accepted is None:
            return None
        return self.scores.set_index("name").loc[self.accepted].to_dict()

    def __str__(self) -> str:
        cols = ["name", "LM", "df", "LM_needed", "p_value", "significant", "kappa_hat", "kept", "like", "like_corr",
                "trim_share"]
        lines = [f"score test: significant when p < {self.alpha:g}/{len(self.scores)} (LM > LM_needed; "
                 f"{self.threshold:.3g} for chi-square(1)); accept when LM >= {self.ratio:g} x runner-up's",
                 self.scores[cols].to_string(index=False, float_format=lambda x: f"{x:.4g}"),
                 f"decision: {self.decision}: {self.message}"]
        return "\n".join(lines)


def _stack(sens, time_outputs, trim_outputs, col: int | None = None):
    parts = [sens.time[o] for o in time_outputs] + [sens.trim[c] for c in trim_outputs]
    M = np.vstack(parts) if parts else np.zeros((0, len(sens.names)))
    return M if col is None else M[:, col]


def residual_vector(sens, data, time_outputs, trim_outputs) -> tuple[np.ndarray, np.ndarray, list]:
    """Data minus the nominal simulation of ``sens``, stacked like the sensitivities.

    Returns (e, w, groups): residuals, weights (1 / mean square per output or
    trim channel, the ML estimate), and the (label, slice) of each block.
    """
    e, w, groups, k = [], [], [], 0
    for o in time_outputs:
        meas = np.concatenate([mv.data[o].to_numpy(dtype=float) for mv in data.maneuvers])
        r = meas - sens.y_time[o]
        e.append(r)
        w.append(np.full(r.size, 1.0 / max(np.mean(r**2), 1e-30)))
        groups.append((f"time:{o}", slice(k, k + r.size)))
        k += r.size
    for c in trim_outputs:
        r = data.trims[c].to_numpy(dtype=float) - sens.y_trim[c]
        e.append(r)
        w.append(np.full(r.size, 1.0 / max(np.mean(r**2), 1e-30)))
        groups.append((f"trim:{c}", slice(k, k + r.size)))
        k += r.size
    return np.concatenate(e), np.concatenate(w), groups


def _signature(e, w, groups) -> dict:
    """RMS per block and lag-1 autocorrelation (whiteness) of each time block."""
    sig = {}
    for label, sl in groups:
        r = e[sl]
        d = {"rms": float(np.sqrt(np.mean(r**2)))}
        if label.startswith("time") and r.size > 2:
            rc = r - r.mean()
            d["lag1_autocorrelation"] = float(np.dot(rc[1:], rc[:-1]) / max(np.dot(rc, rc), 1e-300))
        d["mean"] = float(r.mean())
        sig[label] = d
    return sig


def input_offset_columns(model: HelicopterModel, data, time_outputs, n_trim_rows: int, substeps: int = 2,
                         delta: float = 1e-4) -> np.ndarray:
    """Output response to a constant offset of each input, one column per maneuver and input (stacked rows).

    The model replays a maneuver with inputs = trim + (measured - first measured sample), so the
    noise of the first sample acts as a constant input error over the whole record: a nuisance
    direction the score test must not mistake for an effect. One-sided differences, ``delta`` rad.
    """
    cols = []
    n_per = [len(mv.data) for mv in data.maneuvers]
    starts = np.cumsum([0] + n_per)
    for i, mv in enumerate(data.maneuvers):
        t = mv.data["t"].to_numpy()
        tp = trim_float(model, mv.trim_speed)
        inc = mv.increments()
        base = simulate_outputs(model, tp, t, inc, time_outputs, substeps)
        for k in ("col", "lon"):
            shifted = {c: v + (delta if c == k else 0.0) for c, v in inc.items()}
            if k not in shifted:
                shifted[k] = np.full(t.size, delta)
            sim = simulate_outputs(model, tp, t, shifted, time_outputs, substeps)
            col = []
            for o in time_outputs:
                block = np.zeros(starts[-1])
                block[starts[i]:starts[i + 1]] = (sim[o] - base[o]) / delta
                col.append(block)
            col.append(np.zeros(n_trim_rows))
            cols.append(np.concatenate(col))
    return np.array(cols).T if cols else np.zeros((starts[-1] * len(time_outputs) + n_trim_rows, 0))


def segment_ids(data, time_outputs, n_trims: int, trim_outputs, segment_s: float) -> np.ndarray:
    """Segment of every stacked row for the batch-means variance: per maneuver, ``segment_s`` long
    stretches (all outputs of a stretch together); every trim point (all its channels) on its own."""
    ids, nxt = [], 0
    for mv in data.maneuvers:
        t = mv.data["t"].to_numpy()
        k = np.floor((t - t[0]) / segment_s).astype(int)
        ids.append(nxt + k)
        nxt += int(k.max()) + 1 if k.size else 0
    time_ids = np.concatenate(ids) if ids else np.zeros(0, int)
    trim_ids = nxt + np.arange(n_trims)
    return np.concatenate([time_ids] * len(time_outputs) + [trim_ids] * len(trim_outputs))


def _input_error_whitening(model: HelicopterModel, data, time_outputs, w, seg, input_errors, noise_sigma,
                           substeps: int, input_error_ar: int = 0):
    """Whitening of the stacked rows when the measured inputs are noisy (errors in variables).

    The NLP estimates one error per input sample with known sigmas; to first order, eliminating those
    errors leaves the time residuals of maneuver m with covariance ``V_m = R + S_u Sigma_u S_u^T``
    (``S_u``: exact output sensitivities to every input sample, ``R`` and ``Sigma_u`` the known sensor
    variances, from ``noise_sigma`` or the records' lead-in as the NLP takes them). Its lower Cholesky
    factor with the rows in time order (all outputs of sample k before sample k+1) whitens them as
    innovations: whitened row k depends on samples up to k only, so the batch means over time segments
    stay local. Trim rows keep their weights ``w``. Returns ``(whiten, seg)``: the function applied to
    every stacked vector or column block, and each whitened row's segment. ``input_error_ar``: Sigma_u of the
    NLP's AR model of the input errors (``[objectives] input_error_ar``; 0: independent errors).
    """
    sigma = noise_sigmas(data.maneuvers, (*time_outputs, *input_errors), noise_sigma, input_record=True)
    models = input_error_models(data.maneuvers, input_errors, input_error_ar, input_record=True)
    n_out = len(time_outputs)
    n_per = [len(mv.data) for mv in data.maneuvers]
    n_time = sum(n_per)
    starts = np.cumsum([0] + n_per)
    blocks, seg = [], seg.copy()
    for i, mv in enumerate(data.maneuvers):
        n = len(mv.data)
        # stacked row of (sample k, output j), time order
        idx = (np.arange(n_out)[None, :] * n_time + starts[i] + np.arange(n)[:, None]).ravel()
        blocks.append((idx, input_noise_factor(model, mv, time_outputs, input_errors, sigma, substeps,
                                               models=models)[2]))
        seg[idx] = seg[starts[i] + np.arange(n)].repeat(n_out)
    time_rows = n_out * n_time
    sw_trim = np.sqrt(w[time_rows:])

    def whiten(x):
        out = np.empty_like(x, dtype=float)
        for idx, L in blocks:
            out[idx] = solve_triangular(L, x[idx], lower=True)
        out[time_rows:] = x[time_rows:] * (sw_trim[:, None] if x.ndim == 2 else sw_trim)
        return out
    return whiten, seg


def score_column(A: np.ndarray, e: np.ndarray, b: np.ndarray, seg: np.ndarray, one_sided: bool,
                 variance: str = "batch") -> dict:
    """The score test of one candidate's strength at zero, every array whitened (module docstring).

    ``A``: the nuisance columns (identified parameters' sensitivities, input offsets), ``e``: the residual,
    ``b``: the candidate's sensitivity, ``seg``: the segment of every row. b~ = b - A A^+ b, g = b~.e,
    F = b~.b~, kappa_hat = g / F, LM = g^2 / var(g) with the score's variance by ``variance``:

    - ``white``: F, LM referred to chi-square(1) (df infinite);
    - ``batch``: batch means over the segments of u_i = b~_i (e_i - kappa_hat b~_i), divided by 1 - sum_s F_s^2 / F^2
      (taking kappa_hat out shrinks them by that factor under no effect), referred to F(1, df),
      df = F^2 / sum_s F_s^2 - 1 (Satterthwaite, F_s: segment s's share of F);
    - ``hc3``: as batch, each u_i divided by (1 - h_ii), h_ii the row's leverage in the least-squares fit of
      [A, b]; with one segment per row the HC3 sandwich, for few rows and a few fitted columns.

    One-sided strength: a score of the wrong sign gives p = 1, otherwise p is halved. Returns ``projected``
    (b~), ``F``, ``F_raw`` (b.b), ``g``, ``kappa_hat``, ``LM``, ``LM_white`` (g^2 / F), ``df`` and ``p_value``.
    """
    if variance not in ("white", "batch", "hc3"):
        raise ValueError(f"variance = {variance!r}: choose 'white', 'batch' or 'hc3'")
    coef = np.linalg.lstsq(A, b, rcond=None)[0] if A.shape[1] else np.zeros(0)
    bt = b - A @ coef
    F, F_raw = float(bt @ bt), float(b @ b)
    g = float(bt @ e)
    kappa = g / F if F > 0 else 0.0
    df = np.inf
    if variance != "white" and F > 0:
        u = bt * (e - kappa * bt)  # score contributions, the candidate's fit removed from the residual
        if variance == "hc3":
            X = np.column_stack([A, b])
            u = u / np.maximum(1.0 - np.einsum("ij,ji->i", X, np.linalg.pinv(X)), 1e-6)
        var = float(np.sum(np.bincount(seg, weights=u) ** 2))
        # the variance estimate is a weighted sum of one chi-square(1) per segment, weights = the segments'
        # shares of F: its effective degrees of freedom (Satterthwaite), less one for kappa_hat
        v = np.bincount(seg, weights=bt * bt)
        share = float(np.sum(v * v)) / (F * F)  # 1 / Satterthwaite's df
        df = max(1.0 / share - 1.0, 1.0)
        if variance == "batch":
            # taking kappa_hat out of the residual leaves E[var] = F (1 - share) under no effect, not F (with B
            # equal segments LM would be B/(B-1) F(1, B-1)): scaled back, as the validation rule's batch means are
            # (hc3's leverage does this row by row)
            var /= max(1.0 - share, 1e-12)
        lm = g * g / var if var > 0 else 0.0
    else:
        lm = g * g / F if F > 0 else 0.0
    ref = stats.f(1, df) if np.isfinite(df) else stats.chi2(1)
    p = 1.0 if one_sided and kappa < 0 else float(ref.sf(lm)) * (0.5 if one_sided else 1.0)
    return {"projected": bt, "F": F, "F_raw": F_raw, "g": g, "kappa_hat": kappa, "LM": lm,
            "LM_white": g * g / F if F > 0 else 0.0, "df": df, "p_value": p}


def decide(names, evidence, significant, projected: dict, ratio: float = RATIO,
           confound_corr: float = CONFOUND_CORR, among: str = "all") -> dict:
    """The decision rule (module docstring) on candidates sorted by ``evidence`` (LM; 0 for a wrong-sign
    one-sided score), highest first: ``none`` if the top is not ``significant``; ``accepted`` if it is and its
    evidence is at least ``ratio`` times the runner-up's; else ``confounded`` when their ``projected``
    sensitivities correlate (|rho| >= ``confound_corr``), ``ambiguous`` when not. ``among``: ``all`` (the
    maneuver loop) ranks every candidate; ``significant`` (the trim loop) only the significant ones, so the top
    is the strongest significant candidate and the runner-up the next significant one. Returns ``decision``,
    ``rho`` (top and runner-up, or None) and ``pairs``: every pair of significant candidates that correlate."""
    if among not in ("all", "significant"):
        raise ValueError(f"among = {among!r}: choose 'all' or 'significant'")
    if among == "significant":
        keep = [i for i, s in enumerate(significant) if s]
        names, evidence, significant = ([seq[i] for i in keep] for seq in (names, evidence, significant))

    def corr(a, b):
        x, y = projected[a], projected[b]
        return float(x @ y / np.sqrt(max((x @ x) * (y @ y), 1e-300)))

    sig = [n for n, s in zip(names, significant) if s]
    pairs = [(a, b, corr(a, b)) for i, a in enumerate(sig) for b in sig[i + 1:] if abs(corr(a, b)) >= confound_corr]
    rho = None
    if not names or not significant[0]:
        decision = "none"
    elif len(names) < 2 or evidence[1] * ratio <= evidence[0]:
        decision = "accepted"
    else:
        rho = corr(names[0], names[1])
        decision = "confounded" if abs(rho) >= confound_corr else "ambiguous"
    return {"decision": decision, "rho": rho, "pairs": pairs}


def none_message(scores: pd.DataFrame, level: float) -> str:
    """The message of a "none" decision: the top candidate by LM (``scores`` sorted) is not significant. Candidates
    significant on their own df but ranked below it are named ("not decided"), not left out of the message."""
    top = scores.iloc[0]
    below = [f"{r.name} (LM {r.evidence:.3g}, df {r.df:.3g}, p = {r.p_value:.2g})"
             for r in scores[scores["significant"]].itertuples()]
    return (f"top candidate not significant ({top['name']}: LM {top.evidence:.3g}, p = {top.p_value:.2g} >= "
            f"{level:.2g}, needs LM > {top.LM_needed:.3g} with df {top.df:.3g}); "
            + (f"not decided: {', '.join(below)} {'is' if len(below) == 1 else 'are'} significant below it; "
               if below else "")
            + "any remaining residual is unexplained by the library, signature attached")


def attribute(model: HelicopterModel, identified, data, time_outputs, trim_outputs, candidates=None,
              alpha: float = ALPHA, ratio: float = RATIO, confound_corr: float = CONFOUND_CORR,
              substeps: int = 2, robust: bool = True, segment_s: float = SEGMENT_S, input_errors=(),
              noise_sigma: dict | None = None, variance: str = "batch", input_error_ar: int = 0) -> Attribution:
    """Score every candidate (default: the whole library minus those already in ``model``): library names or
    extension objects (:func:`~.candidates.as_candidate`).

    ``model`` carries the identified values; ``identified`` are the free
    parameter names; ``data`` an :class:`~pyomo_heli.nlp.identification.IdentificationData`.
    ``robust``: also project off the input-offset nuisance of every maneuver and estimate the
    score's variance by batch means over ``segment_s`` stretches (coloured residuals); False gives
    the plain white-noise score test of model_spec.md 4.8.
    ``variance``: with ``robust``, "batch" (the batch means above) or "white" (the input-offset nuisance
    projected off, but the score's variance taken as F, df infinite).
    ``input_errors``, ``noise_sigma``: the NLP's errors-in-variables settings (``NLPOptions``). With input
    errors the time residuals are weighted by the covariance the measured inputs' noise gives them,
    ``V_m = R + S_u,m Sigma_u S_u,m^T`` per maneuver (the input errors eliminated, module docstring),
    instead of by their mean squares; ``input_error_ar``: Sigma_u of the NLP's AR model of the input errors.
    """
    if variance not in ("batch", "white"):
        raise ValueError(f"variance = {variance!r}: choose 'batch' or 'white'")
    have = {e.name for e in model.extensions}
    cands = [c for c in map(as_candidate, candidates or list(CANDIDATES)) if c.name not in have]
    if not cands:
        raise ValueError("no candidate left to score: every candidate is already in the model")
    full = HelicopterModel(parameters=model.parameters, extensions=tuple(model.extensions) + tuple(cands))
    time_outputs, trim_outputs = list(time_outputs), list(trim_outputs)
    speeds = list(data.trims["V"]) if trim_outputs else []
    common = dict(maneuvers=data.maneuvers, time_outputs=time_outputs, trim_speeds=speeds, trim_out=trim_outputs,
                  substeps=substeps)
    default = [c for c in cands if getattr(c, "score_step", None) is None]
    base = sensitivities(full, list(identified) + [c.strength for c in default], **common)
    S = _stack(base, time_outputs, trim_outputs)[:, : len(identified)]
    cols = {c.strength: _stack(base, time_outputs, trim_outputs, len(identified) + i) for i, c in enumerate(default)}
    for c in cands:
        if getattr(c, "score_step", None) is not None:
            scale = full.parameters.spec(c.strength).scale or 1.0
            s = sensitivities(full, [c.strength], rel_step=c.score_step / scale, **common)
            cols[c.strength] = _stack(s, time_outputs, trim_outputs, 0)
    e, w, groups = residual_vector(base, data, time_outputs, trim_outputs)
    n_trim = sum(sl.stop - sl.start for lbl, sl in groups if lbl.startswith("trim"))
    seg = segment_ids(data, time_outputs, len(speeds), trim_outputs, segment_s)
    if robust:
        nuis = input_offset_columns(full, data, time_outputs, n_trim, substeps)
        S_proj = np.hstack([S, nuis])
    else:
        S_proj = S
    if tuple(input_errors) and time_outputs:
        whiten, seg = _input_error_whitening(full, data, time_outputs, w, seg, tuple(input_errors), noise_sigma,
                                             substeps, input_error_ar)
    else:
        sw = np.sqrt(w)

        def whiten(x):
            return x * (sw[:, None] if x.ndim == 2 else sw)
    A, ew = whiten(S_proj), whiten(e)
    n_id = S.shape[1]
    trim_rows = slice(len(e) - n_trim, len(e))

    proj, rows = {}, []
    n_cands = len(cands)
    for c in cands:
        b = whiten(cols[c.strength])
        one_sided = getattr(c, "one_sided", False)
        sc = score_column(A, ew, b, seg, one_sided, variance if robust else "white")
        bt, F, df = sc["projected"], sc["F"], sc["df"]
        ref = stats.f(1, df) if np.isfinite(df) else stats.chi2(1)
        half = 0.5 if one_sided else 1.0
        # the LM this candidate needs to be significant (its own df; one-sided: the two-sided quantile of 2 x level)
        lm_needed = float(ref.isf(alpha / n_cands / half))
        corr_id = [abs(float(b @ A[:, k]) / np.sqrt(max(sc["F_raw"] * float(A[:, k] @ A[:, k]), 1e-300)))
                   for k in range(n_id)]
        k_like = int(np.argmax(corr_id)) if corr_id else None
        proj[c.name] = bt
        rows.append({"name": c.name, "strength": c.strength, "LM": sc["LM"], "df": df, "LM_needed": lm_needed,
                     "p_value": sc["p_value"],
                     # the white-noise LM (variance F): LM / LM_white is the robust variance's correction factor
                     "LM_white": sc["LM_white"],
                     "kappa_hat": sc["kappa_hat"],
                     "kept": F / sc["F_raw"] if sc["F_raw"] > 0 else 0.0,
                     "like": list(identified)[k_like] if k_like is not None else "",
                     "like_corr": corr_id[k_like] if k_like is not None else 0.0,
                     "trim_share": float(bt[trim_rows] @ bt[trim_rows]) / F if F > 0 else 0.0})
    n = len(cands)
    threshold = float(stats.chi2.isf(alpha / n, 1))
    level = alpha / n
    scores = pd.DataFrame(rows)
    scores["significant"] = scores["p_value"] < level
    # rank by evidence = LM (the squared signal-to-noise of the one-step estimate); a wrong-sign one-sided
    # score has none. Significance comes from the p-value (its own df), the ranking and the ratio rule from LM.
    scores["evidence"] = np.where(scores["p_value"] < 1.0, scores["LM"], 0.0)
    scores = scores.sort_values("evidence", ascending=False).reset_index(drop=True)

    rule = decide(list(scores["name"]), list(scores["evidence"]), list(scores["significant"]), proj, ratio,
                  confound_corr)
    pairs = rule["pairs"]
    top = scores.iloc[0]
    second = scores.iloc[1] if len(scores) > 1 else None
    accepted, signature = None, {}
    if rule["decision"] == "none":
        decision = "none"
        signature = _signature(e, w, groups)
        message = none_message(scores, level)
    elif rule["decision"] == "accepted":
        decision, accepted = "accepted", str(top["name"])
        runner = f"; runner-up {second['name']} LM {second.evidence:.3g}" if second is not None else ""
        message = (f"{top['name']} LM {top.evidence:.3g} (df {top.df:.3g}, p = {top.p_value:.2g}){runner}; "
                   f"estimated {top.strength} = {top.kappa_hat:.4g}")
        if top.kept < ABSORBED:
            message += (f"; note: {100 * (1 - top.kept):.0f} % of its signal is absorbed by the identified "
                        f"parameters (most like {top.like}, |rho| = {top.like_corr:.2f})")
    else:
        decision, rho = rule["decision"], rule["rho"]
        message = (f"{top['name']} (LM {top.evidence:.3g}) and {second['name']} (LM {second.evidence:.3g}) are within "
                   f"a factor {ratio:g}; projected sensitivities correlate rho = {rho:.2f}: "
                   + ("the data cannot separate them, none is picked" if decision == "confounded"
                      else "two different signatures both significant, none is picked"))
        signature = _signature(e, w, groups)
    return Attribution(scores=scores.drop(columns="evidence"), decision=decision, accepted=accepted,
                       threshold=threshold, alpha=alpha, ratio=ratio, confound_corr=confound_corr,
                       confounded_pairs=[list(p) for p in pairs], message=message, signature=signature)
