"""The steps of the closed loop around an identification (:mod:`pyomo_heli.workflows.close_loop`): the model's
errors at a point, a candidate added to or removed from the config, the validation rule, the backward check of
effects added earlier, and the shape rule of a candidate with shape parameters."""
from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path

from ..config import ConfigError, IdentificationConfig
from ..diagnosis.candidates import model_with_candidates
from ..log import info
from ..nlp.parameters import FreeParameter
from ..pareto.result import write_json
from ..physics.model import HelicopterModel
from ..report.identification import CURVE_SPEEDS, predict, trim_rms, validation_rms
from .identify import build_problem, identification_fingerprint


def errors_of(model: HelicopterModel, params: dict, id_mans, val_mans, trims, label: str) -> dict:
    """RMS of data minus model (SI) per output on identification and validation maneuvers and per trim channel."""
    speeds = list(trims["V"]) + list(CURVE_SPEEDS)
    pred = predict(label, model, params, speeds, list(id_mans) + list(val_mans))
    # the RMS pools the records the model could replay: the ones it could not are named, so that a comparison of
    # two iterations over different records is said (report.loop.change_table)
    lost = [mv.name for mv in list(id_mans) + list(val_mans) if pred.maneuvers.get(mv.name) is None]
    return {"identification_rms": validation_rms(pred, id_mans)["all"],
            "validation_rms": validation_rms(pred, val_mans)["all"] if val_mans else {},
            "trim_rms": trim_rms(pred, trims)["all"], "problems": pred.problems,
            **({"not_replayed": lost} if lost else {})}


def _with_candidate(cfg: IdentificationConfig, chosen: dict, name: str, kappa: float) -> IdentificationConfig:
    model = model_with_candidates(cfg.model, [name])
    cand = model.extensions[-1]
    spec = model.parameters.spec(cand.strength)
    lo, hi = spec.bounds
    init = min(max(kappa, lo + 0.05 * (hi - lo) if cand.one_sided else lo), hi)
    free = [dataclasses.replace(f, initial=min(max(chosen[f.name], f.lower), f.upper)) for f in cfg.free]
    free.append(FreeParameter(cand.strength, init, lo, hi, spec.scale or 1.0))
    return dataclasses.replace(cfg, model=model, free=free)


def _without(cfg: IdentificationConfig, chosen: dict, name: str) -> IdentificationConfig:
    """``cfg`` without the loop-added effect ``name`` (backward check), its parameters gone too: the model the
    iteration's record rebuilds (:func:`pyomo_heli.config.config_of_result`, the record's extensions); the other
    free parameters start at ``chosen``."""
    exts = tuple(e for e in cfg.model.extensions if e.name != name)
    gone = next(e for e in cfg.model.extensions if e.name == name)
    still = {s.name for e in exts for s in e.parameters()}
    own = [s.name for s in gone.parameters() if s.name not in still]
    model = HelicopterModel(parameters=cfg.model.parameters.without(own), extensions=exts)
    free = [dataclasses.replace(f, initial=min(max(chosen[f.name], f.lower), f.upper)) for f in cfg.free
            if f.name != gone.strength]
    return dataclasses.replace(cfg, model=model, free=free)


