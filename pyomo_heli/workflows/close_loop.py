"""Close the loop: identify, attribute the residual, add the accepted effect, re-identify, repeat.

``close_loop(cfg, out)`` runs, for iteration i = 0, 1, ...:

1. the whole identification (Pareto front, utopia choice) with the current
   model (:func:`pyomo_heli.workflows.identify.run_identification`) into ``out/iter_i``;
2. the errors of the model at the diagnosed point (``[loop] point``): RMS of data minus model per output on the
   identification and the validation maneuvers and per trim channel
   (float-model replay of :mod:`pyomo_heli.report.identification`);
3. the attribution (:func:`pyomo_heli.diagnosis.attribution.attribute`);
4. if nothing is accepted: the residual analysis says whether what is left is
   noise only or an "unexplained residual", with its signature (trim shapes,
   whiteness, coherence: :mod:`pyomo_heli.diagnosis.analysis`);
5. if a candidate is accepted and the iteration limit is not reached: add it
   to the model with its strength free (initial value: the score test's
   one-step estimate, clipped to the bounds; the other free parameters start
   from this iteration's chosen values) and go on. A candidate with shape
   parameters (the wake's profile order) gets them by the shape rule first
   (:func:`select_shape`): freed at the time-domain anchor A only, kept there
   if a likelihood-ratio test against their defaults is significant, and held
   fixed along the whole front.

``out/loop.json`` is rewritten as each iteration finishes, so nothing
finished is lost. Settings come from the config's ``[loop]`` table:
``max_iterations`` (identifications after the first, default 3),
``candidates`` (names, default the whole library), ``alpha``, ``ratio``,
``confound_corr``, ``robust``, ``point`` (``direct``: the Eq. 11 solution solved
directly, default; ``chosen``: the closest sampled front point) (see :mod:`pyomo_heli.diagnosis.attribution`),
``shape`` (``time_domain``: the shape rule, default; ``default``: shape parameters stay at their defaults),
``uncertainty`` (``chosen``: Cramer-Rao standard errors of A, the chosen point and the direct solve of every
iteration, default; ``none``). A finished
iteration found in ``out/iter_i`` (same config and dataset, model - including the source of its effects - free
parameters and input reference) is reused, not redone.

``out`` is marked as a close-loop folder (``checkpoint.json`` with ``"what": "close-loop"``): another
command's results folder (identify's ``front.csv``, ``chosen.json``, ``points/``; multistart's ``starts.csv``)
is refused before anything is loaded or written, and ``identify`` or ``multistart`` refuse this one
(:func:`pyomo_heli.pareto.store.claim_folder`). A damaged ``iter_i/checkpoint.json`` is refused with one line
naming it (rerun with ``--restart``); an unreadable shape decision ``shape_i.json`` is decided again.
"""
from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path

from .. import interrupts
from ..config import ConfigError, IdentificationConfig, config_of_result  # noqa: F401 - re-exported
from ..dataset import load_flight_test
from ..diagnosis import attribution as attr
from ..diagnosis.candidates import CANDIDATES, make_candidate, model_with_candidates
from ..log import Progress, config_and_dataset, info, results_folder
from .identify import build_problem, identification_fingerprint, run_identification, shape_values
from ..nlp.identification import identification_data, prepare_data
from ..nlp.parameters import FreeParameter
from ..pareto.result import write_json
from ..pareto.store import FolderLock, claim_folder, read_checkpoint, write_checkpoint
from ..physics.model import HelicopterModel
from ..settings import Problems, validate
from ..settings.identification import LoopTable
from ..report.identification import CURVE_SPEEDS, predict, trim_rms, validation_rms
from ..report.loop import LOOP_FILE, load_loop  # noqa: F401 - load_loop re-exported (studies)


