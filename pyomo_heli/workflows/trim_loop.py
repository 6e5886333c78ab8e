"""Close the loop on a trim-only flight test (``pyomo-heli trim-loop CONFIG --out DIR``).

A trim-only flight test (docs/data_format.md: no maneuvers, each trim channel measured at its own
speeds) has no time histories: J_time does not exist, and the (J_time, J_trim) Pareto front of the
maneuver identification degenerates to a single point, the minimum of J_trim. This module
identifies that point directly and closes the loop on the trim residuals alone:

1. the trim points in long form, one per measured (row, channel); every ``holdout_every``-th point
   of each channel in speed order (the 3rd, 6th, ... with the default 3) is held out for validation;
2. the identification NLP: one Pyomo trim block per distinct identification speed
   (:func:`pyomo_heli.nlp.trim_block.build_trim_block`), the free parameters shared, the model's trims
   taken to the recorded conventions (:func:`pyomo_heli.physics.conventions.recorded_trim`), and

       J_trim = (1/N) sum_rows sum_(measured channels c) ((y_c - y_c,model) / 1 deg)^2

   (paper Eq. 7; a row carries the channels it measured, N = number of rows) minimised by Ipopt;
3. standard errors from the float model (scipy trims, the second route): J = d(recorded trims)/d(free)
   by central differences at the estimate, cov = s^2 (J^T J)^-1 with s^2 = SSR / (n - p);
4. the score test of every library candidate (:mod:`pyomo_heli.diagnosis.candidates`) on the trim
   residuals, with the decision rules of :mod:`pyomo_heli.diagnosis.attribution` (Bonferroni level
   alpha / n, ratio and confounding rules) and a leverage-corrected sandwich variance (:func:`score_trims`);
   a candidate with no trim signature is reported as not testable on trims;
5. an accepted candidate is added with its strength free (initial value its one-step estimate) and the
   fit repeated, up to ``max_iterations`` times; otherwise the loop stops and the remaining residual's
   shape per channel is reported (largest step between neighbouring speeds, linear trend).

Everything is written to ``DIR``: ``trim_loop.json`` (every number of the report), ``report.md``,
``trim_curves.png`` (data and model before and after) and ``trim_residuals.png``.
"""
from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..dataset import load_flight_test
from ..dataset.schema import KT, TRIM_CHANNELS, TrimConventions
from ..nlp.parameters import FreeParameter
from ..settings import ConfigError
from ..physics.conventions import THETA_DATUM, TrimOutputDatum, recorded_trim
from ..physics.model import HelicopterModel
from ..physics.parameters import DEG
from ..simulation.trim import trim_sweep

RESULT_FILE = "trim_loop.json"
REPORT_FILE = "report.md"
#: relative central-difference step of the float Jacobian (of max(|value|, scale))
JAC_STEP = 1e-5


class TrimLoopError(ConfigError):
    """Bad trim-loop config or data (one line per error naming the file and field); a ConfigError, the one
    error type of a bad settings file."""


class TrimIdentificationFailed(RuntimeError):
    """The J_trim minimisation did not converge (a failed solve, not bad input)."""


# ---------------------------------------------------------------- config
@dataclass
class TrimLoopConfig:
    """What ``trim-loop`` reads from its TOML file (``studies/bo105_flight_trims.toml``)."""

    path: Path
    dataset: Path
    holdout_every: int = 3
    fixed: dict = field(default_factory=dict)
    free: list = field(default_factory=list)  # FreeParameter (SI), without the datum
    max_iterations: int = 2
    candidates: list | None = None
    alpha: float = 0.01
    ratio: float = 2.0
    confound_corr: float = 0.7
    solver: str = "casadi-ipopt"
    solver_options: dict = field(default_factory=dict)