def validation_check(model0: HelicopterModel, params0: dict, model1: HelicopterModel, params1: dict, val_mans,
                     alpha: float = 0.01, joint: bool = False) -> dict:
    """The validation rule: the paired test (Diebold-Mariano, :mod:`pyomo_heli.diagnosis.validation_change`) of each
    output's validation error, model 1 against model 0 on the same records, and of all outputs at once (the table's
    joint row). ``rise``: True when any output's error rises significantly (one-sided p < ``alpha``), or, with
    ``joint``, the joint error does, or model 1 cannot be replayed on a validation record model 0 could (a diverged
    or failed replay is the largest rise there is); ``rows``: the test table as records, over the records both
    models replayed; ``message`` names the rise and the records left out."""
    from ..report.loop import JOINT, validation_change_table

    p0 = predict("before", model0, params0, [], val_mans)
    p1 = predict("after", model1, params1, [], val_mans)
    lost = [mv.name for mv in val_mans if p1.maneuvers.get(mv.name) is None and p0.maneuvers.get(mv.name) is not None]
    both = [mv for mv in val_mans if p0.maneuvers.get(mv.name) is not None and p1.maneuvers.get(mv.name) is not None]
    tab = validation_change_table(p0, p1, both, alpha=alpha)
    rows = tab.to_dict(orient="records")
    bad = [r for r in rows if r["significant rise"] and (joint or r["output"] != JOINT)]
    parts = []
    if lost:
        why = [m for m in p1.problems if any(f"maneuver {n}:" in m for n in lost)] or p1.problems[:1]
        parts.append(f"could not be replayed on validation record(s) {', '.join(lost)} ({'; '.join(why)})")
    if bad:
        parts.append("made the validation error rise significantly on " + ", ".join(
            f"{r['output']} ({r['change [%]']:+.1f} %, p = {r['p (rise)']:.2g})" for r in bad))
    if len(both) < len(val_mans) and not lost:  # the kept model does not replay them: the test runs on the others
        parts.append(("tested on no validation record" if not both else "tested without validation record(s) "
                      + ", ".join(mv.name for mv in val_mans if mv not in both))
                     + ": the kept model could not replay " + ("them" if both else "any"))
    return {"rise": bool(bad or lost), "rows": rows, "message": "; ".join(parts), "not_replayed": lost}


def backward_check(cfg: IdentificationConfig, record: dict, base_names, level: float) -> list[dict]:
    """Wald test of every loop-added effect's strength but the last added (forward selection's backward check), from
    the Cramer-Rao standard errors at the diagnosed point; a strength without one (at a bound, or none computed) is a
    row with ``significant`` None and a note: not tested, so not removed. ``level``: the level a
    term entered at (the structure step's alpha / L), so that every term of a kept model stays significant at the level
    it needed to enter, as in stepwise regression with equal F-to-enter and F-to-remove."""
    from scipy.stats import norm

    se = record.get("standard_errors") or {}
    added = [e for e in cfg.model.extensions if e.name not in base_names][:-1]
    rows = []
    for e in added:
        s = se.get(e.strength)
        if not s or s <= 0 or e.strength not in record["parameters"]:
            # not tested, and said so (a strength at a bound has no standard error; none without [loop] uncertainty)
            rows.append({"name": e.name, "strength": e.strength, "z": math.nan, "p": math.nan, "level": level,
                         "significant": None, "note": "not tested: no standard error (at a bound, or none computed)"})
            continue
        z = record["parameters"][e.strength] / s
        p = float(norm.sf(z) if getattr(e, "one_sided", False) else 2 * norm.sf(abs(z)))
        rows.append({"name": e.name, "strength": e.strength, "z": float(z), "p": p, "level": level,
                     "significant": p < level})
    return rows


def term_to_drop(backward: list[dict]) -> dict | None:
    """The row of :func:`backward_check` whose term the loop removes: of those no longer significant, the least
    significant (largest p), as stepwise regression removes; None when every tested term stays (or none was
    tested)."""
    out = [b for b in backward if b["significant"] is False]
    return max(out, key=lambda b: b["p"]) if out else None


