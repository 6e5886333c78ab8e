"""Close the loop on a trim-only flight test (``pyomo-heli trim-loop CONFIG --out DIR``).

A trim-only flight test (docs/data_format.md: no maneuvers, each trim channel measured at its own
speeds) has no time histories: J_time does not exist, and the (J_time, J_trim) Pareto front of the
maneuver identification degenerates to a single point, the minimum of J_trim. This module
identifies that point directly and closes the loop on the trim residuals alone:

1. the trim points in long form, one per measured (row, channel); every ``holdout_every``-th point
   of each channel in speed order (the 3rd, 6th, ... with the default 3) is held out for validation;
2. the identification NLP (:mod:`pyomo_heli.nlp.trim_identification`): one Pyomo trim block per distinct
   identification speed (:func:`pyomo_heli.nlp.trim_block.build_trim_block`), the free parameters shared,
   the model's trims taken to the recorded conventions (:func:`pyomo_heli.physics.conventions.recorded_trim`), and

       J_trim = (1/N) sum_rows sum_(measured channels c) ((y_c - y_c,model) / 1 deg)^2

   (paper Eq. 7; a row carries the channels it measured, N = number of rows) minimised by Ipopt;
3. standard errors from the float model (scipy trims, the second route): J = d(recorded trims)/d(free)
   by central differences at the estimate, cov = s^2 (J^T J)^-1 with s^2 = SSR / (n - p);
4. the score test of every library candidate (:mod:`pyomo_heli.diagnosis.candidates`) on the trim
   residuals, with the decision rules of :mod:`pyomo_heli.diagnosis.attribution` (Bonferroni level
   alpha / n, ratio and confounding rules) and a leverage-corrected sandwich variance
   (:func:`pyomo_heli.diagnosis.trim_attribution.score_trims`);
   a candidate with no trim signature is reported as not testable on trims; with ``[loop] discovery`` the
   generic discrepancy family is scored with them and the structure determination decides
   (:func:`pyomo_heli.diagnosis.trim_attribution.discovery_decision`: a physical candidate named by
   encompassing, else a significant generic term added "not explained by any library effect");
5. an accepted candidate is added with its strength free (initial value its one-step estimate) and the
   fit repeated, up to ``max_iterations`` times; otherwise the loop stops and the remaining residual's
   shape per channel is reported (largest step between neighbouring speeds, linear trend).

Everything is written to ``DIR``: ``trim_loop.json`` (every number of the report), ``report.md``,
``trim_curves.png`` (data and model before and after) and ``trim_residuals.png``.
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..dataset import load_flight_test
from ..dataset.schema import KT, TRIM_CHANNELS, TrimConventions
from ..nlp.parameters import FreeParameter
from ..settings import ConfigError
from ..settings.identification import unread_discovery_fields
from ..physics.conventions import THETA_DATUM, TrimOutputDatum
from ..physics.model import HelicopterModel
from ..physics.parameters import DEG
from ..diagnosis.candidates import CANDIDATES, make_candidate
from ..diagnosis.trim_attribution import discovery_decision, residual_shape, rms_by, score_trims
from ..physics.discrepancy import generic_names
from ..nlp.trim_identification import TrimIdentificationFailed, identify_trims, standard_errors  # noqa: F401 (cli)
from ..simulation.recorded_trims import predict

RESULT_FILE = "trim_loop.json"


class TrimLoopError(ConfigError):
    """Bad trim-loop config or data (one line per error naming the file and field); a ConfigError, the one
    error type of a bad settings file."""


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
    #: structure determination: the generic discrepancy family scored with the candidates (docs/real_data.md)
    discovery: bool = False
    generic_family: str = "standard"
    generic: list | None = None
    solver: str = "casadi-ipopt"
    solver_options: dict = field(default_factory=dict)


def load_trim_loop_config(path) -> TrimLoopConfig:
    """Read and check a trim-loop config (declared in :mod:`pyomo_heli.settings.trim_loop`): every error of the
    fields at once, then those of the model's parameters, the solver options and the dataset folder."""
    from ..config import free_parameter_unit
    from ..diagnosis.candidates import CANDIDATES
    from ..settings import read_settings
    from ..settings.trim_loop import TrimLoopFile
    from ..solvers import validate_solver_options

    path = Path(path)
    s, problems = read_settings(path, TrimLoopFile, TrimLoopError)
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
        found = free_parameter_unit(base.parameters, name, p.unit, problems, where)
        if found is None:
            continue
        spec, fac = found
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
    given = loop.model_fields_set  # a field the file gives that nothing reads is refused, not dropped
    for key, why in unread_discovery_fields(given, loop.discovery):
        problems.add("loop", f"field '{key}' is not read here: {why}")
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
                          confound_corr=loop.confound_corr, discovery=loop.discovery,
                          generic_family=loop.generic_family, generic=loop.generic)


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
    # (a datum the manifest gives is a model parameter, which the recorded trim adds whatever the conventions: zeroed)
    plain = start.with_parameters(theta_datum=0.0) if "theta_datum" in start.parameters else start
    e_raw = (data - predict(plain, TrimConventions(), pts["V"], pts["channel"])) / DEG
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
    before: list = []  # (free, extensions) before each added term: the name check goes back to them
    withdrawn: list = []  # physical candidates the name check rejected: not offered again
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
        names = [n for n in (cfg.candidates or CANDIDATES) if n not in withdrawn]
        if cfg.discovery:
            names += list(cfg.generic or generic_names(cfg.generic_family))
        score = score_trims(est, conv, ident, [f.name for f in free], names, cfg.alpha, cfg.ratio,
                            cfg.confound_corr)
        if cfg.discovery:
            def generic_p_given(cand_name, generic_name, free=free, values=values, score=score):
                fr, ext = _with_term(free, values, cand_name, score)
                m = _model_of(cfg, ft, [*extensions, ext])
                v, _ = identify_trims(m, fr, ident, conv, cfg.solver, cfg.solver_options)
                return score_trims(m.with_parameters(**v), conv, ident, [f.name for f in fr],
                                   [generic_name])["scores"][0]["p_value"]

            score["discovery"] = discovery_decision(score, generic_p_given, cfg.alpha)
        accepted = score["discovery"]["added"] if cfg.discovery else score["accepted"]
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
        if cfg.discovery:
            progress(f"  discovery: {score['discovery']['decision']}: {score['discovery']['message']}")
        last = extensions[-1].name if extensions else None
        if cfg.discovery and last in CANDIDATES and score["discovery"]["generic_significant"]:
            # the name check (docs/discovery.md): the physical candidate added last must leave the generic family
            # nothing significant; it does not, so back to the model before it, without it
            G = score["discovery"]["best_generic"]
            rec["rejected"] = (f"name check: with {last} fitted, the generic term {G['name']} is significant "
                               f"(p = {G['p_value']:.2g} < {cfg.alpha:g}/{score['n_testable']}); {last} withdrawn")
            progress(f"  {rec['rejected']}")
            withdrawn.append(last)
            free, extensions = before.pop()
            doc["stopped"] = "max_iterations"
            continue
        doc["stopped"] = "max_iterations"
        if accepted is None:
            doc["stopped"] = (f"discovery: {score['discovery']['decision']}" if cfg.discovery
                              else f"score test: {score['decision']}")
            break
        if it == cfg.max_iterations:
            break
        before.append((free, list(extensions)))
        free, cand = _with_term(free, values, accepted, score)
        extensions.append(cand)
    # the model kept: the last iteration the name check did not reject
    doc["final_iteration"] = max(i for i, r in enumerate(doc["iterations"]) if not r.get("rejected"))
    (out / RESULT_FILE).write_text(json.dumps(doc, indent=1, default=_plain) + "\n")
    return doc