def load_trim_loop_config(path) -> TrimLoopConfig:
    """Read and check a trim-loop config (declared in :mod:`pyomo_heli.settings.trim_loop`): every error of the
    fields at once, then those of the model's parameters, the solver options and the dataset folder."""
    from ..config import unit_factor
    from ..diagnosis.candidates import CANDIDATES
    from ..settings import Problems, validate
    from ..settings.trim_loop import TrimLoopFile
    from ..solvers import validate_solver_options
    from ..tomlfile import read_toml

    path = Path(path)
    raw = read_toml(path, TrimLoopError)
    f = str(path)
    problems = Problems(f, TrimLoopError)
    s = validate(TrimLoopFile, raw, problems)
    problems.raise_if_any()
    ds = Path(s.data.dataset)
    if not ds.is_absolute():
        ds = (path.parent / ds).resolve()
    if not (ds / "manifest.json").is_file():
        problems.add("data", f"field 'dataset': {ds} is not a flight-test folder (no manifest.json)")
    every = s.data.holdout_every
    if every == 1:
        problems.add("data", f"field 'holdout_every' must be 0 (hold nothing out) or an integer >= 2, got {every!r}")
    fixed = dict(s.model.parameters)
    base = HelicopterModel(extensions=(TrimOutputDatum(),))
    try:
        base = base.with_parameters(**fixed)
    except (KeyError, ValueError) as exc:
        problems.add("model.parameters", str(exc.args[0]))
    free = []
    for name, p in s.parameters.items():
        where = f"parameters.{name}"
        if name == THETA_DATUM:
            problems.add(where, "the pitch-attitude datum is freed by the dataset's manifest "
                                "(conventions.theta_datum_deg = \"estimate\"), not by the config")
            continue
        if name not in base.parameters:
            problems.add(where, base.parameters._unknown(name))
            continue
        spec = base.parameters.spec(name)
        try:
            fac = unit_factor(spec, p.unit)
        except ValueError as exc:
            problems.add(where, str(exc))
            continue
        lo, hi = spec.bounds or (None, None)
        vals = {}
        for key, default in (("initial", spec.value / fac), ("lower", None if lo is None else lo / fac),
                             ("upper", None if hi is None else hi / fac), ("scale", (spec.scale or 1.0) / fac)):
            v = getattr(p, key)
            v = default if v is None else v
            if v is None:
                problems.add(where, f"field '{key}' is needed ({name} has no default bounds)")
                continue
            vals[key] = v * fac
        if len(vals) < 4:
            continue
        try:
            free.append(FreeParameter(name, vals["initial"], vals["lower"], vals["upper"], vals["scale"]))
        except ValueError as exc:
            problems.add(where, str(exc))
    loop = s.loop
    cands = loop.candidates
    if cands is not None:
        bad = [c for c in cands if c not in CANDIDATES]
        if bad:
            problems.add("loop", f"field 'candidates': unknown {bad}; choose from {', '.join(CANDIDATES)}")
    try:
        validate_solver_options(s.solver.name, dict(s.solver.options))
    except ValueError as exc:
        problems.add_text(f"[solver] options: {exc}")
    problems.raise_if_any()
    return TrimLoopConfig(path=path, dataset=ds, holdout_every=every, fixed=fixed, free=free,
                          max_iterations=loop.max_iterations, candidates=cands, solver=s.solver.name,
                          solver_options=dict(s.solver.options), alpha=loop.alpha, ratio=loop.ratio,
                          confound_corr=loop.confound_corr)


# ---------------------------------------------------------------- data
def trim_points(ft, holdout_every: int = 3) -> pd.DataFrame:
    """One row per measured (trims.csv row, channel): ``row`` (0-based data row), ``channel``, ``V`` [m/s],
    ``value`` [rad], ``role``; every ``holdout_every``-th point of each channel in speed order (ties by row)
    is ``validation`` (0: none)."""
    out = []
    for c in TRIM_CHANNELS:
        if c not in ft.trims:
            continue
        d = ft.trims[["V", c]].dropna()
        d = d.assign(row=d.index.to_numpy(dtype=int)).sort_values(["V", "row"], kind="stable")
        k = np.arange(len(d))
        held = (k % holdout_every == holdout_every - 1) if holdout_every else np.zeros(len(d), bool)
        out.append(pd.DataFrame({"row": d["row"].to_numpy(), "channel": c, "V": d["V"].to_numpy(dtype=float),
                                 "value": d[c].to_numpy(dtype=float),
                                 "role": np.where(held, "validation", "identification")}))
    if not out:
        return pd.DataFrame(columns=["row", "channel", "V", "value", "role"])
    return pd.concat(out, ignore_index=True)


# ---------------------------------------------------------------- the model as recorded
def predict(model: HelicopterModel, conventions, V, channels) -> np.ndarray:
    """Recorded trim value [rad] of ``channels[i]`` at speed ``V[i]`` [m/s] (float trims, continuation)."""
    V = np.asarray(V, dtype=float)
    speeds = sorted(set(V.tolist()))
    tps = dict(zip(speeds, trim_sweep(model, speeds)))
    p = model.parameters
    rec = {v: recorded_trim(tp.col, tp.lon, tp.theta, p, conventions) for v, tp in tps.items()}
    return np.array([rec[v][c] for v, c in zip(V, channels)], dtype=float)


def jacobian(model: HelicopterModel, conventions, pts: pd.DataFrame, names) -> np.ndarray:
    """d(recorded trims)/d(parameter) [rad per SI unit], central differences of the float trims."""
    cols = []
    for n in names:
        spec = model.parameters.spec(n)
        v = model.parameters[n]
        h = JAC_STEP * max(abs(v), spec.scale or 1.0)
        lo, hi = spec.bounds or (-np.inf, np.inf)
        a, b = (v - h, v + h)
        if a < lo:
            a = v
        if b > hi:
            b = v
        ya = predict(model.with_parameters(**{n: a}), conventions, pts["V"], pts["channel"])
        yb = predict(model.with_parameters(**{n: b}), conventions, pts["V"], pts["channel"])
        cols.append((yb - ya) / (b - a))
    return np.array(cols).T if cols else np.zeros((len(pts), 0))