@dataclass
class LoopSettings:
    max_iterations: int = 3
    candidates: list | None = None
    alpha: float = attr.ALPHA
    ratio: float = attr.RATIO
    confound_corr: float = attr.CONFOUND_CORR
    robust: bool = True
    point: str = "direct"
    shape: str = "time_domain"
    uncertainty: str = "chosen"
    #: with [objectives] input_errors: the score test eliminates the input errors ("eliminated") or takes the
    #: measured inputs as exact ("measured", the test of the loops before 2026-11-24 evening)
    score_inputs: str = "eliminated"
    #: structure determination over the physical candidates and the generic discrepancy family, physics named by
    #: encompassing (pyomo_heli.diagnosis.discovery; docs/discovery.md)
    discovery: bool = False
    #: the generic terms offered with ``discovery`` (names of pyomo_heli.physics.discrepancy; default the whole family)
    generic: list | None = None
    #: reject a step whose model makes the validation error rise significantly on any output (paired test)
    validation_rule: bool = True


def loop_settings(cfg: IdentificationConfig) -> LoopSettings:
    """The ``[loop]`` table of an identification config (declared by
    :class:`pyomo_heli.settings.identification.LoopTable`), checked; every error names its field."""
    raw = cfg.raw.get("loop", {})
    problems = Problems(str(cfg.path))
    if not isinstance(raw, dict):
        problems.add("loop", "must be a table")
        problems.raise_if_any()
    table = validate(LoopTable, raw, problems, "loop")
    if table is not None:
        for n in table.candidates or ():
            if n not in CANDIDATES:
                problems.add("loop", f"field 'candidates': unknown candidate {n!r}; choose from "
                                     f"{', '.join(CANDIDATES)}")
    problems.raise_if_any()
    return LoopSettings(**{k: list(v) if isinstance(v, list) else v for k, v in table.model_dump().items()})


def errors_of(model: HelicopterModel, params: dict, id_mans, val_mans, trims, label: str) -> dict:
    """RMS of data minus model (SI) per output on identification and validation maneuvers and per trim channel."""
    speeds = list(trims["V"]) + list(CURVE_SPEEDS)
    pred = predict(label, model, params, speeds, list(id_mans) + list(val_mans))
    return {"identification_rms": validation_rms(pred, id_mans)["all"],
            "validation_rms": validation_rms(pred, val_mans)["all"] if val_mans else {},
            "trim_rms": trim_rms(pred, trims)["all"], "problems": pred.problems}


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
    """``cfg`` without the loop-added effect ``name`` (backward check); the other free parameters start at
    ``chosen``."""
    exts = tuple(e for e in cfg.model.extensions if e.name != name)
    gone = next(e for e in cfg.model.extensions if e.name == name)
    model = HelicopterModel(parameters=cfg.model.parameters, extensions=exts).with_parameters(**{gone.strength: 0.0})
    free = [dataclasses.replace(f, initial=min(max(chosen[f.name], f.lower), f.upper)) for f in cfg.free
            if f.name != gone.strength]
    return dataclasses.replace(cfg, model=model, free=free)


def validation_check(model0: HelicopterModel, params0: dict, model1: HelicopterModel, params1: dict, val_mans,
                     alpha: float = 0.01) -> dict:
    """The validation rule: the paired test (Diebold-Mariano, :mod:`pyomo_heli.diagnosis.validation_change`) of each
    output's validation error, model 1 against model 0 on the same records. ``rise``: True when any output's error
    rises significantly (one-sided p < ``alpha``); ``rows``: the test table as records; ``message`` names them."""
    from ..report.loop import validation_change_table

    p0 = predict("before", model0, params0, [], val_mans)
    p1 = predict("after", model1, params1, [], val_mans)
    tab = validation_change_table(p0, p1, val_mans, alpha=alpha)
    rows = tab.to_dict(orient="records")
    bad = [r for r in rows if r["significant rise"]]
    msg = ("made the validation error rise significantly on " + ", ".join(
        f"{r['output']} ({r['change [%]']:+.1f} %, p = {r['p (rise)']:.2g})" for r in bad)) if bad else ""
    return {"rise": bool(bad), "rows": rows, "message": msg}


def backward_check(cfg: IdentificationConfig, record: dict, base_names, alpha: float) -> list[dict]:
    """Wald test of every loop-added effect's strength but the last added (forward selection's backward check), from
    the Cramer-Rao standard errors at the diagnosed point; skipped for a strength without one."""
    from scipy.stats import norm

    se = record.get("standard_errors") or {}
    added = [e for e in cfg.model.extensions if e.name not in base_names][:-1]
    rows = []
    for e in added:
        s = se.get(e.strength)
        if not s or s <= 0 or e.strength not in record["parameters"]:
            continue
        z = record["parameters"][e.strength] / s
        p = float(norm.sf(z) if getattr(e, "one_sided", False) else 2 * norm.sf(abs(z)))
        rows.append({"name": e.name, "strength": e.strength, "z": float(z), "p": p, "significant": p < alpha})
    return rows


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


