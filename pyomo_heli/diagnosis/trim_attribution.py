"""The score test of the candidate effects on trim residuals alone, and the residual's shape over speed.

The candidates' sensitivities are central differences of the float model's recorded trims
(:mod:`pyomo_heli.simulation.recorded_trims`); the test itself and its decision rule are those of
:mod:`pyomo_heli.diagnosis.attribution` (:func:`~pyomo_heli.diagnosis.attribution.score_column`,
:func:`~pyomo_heli.diagnosis.attribution.decide`), every trim point its own segment.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from ..dataset.schema import KT, TRIM_CHANNELS
from ..physics.discrepancy import generic_term, is_generic
from ..physics.model import HelicopterModel
from ..physics.parameters import DEG
from ..simulation.recorded_trims import jacobian, predict
from .attribution import ALPHA, CONFOUND_CORR, RATIO, decide, score_column
from .candidates import CANDIDATES, make_candidate


def score_trims(model: HelicopterModel, conventions, pts: pd.DataFrame, identified, candidates=None,
                alpha: float = ALPHA, ratio: float = RATIO, confound_corr: float = CONFOUND_CORR,
                variance: str = "hc3") -> dict:
    """Score test of each candidate's strength at zero on the trim residuals of ``pts`` (decision rule of
    :func:`pyomo_heli.diagnosis.attribution.decide` among the significant candidates: level alpha / number of
    testable candidates, ratio, confounding).

    e = data - model [deg], S = d(trims)/d(identified), s_j = d(trims)/d(kappa_j) (one-sided forward
    difference at zero for a one-sided strength), all whitened by the common residual variance
    s^2 = e.e / (n - p); :func:`~pyomo_heli.diagnosis.attribution.score_column` projects s_j off S and gives
    g, F and kappa_hat = g / F. The score's variance (``variance``):

    - ``hc3`` (default): sandwich over the points, each point's residual r_i = e_i - kappa_hat s~_i divided by
      (1 - h_ii), h_ii its leverage in the fit of [S, s_j]: LM = (s~.e)^2 / sum_i (s~_i r_i / (1 - h_ii))^2;
    - ``hc0``: the same without the leverage (attribution's batch means with one segment per point);
    - ``white``: the classical F test of the added column, (SSR_0 - SSR_1) / (SSR_1 / (n - p - 1)).

    hc3 and hc0 are referred to F(1, df), df = F^2 / sum_i (s~_i^2 / s^2)^2 - 1 (Satterthwaite), white to
    F(1, n - p - 1). With tens of trim points and a few identified parameters the leverage matters: on 20
    noise-only synthetic trim sets (``python studies/score_test_level.py --trims --seeds 0-19``) 3.8 % of the hc3
    p-values fell below 0.05, 7.5 % of the hc0 ones. Every row keeps all three p-values (``p_by_variance``).
    A candidate whose trims do not move (or whose signal the identified parameters absorb) is not testable.
    """
    if variance not in ("hc3", "hc0", "white"):
        raise ValueError(f"variance = {variance!r}: choose 'hc3', 'hc0' or 'white'")
    have = {e.name for e in model.extensions}
    names = [n for n in (candidates or list(CANDIDATES)) if n not in have]
    y = predict(model, conventions, pts["V"], pts["channel"])
    e = (pts["value"].to_numpy(dtype=float) - y) / DEG
    S = jacobian(model, conventions, pts, identified) / DEG
    s2 = max(float(e @ e) / max(len(e) - S.shape[1], 1), 1e-24)  # floor: noise-free data fit exactly
    sw = 1.0 / np.sqrt(s2)
    A, ew, seg = S * sw, e * sw, np.arange(len(e))  # whitened; every point its own segment
    n_pts, k = len(e), S.shape[1] + 1
    rows, proj, testable = [], {}, []
    for n in names:
        cand = make_candidate(n)
        full = HelicopterModel(parameters=model.parameters, extensions=tuple(model.extensions) + (cand,))
        spec = full.parameters.spec(cand.strength)
        h = 1e-3 * (spec.scale or 1.0)
        base = predict(full, conventions, pts["V"], pts["channel"])
        up = predict(full.with_parameters(**{cand.strength: h}), conventions, pts["V"], pts["channel"])
        if cand.one_sided:
            s = (up - base) / h / DEG
        else:
            dn = predict(full.with_parameters(**{cand.strength: -h}), conventions, pts["V"], pts["channel"])
            s = (up - dn) / (2 * h) / DEG
        # the raw sensitivity per point [deg per unit strength], points as in the returned "points"
        row = {"name": n, "strength": cand.strength, "signature": cand.signature, "sensitivity_deg": s.tolist()}
        sc = {v: score_column(A, ew, s * sw, seg, cand.one_sided, v) for v in ("batch", "hc3")}
        F, raw = sc["hc3"]["F"], sc["hc3"]["F_raw"]
        if raw < 1e-12 or F < 1e-9 * raw:
            row.update(testable=False, LM=0.0, df=float("nan"), p_value=1.0, kappa_hat=0.0,
                       kept=0.0 if raw > 0 else float("nan"),
                       note="no trim signature" if raw < 1e-12 else "absorbed by the identified parameters")
            rows.append(row)
            continue
        kappa, st = sc["hc3"]["kappa_hat"], sc["hc3"]["projected"]
        # classical F test of the added column (exact for a linear model with one Gaussian noise level)
        r = ew - kappa * st  # residual with the candidate fitted too
        ssr1 = float(r @ r)
        lm_white = (ssr1 and (float(ew @ ew) - ssr1) / (ssr1 / max(n_pts - k, 1))) or 0.0
        p_white = float(stats.f(1, max(n_pts - k, 1)).sf(lm_white))
        p_white = 1.0 if cand.one_sided and kappa < 0 else p_white * (0.5 if cand.one_sided else 1.0)
        ps = {"white": p_white, "hc0": sc["batch"]["p_value"], "hc3": sc["hc3"]["p_value"]}
        lms = {"white": lm_white, "hc0": sc["batch"]["LM"], "hc3": sc["hc3"]["LM"]}
        df = float(max(n_pts - k, 1)) if variance == "white" else sc["hc3"]["df"]
        row.update(p_by_variance=ps)
        proj[n] = st
        testable.append(n)
        row.update(testable=True, LM=lms[variance], df=df, p_value=ps[variance], kappa_hat=kappa, kept=F / raw,
                   note="")
        rows.append(row)
    n_test = max(len(testable), 1)
    level = alpha / n_test
    for r in rows:
        r["significant"] = bool(r["testable"] and r["p_value"] < level)
        r["evidence"] = r["LM"] if r["testable"] and r["p_value"] < 1.0 else 0.0
    rows.sort(key=lambda r: -r["evidence"])
    rule = decide([r["name"] for r in rows], [r["evidence"] for r in rows], [r["significant"] for r in rows], proj,
                  ratio, confound_corr, among="significant")
    decision, accepted = rule["decision"], None
    sig = [r for r in rows if r["significant"]]
    top, second = (sig + [None, None])[:2]
    if decision == "none":
        best = rows[0] if rows else None
        message = (f"no candidate significant at p < {alpha:g}/{n_test}" +
                   (f" (best: {best['name']}, LM {best['LM']:.3g}, p = {best['p_value']:.2g})" if best else ""))
    elif decision == "accepted":
        accepted = top["name"]
        message = (f"{top['name']} LM {top['LM']:.3g} (p = {top['p_value']:.2g}), "
                   f"{top['strength']} ~ {top['kappa_hat']:.4g}")
    else:
        message = (f"{top['name']} (LM {top['LM']:.3g}) and {second['name']} (LM {second['LM']:.3g}) within a "
                   f"factor {ratio:g}, projected sensitivities rho = {rule['rho']:.2f}: none is picked")
    for r in rows:
        r.pop("evidence")
    return {"decision": decision, "accepted": accepted, "message": message, "level": level, "alpha": alpha,
            "n_testable": len(testable), "scores": rows,
            "points": {"speed_kt": (pts["V"] / KT).tolist(), "channel": pts["channel"].tolist()}}


def discovery_decision(score: dict, generic_p_given, alpha: float = ALPHA) -> dict:
    """Structure determination on trims (``[loop] discovery``): the decision over a library of physical candidates
    and generic discrepancy terms scored together by :func:`score_trims` (Bonferroni level alpha / L).

    - nothing significant: nothing is added; the best generic term (largest LM) is reported as what is left;
    - a significant generic term G and no physical one: G is added, "not explained by any library effect";
    - a significant physical candidate P: P is fitted and G (the best significant generic term, else the best
      generic term) scored again at that fit, ``generic_p_given(P, G)``; P is named when G then adds nothing
      (p >= alpha); otherwise G is added if it is significant, else nothing ("ambiguous").

    Returns the decision (``named``, ``discovered``, ``ambiguous``, ``none``), the term to add (``added``), the
    best generic row and the encompassing test, and a message; the decision rule of :func:`score_trims` (ratio,
    confounding) is not used, as generic terms are correlated by construction."""
    rows = [r for r in score["scores"] if r["testable"]]
    gen = sorted((r for r in rows if is_generic(r["name"])), key=lambda r: -r["LM"])
    sig_g = [r for r in gen if r["significant"]]
    sig_p = sorted((r for r in rows if r["significant"] and not is_generic(r["name"])), key=lambda r: -r["LM"])
    G = (sig_g or gen or [None])[0]
    L = score["n_testable"]

    def about(r):
        return (f"{generic_term(r['name']).formula()}, c ~ {r['kappa_hat']:.3g} (one-step), LM {r['LM']:.3g}, "
                f"p = {r['p_value']:.2g}")

    out = {"best_generic": G and {k: G[k] for k in ("name", "LM", "p_value", "kappa_hat", "df")},
           "encompassing": None, "added": None, "generic_significant": bool(sig_g)}
    if not sig_p and not sig_g:
        out.update(decision="none", message=f"nothing significant over the library of {L} terms (p < {alpha:g}/{L})"
                   + (f"; best generic description of what is left: {about(G)}" if G else ""))
        return out
    if not sig_p:
        out.update(decision="discovered", added=G["name"],
                   message=f"not explained by any library effect; discovered {about(G)}")
        return out
    P = sig_p[0]
    if G is None:
        out.update(decision="named", added=P["name"], message=f"{P['name']} (no generic term to test it against)")
        return out
    p_g = float(generic_p_given(P["name"], G["name"]))
    out["encompassing"] = {"candidate": P["name"], "generic": G["name"], "p_generic_given_candidate": p_g,
                           "encompasses": p_g >= alpha}
    if p_g >= alpha:
        out.update(decision="named", added=P["name"],
                   message=f"{P['name']} named (LM {P['LM']:.3g}, p = {P['p_value']:.2g}): with it fitted, "
                           f"{G['name']} adds nothing (p = {p_g:.2g} >= {alpha:g})")
    elif G["significant"]:
        out.update(decision="discovered", added=G["name"],
                   message=f"not explained by any library effect ({P['name']} tested: {G['name']} adds to it, "
                           f"p = {p_g:.2g}); discovered {about(G)}")
    else:
        out.update(decision="ambiguous", message=f"{P['name']} significant, but {G['name']} still adds to it "
                                                 f"(p = {p_g:.2g}); nothing added; what is left: {about(G)}")
    return out


def residual_shape(pts: pd.DataFrame, e_deg: np.ndarray) -> dict:
    """Per channel: the residual (data - model) against speed, its largest step between neighbouring speeds,
    the means below and above that step, and its least-squares linear trend [deg per 10 kt]."""
    out = {}
    for c in TRIM_CHANNELS:
        sel = (pts["channel"] == c).to_numpy()
        if not sel.any():
            continue
        order = np.argsort(pts["V"].to_numpy()[sel], kind="stable")
        kt = pts["V"].to_numpy()[sel][order] / KT
        r = e_deg[sel][order]
        d = {"speed_kt": kt.tolist(), "residual_deg": r.tolist(), "rms_deg": float(np.sqrt(np.mean(r**2))),
             "mean_deg": float(r.mean())}
        if r.size >= 2:
            j = int(np.argmax(np.abs(np.diff(r))))
            d.update(step_deg=float(r[j + 1] - r[j]), step_between_kt=[float(kt[j]), float(kt[j + 1])],
                     mean_below_step_deg=float(r[: j + 1].mean()), mean_above_step_deg=float(r[j + 1:].mean()))
            slope = np.polyfit(kt, r, 1)[0] if np.ptp(kt) > 0 else 0.0
            d["trend_deg_per_10kt"] = float(10 * slope)
        out[c] = d
    return out


def rms_by(pts: pd.DataFrame, e_deg: np.ndarray) -> dict:
    """RMS [deg] of the residuals per role and channel."""
    out = {}
    for role in ("identification", "validation"):
        out[role] = {}
        for c in TRIM_CHANNELS:
            sel = ((pts["role"] == role) & (pts["channel"] == c)).to_numpy()
            if sel.any():
                out[role][c] = float(np.sqrt(np.mean(e_deg[sel] ** 2)))
    return out