def _with_term(free: list, values: dict, name: str, score: dict):
    """The free parameters started at ``values`` plus the strength of candidate or generic term ``name`` (started at
    its one-step estimate within its bounds), and the term."""
    cand = make_candidate(name)
    spec = HelicopterModel(extensions=(cand,)).parameters.spec(cand.strength)
    k0 = float(np.clip(next(r["kappa_hat"] for r in score["scores"] if r["name"] == name), *spec.bounds))
    free = [dataclasses.replace(f, initial=float(np.clip(values[f.name], f.lower, f.upper))) for f in free]
    return [*free, FreeParameter(cand.strength, k0, spec.bounds[0], spec.bounds[1], spec.scale)], cand


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


def write_trim_report(cfg: TrimLoopConfig, doc: dict, out) -> Path:
    """``report.md`` and the two figures (:mod:`pyomo_heli.report.trim_loop`); the dense model curves are added
    to ``trim_loop.json``."""
    from ..report.trim_loop import write_trim_loop_report

    out = Path(out)
    doc["curves"] = {"before": dense_curves(cfg, doc, None),
                     "after": dense_curves(cfg, doc, doc.get("final_iteration", len(doc["iterations"]) - 1))}
    (out / RESULT_FILE).write_text(json.dumps(doc, indent=1, default=_plain) + "\n")
    return write_trim_loop_report(doc, cfg.path, out)