class IdentificationFailed(RuntimeError):
    """An iteration's identification converged at no front point: the loop cannot go on (the input was fine)."""


def _diagnosed_point(result, which: str) -> tuple[dict, str]:
    """The point of the front the loop diagnoses and reports.

    ``direct``: the Eq. 11 solution solved directly (the utopia-closest point of the continuous
    front), so that a coarse front (few points, as the loop's time budget needs) does not decide
    the compromise; the closest sampled point if that solve failed. ``chosen``: the closest sampled
    front point (the identification report's C).
    """
    d = result.direct
    if which == "direct" and d and d.get("success"):
        return d, "Eq. 11 direct"
    return result.chosen, "closest front point" + (" (direct solve failed)" if which == "direct" else "")


def _finished(cfg: IdentificationConfig, folder: Path):
    """A finished identification of the same model, free parameters and config in ``folder``, or None.

    Lets a loop that was stopped resume without redoing finished fronts (nothing finished is lost).
    """
    from ..pareto.result import IdentificationResult

    if not (folder / "chosen.json").is_file():
        return None
    meta = folder / "checkpoint.json"  # written by every identification run (copies in docs/ may lack it)
    if meta.is_file():
        from .identify import identification_fingerprint

        if read_checkpoint(meta).get("fingerprint") != identification_fingerprint(cfg):
            return None  # another config, data or setting (e.g. resample_inputs): not the same identification
    try:
        res = IdentificationResult.load(folder)
    except (FileNotFoundError, ValueError, KeyError):
        return None
    from .identify import extension_forms

    same = (res.info.get("shape_parameters", {}) == shape_values(cfg.model)
            and res.parameters == [f.name for f in cfg.free]
            and res.info.get("extensions") == [e.name for e in cfg.model.extensions]
            and res.info.get("extension_forms", {}) == extension_forms(cfg.model.extensions)
            and res.info.get("input_reference_s", 0.0) == cfg.input_reference_s
            and Path(res.info.get("config", "")).resolve() == Path(cfg.path).resolve()
            and Path(res.info.get("dataset", "")).resolve() == Path(cfg.dataset).resolve()
            and len(res.front) == cfg.pareto.points)
    if same:  # and the recorded maneuvers, dataset content and model (folders that record them)
        from ..provenance import ResultsMismatchError, check_results_match

        try:
            check_results_match(cfg, res, folder, warn=lambda msg: None)
        except ResultsMismatchError:
            return None
    return res if same else None


def residual_verdict(cfg: IdentificationConfig, chosen: dict, progress=info) -> dict:
    """When nothing is accepted: is the residual noise only, or an unexplained residual with a signature?

    Uses the residual analysis of :mod:`pyomo_heli.diagnosis.analysis` (trim shapes, whiteness,
    coherence) on the chosen parameters. A failure is reported, not raised (the loop's results stand).
    """
    try:
        from ..diagnosis.analysis import diagnose
        from ..diagnosis.residuals import compute_residuals

        d = diagnose(compute_residuals(cfg, chosen, label="chosen"))
    except Exception as exc:  # noqa: BLE001 - the verdict is an addition to finished results
        progress(f"residual diagnosis failed: {exc}")
        return {"status": f"failed: {exc}"}
    status = "noise only" if d.verdict.get("noise_only") else "unexplained residual"
    progress(f"residual diagnosis: {status}")
    return {"status": status, "verdict": d.verdict, "findings": d.findings}


def _score_inputs(cfg: IdentificationConfig, settings: LoopSettings) -> dict:
    """The score test's errors-in-variables arguments: the NLP's input errors and sigmas, unless the loop
    takes the measured inputs as exact (``[loop] score_inputs = "measured"``) or there are none."""
    if settings.score_inputs == "measured" or not cfg.nlp.input_errors:
        return {}
    return {"input_errors": cfg.nlp.input_errors, "noise_sigma": cfg.nlp.noise_sigma}