# ---------------------------------------------------------------- identification (Pyomo NLP)
def build_trim_nlp(model: HelicopterModel, free, pts: pd.DataFrame, conventions):
    """The trim-only identification NLP: trim blocks per distinct speed, J_trim over ``pts`` as objective."""
    import pyomo.environ as pyo

    from ..nlp.objectives import add_trim_objective
    from ..nlp.parameters import add_parameters
    from ..nlp.trim_block import build_trim_block

    m = pyo.ConcreteModel(name="trim_identification")
    pmap = add_parameters(m, model.parameters, free)
    speeds = sorted(set(pts["V"].tolist()))
    init = model.with_parameters(**{f.name: f.initial for f in free}) if free else model
    guesses = trim_sweep(init, speeds)
    m.trim = pyo.Block(range(len(speeds)))
    rec = []
    for i, (V, tp) in enumerate(zip(speeds, guesses)):
        build_trim_block(m.trim[i], model, pmap, V, guess={**tp.to_dict(), **tp.extra_states})
        blk = m.trim[i]
        rec.append(recorded_trim(blk.col, blk.lon, blk.theta, pmap, conventions))
    index = {v: i for i, v in enumerate(speeds)}
    residuals = [[float(r.value) - rec[index[r.V]][r.channel] for r in grp.itertuples()]
                 for _, grp in pts.groupby("row", sort=True)]
    add_trim_objective(m, residuals)
    m.J_time = pyo.Expression(expr=0.0)  # no maneuvers: the front's other objective does not exist
    m.objective = pyo.Objective(expr=m.J_trim)
    m.speeds = speeds
    return m


def identify_trims(model: HelicopterModel, free, pts: pd.DataFrame, conventions, solver: str = "casadi-ipopt",
                   options: dict | None = None) -> tuple[dict, dict]:
    """Minimise J_trim over the free parameters; returns (values SI, solve info). RuntimeError on failure."""
    import pyomo.environ as pyo

    from ..nlp.parameters import free_parameter_values
    from ..solvers import make_solver

    m = build_trim_nlp(model, free, pts, conventions)
    res = make_solver(m, solver, options).solve(warm_start="none")
    info = {"status": res.status, "iterations": res.iterations, "J_trim": float(pyo.value(m.J_trim)),
            "wall_time_s": res.wall_time, "solver": res.solver}
    if not res.success:
        raise TrimIdentificationFailed(f"trim identification failed: Ipopt status {res.status} ({res.message})")
    return free_parameter_values(m), info


def standard_errors(model: HelicopterModel, conventions, pts: pd.DataFrame, names) -> dict:
    """Least-squares standard errors of ``names`` at ``model`` (its values are the estimate).

    e = data - model [deg]; J [deg per SI unit]; s^2 = e.e / (n - p); cov = s^2 (J^T J)^-1.
    """
    y = predict(model, conventions, pts["V"], pts["channel"])
    e = (pts["value"].to_numpy(dtype=float) - y) / DEG
    J = jacobian(model, conventions, pts, names) / DEG
    n, p = J.shape
    dof = max(n - p, 1)
    s2 = float(e @ e) / dof
    if p == 0:
        return {"se": {}, "se_robust": {}, "corr": [], "s_deg": math.sqrt(s2), "dof": dof, "cond": 0.0}
    JtJ = J.T @ J
    inv = np.linalg.pinv(JtJ)
    cov = s2 * inv
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    # sandwich (heteroscedasticity-robust, HC1) covariance: does not assume one variance for every point
    meat = (J * (e**2)[:, None]).T @ J * n / dof
    se_rob = np.sqrt(np.maximum(np.diag(inv @ meat @ inv), 0.0))
    d = np.where(se > 0, se, 1.0)
    corr = cov / np.outer(d, d)
    return {"se": dict(zip(names, se.tolist())), "se_robust": dict(zip(names, se_rob.tolist())),
            "corr": corr.tolist(), "s_deg": math.sqrt(s2), "dof": dof,
            "cond": float(np.linalg.cond(JtJ / np.outer(np.sqrt(np.diag(JtJ)), np.sqrt(np.diag(JtJ)))))}