def select_shape(cfg: IdentificationConfig, cand, file: Path, alpha: float,
                 progress=info) -> tuple[IdentificationConfig, dict]:
    """The shape rule: a candidate's shape parameters from the time series, tested against their defaults.

    ``cfg`` already has the candidate in its model with its strength free. Anchor A (min J_time, the
    time series alone) is solved twice on one NLP: with the shape parameters pinned at their defaults
    (by equal bounds), then freed, starting from the first solution. J_time is the negative
    log-likelihood (Eq. 5-6), so LR = 2 (J_A,default - J_A,free) is chi^2 with one degree of freedom per
    shape parameter when the default shape is right (nominal level for white residuals; a misfit that is
    still coloured makes the test liberal, which here only means the fitted shape is used). If
    p < ``alpha`` the shape is held at A's values, otherwise at the defaults; the returned config has
    them fixed in its model for the whole front. Why not free along the front: the trim anchor B would
    then trade the shape against the tail lift slope (docs/close_loop.md, "How much of the full-size
    miss is the candidate's form?"). The decision is written to ``file`` and read back when the same
    config asks again, so a rerun of the loop resumes without solving it again.
    """
    from scipy.stats import chi2

    from ..pareto.front import ParetoSolver

    names = list(cand.shape_parameters)
    specs = {n: cfg.model.parameters.spec(n) for n in names}
    for n, spec in specs.items():
        if not spec.bounds or not spec.bounds[0] <= spec.value <= spec.bounds[1]:
            raise ConfigError(f"candidate {cand.name}: shape parameter {n} needs bounds around its default "
                              f"{spec.value} to be fitted (got {spec.bounds}); declare them in its ParameterSpec")
    free = list(cfg.free) + [FreeParameter(n, specs[n].value, *specs[n].bounds, specs[n].scale or 1.0) for n in names]
    cfg_s = dataclasses.replace(cfg, free=free)
    key = {"fingerprint": identification_fingerprint(cfg_s), "initial": {f.name: f.initial for f in free}}
    doc = None
    if file.is_file():
        try:
            doc = json.loads(file.read_text())
        except ValueError as exc:  # damaged (not by a kill: written whole or not at all): decide again
            progress(f"  warning: {file}: unreadable shape decision ({exc}); deciding it again")
        if not isinstance(doc, dict) or not isinstance(doc.get("values"), dict) or "decision" not in doc:
            if doc is not None:
                progress(f"  warning: {file}: not a shape decision of this loop; deciding it again")
            doc = None
        if doc is not None and doc.get("key") == key:
            progress(f"  shape of {cand.name}: reusing {file} ({doc['decision']})")
            return dataclasses.replace(cfg, model=cfg.model.with_parameters(**doc["values"])), doc
    t0 = time.perf_counter()
    m, _, _ = build_problem(cfg_s)
    ps = ParetoSolver(m, cfg.pareto)
    for n in names:  # pinned at the defaults by equal bounds: the same NLP serves both solves
        v = specs[n].value / m.theta_scale[n]
        m.theta_s[n].setlb(v)
        m.theta_s[n].setub(v)
        m.theta_s[n].set_value(v)
    a0 = ps.point_a()
    for f in free[len(cfg.free):]:
        m.theta_s[f.name].setlb(f.lower / f.scale)
        m.theta_s[f.name].setub(f.upper / f.scale)
    a1 = ps.point_a()
    doc = {"key": key, "candidate": cand.name, "defaults": {n: specs[n].value for n in names},
           "A_default": {"J_time": a0.J_time, "parameters": a0.parameters, "success": a0.success,
                         "status": a0.status, "iterations": a0.iterations},
           "A_free": {"J_time": a1.J_time, "parameters": a1.parameters, "success": a1.success,
                      "status": a1.status, "iterations": a1.iterations}}
    if a0.success and a1.success:
        lr = max(2.0 * (a0.J_time - a1.J_time), 0.0)
        pval = float(chi2.sf(lr, len(names)))
        fitted = pval < alpha
        doc.update(LR=lr, dof=len(names), p=pval, alpha=alpha)
        doc["decision"] = (f"fitted at anchor A (LR {lr:.4g}, p = {pval:.3g} < {alpha:g})" if fitted
                           else f"defaults kept (LR {lr:.4g}, p = {pval:.3g} >= {alpha:g})")
    else:
        fitted = False
        doc["decision"] = f"defaults kept (anchor A solves: {a0.status}; {a1.status})"
    doc["values"] = {n: (a1.parameters[n] if fitted else specs[n].value) for n in names}
    doc["wall_time"] = time.perf_counter() - t0
    write_json(file, doc)
    progress(f"  shape of {cand.name}: {doc['decision']}: "
             + ", ".join(f"{n} = {v:.4g}" for n, v in doc["values"].items()))
    return dataclasses.replace(cfg, model=cfg.model.with_parameters(**doc["values"])), doc