@results_folder("out", config_and_dataset)
def close_loop(cfg: IdentificationConfig, out, settings: LoopSettings | None = None, progress=info,
               restart: bool = False) -> dict:
    """Run the loop; returns the content of ``loop.json`` (also written after every iteration).

    A rerun on the same ``out`` reuses the finished iterations and shape decisions of the same fingerprint
    (:func:`_finished`); ``restart`` discards them and identifies every iteration afresh."""
    settings = settings or loop_settings(cfg)
    out = Path(out)
    claim_folder(out, "close-loop", restart)  # another command's results folder: refused before anything is done
    ft = load_flight_test(cfg.dataset)
    id_data = identification_data(cfg, ft)
    val_mans = (list(prepare_data(ft, cfg.validation, input_reference_s=cfg.input_reference_s).maneuvers)
                if cfg.validation else [])
    # the folder only once the data loaded (a bad dataset leaves no folder behind), locked for the loop's life;
    # SIGINT/SIGTERM stop it with Interrupted (finished iterations and points stay on disk, a rerun resumes)
    with interrupts.guard(), FolderLock(out, "close-loop"):
        return _close_loop(cfg, out, settings, progress, restart, ft, id_data, val_mans)


def _close_loop(cfg, out: Path, settings, progress, restart, ft, id_data, val_mans) -> dict:
    write_checkpoint(out, "close-loop")
    trims = ft.trims.reset_index(drop=True)
    doc = {"config": str(cfg.path), "dataset": str(cfg.dataset), "settings": dataclasses.asdict(settings),
           "units": "SI (rad, rad/s, m/s, g)", "iterations": [], "stopped": None}
    i = 0
    added_shape = None  # the shape rule's record for the candidate added last
    bar = Progress(settings.max_iterations + 1, "loop iterations", at_most=True)
    models = []  # the model of every finished iteration (the validation rule compares the last two)
    base_names = [e.name for e in cfg.model.extensions]  # declared by the config: never dropped by the loop
    while True:
        t0 = time.perf_counter()
        names = [e.name for e in cfg.model.extensions]
        progress(f"iteration {i}: model M0{''.join(' + ' + n for n in names)}; free "
                 f"{', '.join(f.name for f in cfg.free)}")
        result = None if restart else _finished(cfg, out / f"iter_{i}")
        reused = result is not None
        if result is not None:
            progress(f"  iteration {i}: reusing the finished identification in {out / f'iter_{i}'}")
        else:
            result = run_identification(cfg, out / f"iter_{i}", progress=lambda s: progress("  " + s),
                                        restart=restart,
                                        uncertainty=settings.uncertainty if settings.uncertainty != "none" else False)
        if result.chosen is None:
            raise IdentificationFailed(f"iteration {i}: no front point converged, nothing to diagnose; every status "
                                       f"is in {out / f'iter_{i}' / 'front.csv'}")
        if result.info.get("unreliable"):
            raise IdentificationFailed(f"iteration {i}: {result.info['unreliable']['reason']}; the utopia point and "
                                       f"the Eq. 11 choice are unreliable, nothing to diagnose (statuses in "
                                       f"{out / f'iter_{i}' / 'front.csv'})")
        point, which = _diagnosed_point(result, settings.point)
        # in the free parameters' order, whether the point was just solved or read back from disk
        chosen = {**{f.name: point["parameters"][f.name] for f in cfg.free if f.name in point["parameters"]},
                  **point["parameters"]}
        errs = errors_of(cfg.model, chosen, id_data.maneuvers, val_mans, trims, f"iteration {i}")
        model = cfg.model.with_parameters(**chosen)
        pool = settings.candidates or list(CANDIDATES)
        left = [n for n in pool if n not in names]
        record = {
            "iteration": i, "extensions": names, "results_dir": f"iter_{i}",
            "free": [f.name for f in cfg.free], "parameters": chosen,
            "units": {n: cfg.model.parameters.spec(n).unit for n in chosen},
            "shape_parameters": shape_values(cfg.model), "shape_selection": added_shape,
            "point": which, "J_time": point["J_time"], "J_trim": point["J_trim"],
            # Cramer-Rao standard errors at the diagnosed point (None: not computed, or at a bound)
            "standard_errors": (point.get("uncertainty") or {}).get("se"),
            **errs}
        doc["iterations"].append(record)
        # the validation rule: a step whose model validates significantly worse on any output is rejected
        if i > 0 and settings.validation_rule and val_mans:
            check = validation_check(models[-1], doc["iterations"][-2]["parameters"], cfg.model, chosen, val_mans)
            record["validation_check"] = check["rows"]
            if check["rise"]:
                record["rejected"] = check["message"]
                doc["final_iteration"] = i - 1
                doc["stopped"] = (f"step rejected: adding {names[-1]} {check['message']}; the model of iteration "
                                  f"{i - 1} is kept")
                write_json(out / LOOP_FILE, doc)
                progress(f"stopped: {doc['stopped']}")
                return doc
        doc["final_iteration"] = i
        att, add, init = None, None, None
        models.append(cfg.model)
        backward = backward_check(cfg, record, base_names, settings.alpha) if settings.discovery else []
        if backward:
            record["backward_check"] = backward
        dropped = [b["name"] for b in backward if not b["significant"]]
        if dropped and i < settings.max_iterations:
            p_drop = next(b["p"] for b in backward if b["name"] == dropped[0])
            record["decision"] = {"decision": "dropped", "message": f"backward check: {dropped[0]} no longer "
                                  f"significant (Wald p = {p_drop:.2g})"}
            write_json(out / LOOP_FILE, doc)
            progress(record["decision"]["message"] + "; removed")
            cfg = _without(cfg, chosen, dropped[0])
            added_shape = None
            i += 1
            continue
        if settings.discovery:
            from ..diagnosis.discovery import discovery_step

            step = discovery_step(cfg, model, chosen, id_data, physical=left, generic=settings.generic,
                                  alpha=settings.alpha, ratio=settings.ratio, confound_corr=settings.confound_corr,
                                  robust=settings.robust, score_kw=_score_inputs(cfg, settings), progress=progress)
            att = attr.Attribution.from_dict(step["attribution"])
            record["attribution"] = step.pop("attribution")
            record["discovery"] = step
            add, init = step["added"], step["initial"]
            decision, message = step["decision"], step["message"]
            progress(f"discovery: {decision}: {message}")
        elif left:
            att = attr.attribute(model, [f.name for f in cfg.free], id_data, cfg.nlp.time_outputs,
                                 cfg.nlp.trim_outputs, candidates=left, alpha=settings.alpha, ratio=settings.ratio,
                                 confound_corr=settings.confound_corr, robust=settings.robust,
                                 **_score_inputs(cfg, settings))
            progress(str(att))
            record["attribution"] = att.to_dict()
            decision, message = att.decision, att.message
            if att.decision == "accepted":
                add, init = att.accepted, float(att.accepted_row()["kappa_hat"])
        else:
            record["attribution"] = None
        record["wall_time"] = time.perf_counter() - t0
        if att is not None and add is None:
            record["residual_diagnosis"] = residual_verdict(cfg, chosen, progress)
        if att is None:
            doc["stopped"] = "every candidate of the library is in the model"
        elif add is None:
            doc["stopped"] = f"nothing accepted ({decision}): {message}"
        elif i >= settings.max_iterations:
            doc["stopped"] = f"iteration limit {settings.max_iterations} reached; {add} would be added next"
        write_json(out / LOOP_FILE, doc)
        progress(f"iteration {i} finished" + bar.tick(from_disk=reused))
        if doc["stopped"]:
            progress(f"stopped: {doc['stopped']}")
            return doc
        progress(f"adding {add} with {make_candidate(add).strength} free (estimate {init:.4g})")
        cfg = _with_candidate(cfg, chosen, add, init)
        cand = cfg.model.extensions[-1]
        added_shape = None
        if cand.shape_parameters and settings.shape == "time_domain":
            shape_file = out / f"shape_{i + 1}.json"
            if restart and shape_file.is_file():
                shape_file.unlink()
            cfg, added_shape = select_shape(cfg, cand, shape_file, settings.alpha, progress)
        i += 1