# ---------------------------------------------------------------- score test on trims
def score_trims(model: HelicopterModel, conventions, pts: pd.DataFrame, identified, candidates=None,
                alpha: float = 0.01, ratio: float = 2.0, confound_corr: float = 0.7, variance: str = "hc3") -> dict:
    """Score test of each candidate's strength at zero on the trim residuals of ``pts`` (decision rules of
    :mod:`pyomo_heli.diagnosis.attribution`: level alpha / number of testable candidates, ratio, confounding).

    e = data - model [deg], S = d(trims)/d(identified), s_j = d(trims)/d(kappa_j) (one-sided forward
    difference at zero for a one-sided strength), s~_j = s_j - S S^+ s_j, with the common residual
    variance s^2: g = s~.e / s^2, F = s~.s~ / s^2, kappa_hat = g / F. The score's variance (``variance``):

    - ``hc3`` (default): sandwich over the points, each point's residual r_i = e_i - kappa_hat s~_i divided by
      (1 - h_ii), h_ii its leverage in the fit of [S, s_j]: LM = (s~.e)^2 / sum_i (s~_i r_i / (1 - h_ii))^2;
    - ``hc0``: the same without the leverage (attribution.py's batch means with one segment per point);
    - ``white``: the classical F test of the added column, (SSR_0 - SSR_1) / (SSR_1 / (n - p - 1)).

    hc3 and hc0 are referred to F(1, df), df = F^2 / sum_i (s~_i^2 / s^2)^2 - 1 (Satterthwaite), white to
    F(1, n - p - 1). With tens of trim points and a few identified parameters the leverage matters: on 20
    noise-only synthetic trim sets (studies/trim_score_level.py) 3.8 % of the hc3 p-values fell below 0.05,
    11.2 % of the hc0 ones. Every row keeps all three p-values (``p_by_variance``).
    """
    from scipy import stats

    from ..diagnosis.candidates import CANDIDATES, make_candidate

    have = {e.name for e in model.extensions}
    names = [n for n in (candidates or list(CANDIDATES)) if n not in have]
    y = predict(model, conventions, pts["V"], pts["channel"])
    e = (pts["value"].to_numpy(dtype=float) - y) / DEG
    S = jacobian(model, conventions, pts, identified) / DEG
    s2 = max(float(e @ e) / max(len(e) - S.shape[1], 1), 1e-24)  # floor: noise-free data fit exactly
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
        raw = float(s @ s)
        coef = np.linalg.lstsq(S, s, rcond=None)[0] if S.shape[1] else np.zeros(0)
        st = s - S @ coef if S.shape[1] else s
        F = float(st @ st) / s2
        if raw / s2 < 1e-12 or F < 1e-9 * raw / s2:
            row.update(testable=False, LM=0.0, df=float("nan"), p_value=1.0, kappa_hat=0.0,
                       kept=0.0 if raw > 0 else float("nan"),
                       note="no trim signature" if raw / s2 < 1e-12 else "absorbed by the identified parameters")
            rows.append(row)
            continue
        g = float(st @ e) / s2
        kappa = g / F
        r = e - kappa * st  # residual with the candidate fitted too
        half = 0.5 if cand.one_sided else 1.0
        n_pts, k = len(e), S.shape[1] + 1
        # classical F test of the added column (exact for a linear model with one Gaussian noise level)
        ssr1 = float(r @ r)
        lm_white = (ssr1 and (float(e @ e) - ssr1) / (ssr1 / max(n_pts - k, 1))) or 0.0
        p_white = float(stats.f(1, max(n_pts - k, 1)).sf(lm_white))
        # sandwich variance of the score, one segment per point, raw (HC0, the batch means of attribution.py)
        # and with each point's residual inflated by its leverage in the augmented fit (HC3)
        X = np.column_stack([S, s]) if S.shape[1] else s[:, None]
        lev = np.einsum("ij,ji->i", X, np.linalg.pinv(X))
        u0 = st * r
        u3 = u0 / np.maximum(1.0 - lev, 1e-6)
        lm_hc0 = float(st @ e) ** 2 / float(u0 @ u0) if float(u0 @ u0) > 0 else 0.0
        lm_hc3 = float(st @ e) ** 2 / float(u3 @ u3) if float(u3 @ u3) > 0 else 0.0
        v = st * st / s2
        df = max(F * F / float(v @ v) - 1.0, 1.0)
        ps = {"white": p_white, "hc0": float(stats.f(1, df).sf(lm_hc0)), "hc3": float(stats.f(1, df).sf(lm_hc3))}
        lms = {"white": lm_white, "hc0": lm_hc0, "hc3": lm_hc3}
        if variance == "white":
            df = float(max(n_pts - k, 1))
        lm = lms[variance]
        ps = {key: (1.0 if cand.one_sided and kappa < 0 else val * half) for key, val in ps.items()}
        p = ps[variance]
        row.update(p_by_variance=ps)
        proj[n] = st
        testable.append(n)
        row.update(testable=True, LM=lm, df=df, p_value=p, kappa_hat=kappa, kept=F / (raw / s2), note="")
        rows.append(row)
    n_test = max(len(testable), 1)
    level = alpha / n_test
    for r in rows:
        r["significant"] = bool(r["testable"] and r["p_value"] < level)
        r["evidence"] = r["LM"] if r["testable"] and r["p_value"] < 1.0 else 0.0
    rows.sort(key=lambda r: -r["evidence"])
    sig = [r for r in rows if r["significant"]]
    decision, accepted, message = "none", None, ""
    if not sig:
        top = rows[0] if rows else None
        message = (f"no candidate significant at p < {alpha:g}/{n_test}" +
                   (f" (best: {top['name']}, LM {top['LM']:.3g}, p = {top['p_value']:.2g})" if top else ""))
    else:
        top, second = sig[0], (sig[1] if len(sig) > 1 else None)
        if second is None or second["evidence"] * ratio <= top["evidence"]:
            decision, accepted = "accepted", top["name"]
            message = (f"{top['name']} LM {top['LM']:.3g} (p = {top['p_value']:.2g}), "
                       f"{top['strength']} ~ {top['kappa_hat']:.4g}")
        else:
            a, b = proj[top["name"]], proj[second["name"]]
            rho = float(a @ b / math.sqrt(max((a @ a) * (b @ b), 1e-300)))
            decision = "confounded" if abs(rho) >= confound_corr else "ambiguous"
            message = (f"{top['name']} (LM {top['LM']:.3g}) and {second['name']} (LM {second['LM']:.3g}) within a "
                       f"factor {ratio:g}, projected sensitivities rho = {rho:.2f}: none is picked")
    for r in rows:
        r.pop("evidence")
    return {"decision": decision, "accepted": accepted, "message": message, "level": level, "alpha": alpha,
            "n_testable": len(testable), "scores": rows,
            "points": {"speed_kt": (pts["V"] / KT).tolist(), "channel": pts["channel"].tolist()}}


# ---------------------------------------------------------------- residual shape
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


# ---------------------------------------------------------------- the loop
def _load(cfg: TrimLoopConfig):
    """The config's dataset; its problems as one line naming each file and row or field."""
    from ..dataset import DatasetError

    try:
        return load_flight_test(cfg.dataset)
    except DatasetError as exc:
        raise TrimLoopError(f"{cfg.path} [data] dataset {cfg.dataset}: " + "; ".join(str(p) for p in exc.problems)) \
            from None


def _model_of(cfg: TrimLoopConfig, ft, extensions=(), values: dict | None = None) -> HelicopterModel:
    model = HelicopterModel(extensions=(TrimOutputDatum(), *extensions))
    fixed = dict(cfg.fixed)
    if not ft.conventions.estimate_theta_datum:
        fixed[THETA_DATUM] = ft.conventions.theta_datum
    return model.with_parameters(**fixed, **(values or {}))


def run_trim_loop(cfg: TrimLoopConfig, out, progress=print) -> dict:
    """Identify, test the candidates, add the accepted one, repeat; write ``out/trim_loop.json``."""
    from ..dataset.reader import check_model_matches_manifest
    from ..diagnosis.candidates import make_candidate

    ft = _load(cfg)
    out = Path(out)
    if ft.trims is None or len(ft.trims) == 0:
        raise TrimLoopError(f"{cfg.dataset}: no trim points")
    climb = np.flatnonzero(np.abs(ft.trims["gamma_fp"].to_numpy(dtype=float)) > 1e-9)
    if climb.size:
        raise TrimLoopError(f"{cfg.dataset}/{ft.trim_file}: rows {[int(i) + 1 for i in climb[:5]]} have gamma_fp != 0; "
                            f"the trim identification trims in level flight only")
    conv = ft.conventions
    free = list(cfg.free)
    if conv.estimate_theta_datum:
        spec = TrimOutputDatum().parameters()[0]
        free.append(FreeParameter(THETA_DATUM, 0.0, spec.bounds[0], spec.bounds[1], spec.scale))
    if not free:
        raise TrimLoopError(f"{cfg.path} [parameters]: no free parameter (and the manifest of {cfg.dataset} states the "
                            f"pitch-attitude datum): nothing to identify")
    model = _model_of(cfg, ft)
    check_model_matches_manifest(ft, model.parameters, f"{cfg.path} [model]", skip=[f.name for f in free])
    pts = trim_points(ft, cfg.holdout_every)
    ident = pts[pts["role"] == "identification"].reset_index(drop=True)
    if len(ident) <= len(free):
        raise TrimLoopError(f"{cfg.path}: {len(ident)} identification trim points for {len(free)} free parameters")
    data = pts["value"].to_numpy(dtype=float)
    out.mkdir(parents=True, exist_ok=True)

    start = model.with_parameters(**{f.name: f.initial for f in free})
    y0 = predict(start, conv, pts["V"], pts["channel"])
    e0 = (data - y0) / DEG
    # the same start read as if the data followed the model's own conventions (col at r_ref, no datum): what
    # the declared conventions change
    e_raw = (data - predict(start, TrimConventions(), pts["V"], pts["channel"])) / DEG
    import os

    # the dataset as the config names it (relative to the config's folder), not this machine's absolute path
    doc = {"config": str(cfg.path), "dataset": os.path.relpath(cfg.dataset, Path(cfg.path).parent),
           "aircraft": ft.aircraft,
           "trim_only": ft.trim_only,
           "front": ("degenerate: a trim-only flight test has no maneuvers, so J_time does not exist and the "
                     "(J_time, J_trim) Pareto front is the single point minimising J_trim"
                     if ft.trim_only else "maneuvers present but not used: trims only"),
           "conventions": {"collective_station": conv.collective_station, "model_r_ref": model.parameters["r_ref"],
                           "lon_sign": conv.lon_sign,
                           "theta_datum_deg": None if conv.theta_datum is None else conv.theta_datum / DEG,
                           "theta_datum_estimated": conv.estimate_theta_datum},
           "source": ft.source, "accuracy": ft.accuracy, "assumptions": ft.assumptions,
           "mass_kg": ft.mass, "rho_kg_m3": ft.rho, "holdout_every": cfg.holdout_every,
           "points": {"speed_kt": (pts["V"] / KT).tolist(), "channel": pts["channel"].tolist(),
                      "role": pts["role"].tolist(), "row": [int(r) + 1 for r in pts["row"]],
                      "value_deg": (data / DEG).tolist()},
           "counts": {role: {c: int(((pts.role == role) & (pts.channel == c)).sum()) for c in TRIM_CHANNELS}
                      for role in ("identification", "validation")},
           "initial": {"parameters": {f.name: f.initial for f in free}, "model_deg": (y0 / DEG).tolist(),
                       "rms_deg": rms_by(pts, e0), "rms_deg_without_conventions": rms_by(pts, e_raw)},
           "iterations": []}
    extensions: list = []
    for it in range(cfg.max_iterations + 1):
        progress(f"iteration {it}: free {', '.join(f.name for f in free)}"
                 + (f"; extensions {', '.join(e.name for e in extensions)}" if extensions else ""))
        model = _model_of(cfg, ft, extensions)
        values, info = identify_trims(model, free, ident, conv, cfg.solver, cfg.solver_options)
        est = model.with_parameters(**values)
        y = predict(est, conv, pts["V"], pts["channel"])
        e = (data - y) / DEG
        se = standard_errors(est, conv, ident, [f.name for f in free])
        J_float = float(np.sum(e[(pts.role == "identification").to_numpy()] ** 2)) / ident["row"].nunique()
        score = score_trims(est, conv, ident, [f.name for f in free], cfg.candidates, cfg.alpha, cfg.ratio,
                            cfg.confound_corr)
        rec = {"iteration": it, "extensions": [x.name for x in extensions], "free": [f.name for f in free],
               "solve": info, "J_trim_float": J_float,
               "parameters": {n: {"value": v, "se": se["se"][n], "se_robust": se["se_robust"][n],
                                  "shown": _shown(est, n, v), "se_shown": _shown(est, n, se["se"][n]),
                                  "se_robust_shown": _shown(est, n, se["se_robust"][n])}
                              for n, v in values.items()},
               "correlation": se["corr"], "residual_sigma_deg": se["s_deg"], "dof": se["dof"],
               "information_condition": se["cond"],
               "model_deg": (y / DEG).tolist(), "rms_deg": rms_by(pts, e), "score_test": score,
               "residual_shape": residual_shape(pts, e)}
        doc["iterations"].append(rec)
        progress(f"  J_trim {info['J_trim']:.4g} deg^2 ({info['status']}); held-out RMS "
                 + ", ".join(f"{c} {v:.3f}" for c, v in rec["rms_deg"]["validation"].items()) + " deg")
        progress(f"  score test: {score['decision']}: {score['message']}")
        doc["stopped"] = "max_iterations"
        if score["decision"] != "accepted":
            doc["stopped"] = f"score test: {score['decision']}"
            break
        if it == cfg.max_iterations:
            break
        cand = make_candidate(score["accepted"])
        spec = HelicopterModel(extensions=(cand,)).parameters.spec(cand.strength)
        k0 = float(np.clip(next(r["kappa_hat"] for r in score["scores"] if r["name"] == cand.name),
                           *spec.bounds))
        free = [dataclasses.replace(f, initial=float(np.clip(values[f.name], f.lower, f.upper))) for f in free]
        free.append(FreeParameter(cand.strength, k0, spec.bounds[0], spec.bounds[1], spec.scale))
        extensions.append(cand)
    (out / RESULT_FILE).write_text(json.dumps(doc, indent=1, default=_plain) + "\n")
    return doc


def _held_text(every: int) -> str:
    if not every:
        return "nothing held out"
    nth = {2: "second", 3: "third", 4: "fourth", 5: "fifth"}.get(every, f"{every}th")
    return f"every {nth} point of each channel in speed order held out"


def _shown(model, name, value):
    spec = model.parameters.spec(name)
    if spec.display is None:
        return [value, spec.unit]
    unit, factor = spec.display
    return [value * factor, unit]


def _plain(v):
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    if isinstance(v, np.bool_):
        return bool(v)
    raise TypeError(type(v).__name__)


# ---------------------------------------------------------------- report and figures
def dense_curves(cfg: TrimLoopConfig, doc: dict, which: int | None) -> dict:
    """Model trim curves [deg] on a speed grid: initial guess (which None) or iteration ``which``'s estimate."""
    from ..diagnosis.candidates import make_candidate

    ft = _load(cfg)
    kt = np.linspace(0.0, max(doc["points"]["speed_kt"]) + 5.0, 45)
    if which is None:
        model = _model_of(cfg, ft, (), doc["initial"]["parameters"])
    else:
        it = doc["iterations"][which]
        model = _model_of(cfg, ft, [make_candidate(n) for n in it["extensions"]],
                          {n: p["value"] for n, p in it["parameters"].items()})
    V = np.repeat(kt * KT, 3)
    ch = np.tile(list(TRIM_CHANNELS), kt.size)
    y = predict(model, ft.conventions, V, ch) / DEG
    return {"speed_kt": kt.tolist(), **{c: y[ch == c].tolist() for c in TRIM_CHANNELS}}


LABELS = {"col": "collective (as recorded) [deg]", "lon": "longitudinal cyclic [deg]",
          "theta": "pitch attitude [deg]"}


def plot_trim_curves(doc: dict, curves_before: dict, curves_after: dict, path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = doc["points"]
    fig, axes = plt.subplots(3, 1, figsize=(7, 9), sharex=True)
    for ax, c in zip(axes, TRIM_CHANNELS):
        for role, mk, lab in (("identification", "o", "data, identification"), ("validation", "s", "data, held out")):
            sel = [i for i, (cc, r) in enumerate(zip(pts["channel"], pts["role"])) if cc == c and r == role]
            ax.plot([pts["speed_kt"][i] for i in sel], [pts["value_deg"][i] for i in sel], mk,
                    mfc="none" if role == "validation" else None, color="k", label=lab)
        ax.plot(curves_before["speed_kt"], curves_before[c], "--", color="tab:blue", label="model before (initial)")
        ax.plot(curves_after["speed_kt"], curves_after[c], "-", color="tab:red", label="model after (identified)")
        ax.set_ylabel(LABELS[c])
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("airspeed [kt]")
    fig.suptitle(f"{doc['aircraft']}: level-flight trims, data vs model")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_residuals(doc: dict, path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = doc["points"]
    fig, axes = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    first, last = doc["initial"]["model_deg"], doc["iterations"][-1]["model_deg"]
    for ax, c in zip(axes, TRIM_CHANNELS):
        sel = sorted((i for i, cc in enumerate(pts["channel"]) if cc == c), key=lambda i: pts["speed_kt"][i])
        v = [pts["speed_kt"][i] for i in sel]
        ax.plot(v, [pts["value_deg"][i] - first[i] for i in sel], "--o", color="tab:blue", mfc="none",
                label="before")
        ax.plot(v, [pts["value_deg"][i] - last[i] for i in sel], "-o", color="tab:red", label="after")
        held = [pts["speed_kt"][i] for i in sel if pts["role"][i] == "validation"]
        for h in held:
            ax.axvline(h, color="0.8", lw=0.8)
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_ylabel(f"data - model, {c} [deg]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, title="grey lines: held-out speeds", title_fontsize=7)
    axes[-1].set_xlabel("airspeed [kt]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def write_trim_report(cfg: TrimLoopConfig, doc: dict, out) -> Path:
    """``report.md`` and the two figures; the dense model curves are added to ``trim_loop.json``."""
    out = Path(out)
    before = dense_curves(cfg, doc, None)
    after = dense_curves(cfg, doc, len(doc["iterations"]) - 1)
    doc["curves"] = {"before": before, "after": after}
    (out / RESULT_FILE).write_text(json.dumps(doc, indent=1, default=_plain) + "\n")
    plot_trim_curves(doc, before, after, out / "trim_curves.png")
    plot_residuals(doc, out / "trim_residuals.png")
    last = doc["iterations"][-1]
    c = doc["conventions"]
    L = [f"# Trim-only closed loop: {doc['aircraft']}", "",
         f"Config `{cfg.path}`, dataset `{doc['dataset']}` (relative to the config).", ""]
    if doc.get("source"):
        L += [f"Source: {doc['source']}", ""]
    L += [f"Front: {doc['front']}.", "",
          "## Conventions applied by the model's output equations", "",
          "- collective: recorded at r/R = "
          f"{c['collective_station'] if c['collective_station'] is not None else 'r_ref'}"
          f" (model col at r_ref = {c['model_r_ref']:g}); col_rec = col + (r_c - r_ref) theta_twist R",
          f"- longitudinal cyclic sign: {c['lon_sign']:+d} (+1: positive aft)",
          "- pitch-attitude datum: " + ("unknown, **estimated** (theta_datum below)" if c["theta_datum_estimated"]
                                        else f"{c['theta_datum_deg']:g} deg (declared)"),
          f"- mass {doc['mass_kg']:g} kg, air density {doc['rho_kg_m3']:g} kg/m^3 (manifest)"]
    for a in doc.get("assumptions") or []:
        L.append(f"- assumption: {a}")
    n_id, n_val = doc["counts"]["identification"], doc["counts"]["validation"]
    L += ["", "## Data", "",
          f"Trim points per channel, identification / held out ({_held_text(doc['holdout_every'])}): "
          + ", ".join(f"{ch} {n_id[ch]}/{n_val[ch]}" for ch in TRIM_CHANNELS), ""]
    L += ["## Iterations", ""]
    for it in doc["iterations"]:
        L += [f"### Iteration {it['iteration']}"
              + (f" (with {', '.join(it['extensions'])})" if it["extensions"] else ""),
              "", f"J_trim = {it['solve']['J_trim']:.4g} deg^2 (Ipopt {it['solve']['status']}, "
              f"{it['solve']['iterations']} iterations; float-model check {it['J_trim_float']:.4g}); "
              f"residual sigma {it['residual_sigma_deg']:.3f} deg, "
              f"{it['dof']} degrees of freedom", "",
              "| parameter | estimate | standard error | robust SE | unit |", "|---|---|---|---|---|"]
        for n, p in it["parameters"].items():
            tag = " (convention offset)" if n == THETA_DATUM else ""
            L.append(f"| {n}{tag} | {p['shown'][0]:.5g} | {p['se_shown'][0]:.3g} | {p['se_robust_shown'][0]:.3g} | "
                     f"{p['shown'][1]} |")
        L += ["", "Standard errors: s^2 (J^T J)^-1 with one residual variance s^2 for every point; robust: the "
                  "sandwich (HC1) estimate. Both take the residuals as independent, which a structured residual "
                  "(below) is not: read them as lower bounds."]
        st = it["score_test"]
        L += ["", f"Score test ({st['n_testable']} candidates with a trim signature, level {st['level']:.2g}, "
                  f"leverage-corrected sandwich variance): "
                  f"**{st['decision']}**: {st['message']}", "",
              "| candidate | LM | df | p | estimate | kept | note |", "|---|---|---|---|---|---|---|"]
        for r in st["scores"]:
            if r["testable"]:
                L.append(f"| {r['name']} | {r['LM']:.3g} | {r['df']:.3g} | {r['p_value']:.2g} | {r['kappa_hat']:.3g} | "
                         f"{r['kept']:.2f} | |")
            else:
                L.append(f"| {r['name']} | - | - | - | - | - | {r['note']} |")
        L.append("")
    L += ["## RMS error, data minus model [deg]", "", "| points | channel | before | after |", "|---|---|---|---|"]
    for role in ("identification", "validation"):
        for ch in TRIM_CHANNELS:
            if ch in last["rms_deg"][role]:
                L.append(f"| {role} | {ch} | {doc['initial']['rms_deg'][role][ch]:.3f} | "
                         f"{last['rms_deg'][role][ch]:.3f} |")
    raw = doc["initial"]["rms_deg_without_conventions"]
    L += ["", "Before = the initial model with the declared conventions applied; without them (collective read as "
              "if at r_ref, no datum) the initial RMS on all identification points would be "
              + ", ".join(f"{ch} {v:.3f}" for ch, v in raw["identification"].items()) + " deg."]
    L += ["", "## Remaining residual (final model, all points)", "",
          "| channel | RMS | largest step | between [kt] | mean below / above | trend [deg/10 kt] |",
          "|---|---|---|---|---|---|"]
    for ch, s in last["residual_shape"].items():
        L.append(f"| {ch} | {s['rms_deg']:.3f} | {s.get('step_deg', 0):+.2f} | "
                 f"{s.get('step_between_kt', ['-', '-'])[0]:.1f}-{s.get('step_between_kt', ['-', '-'])[1]:.1f} | "
                 f"{s.get('mean_below_step_deg', 0):+.2f} / {s.get('mean_above_step_deg', 0):+.2f} | "
                 f"{s.get('trend_deg_per_10kt', 0):+.3f} |")
    if last["score_test"]["decision"] != "accepted":
        L += ["", "No candidate of the library explains the remaining residual (score test above). Its shape per "
                  "channel is in the table and in `trim_residuals.png`; a generic speed-dependent correction "
                  "(structure determination) is not part of this loop. docs/real_data.md discusses the missing "
                  "physics the shape points to."]
    L += ["", "Not represented by the 3-DoF longitudinal model (not fitted, whatever the data hold): lateral cyclic "
              "and roll attitude (no lateral degrees of freedom), tail-rotor collective (no tail rotor), main-rotor "
              "power (no torque equation)."]
    L += ["", f"Stopped: {doc['stopped']}.", "",
          "Figures: `trim_curves.png` (data and model before/after), `trim_residuals.png` (data minus model).",
          "Every number above is in `trim_loop.json`.", ""]
    path = out / REPORT_FILE
    path.write_text("\n".join(L))
    return path
