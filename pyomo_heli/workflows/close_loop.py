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

From iteration 1 on, the validation rule (``[loop] validation_rule``) compares each re-identified model with the
model kept so far on the validation records (paired test, :func:`validation_check`); a significant rise on any
output (with ``[loop] validation_joint``, also of all outputs at once) rejects the step. With ``[loop]
after_rejection = "next"`` (default) the loop then goes back to the kept model and runs its step again with the
rejected terms left out for the rest of the loop; ``"stop"`` stops there.
With ``[loop] discovery``, the name check: a physical candidate added at the last step (named by encompassing, or
taken by the library) must leave the generic family nothing significant at the next step (after a backward-check
drop, the step after that); when the best generic term is significant there, the candidate described the missing
effect only in part, and its step is rejected in the same way (``name_check`` in the record: that step; the loop
goes back to the model before the candidate came in and tries the next term).
With ``[loop] discovery``, the backward check as well: from the second added term on, an earlier added term whose
strength is no longer significant at the level it entered at (Wald, Cramer-Rao SE) is removed, not offered again,
and the model re-identified, past the iteration limit too; the validation rule judges the model without it as it
judges a step, and keeps the term when its removal makes the validation significantly worse.

``out/loop.json`` is rewritten as each iteration finishes, so nothing
finished is lost. Settings come from the config's ``[loop]`` table:
``max_iterations`` (identifications after the first, default 3; a backward-check removal goes past it),
``candidates`` (names, default the whole library), ``alpha``, ``ratio``,
``confound_corr``, ``robust``, ``point`` (``direct``: the Eq. 11 solution solved
directly, default; ``chosen``: the closest sampled front point) (see :mod:`pyomo_heli.diagnosis.attribution`),
``shape`` (``time_domain``: the shape rule, default; ``default``: shape parameters stay at their defaults),
``uncertainty`` (``chosen``: Cramer-Rao standard errors of A, the chosen point and the direct solve of every
iteration, default; ``none``). A finished
iteration found in ``out/iter_i`` (same config and dataset, model - including the source of its effects - free
parameters and input reference) is reused, not redone, and so is a finished structure step with discovery
(:func:`stored_step`, ``out/steps/``: the screen's NLP solves take minutes at full size).

``out`` is marked as a close-loop folder (``checkpoint.json`` with ``"what": "close-loop"``): another
command's results folder (identify's ``front.csv``, ``chosen.json``, ``points/``; multistart's ``starts.csv``)
is refused before anything is loaded or written, and ``identify`` or ``multistart`` refuse this one
(:func:`pyomo_heli.pareto.store.claim_folder`). A damaged ``iter_i/checkpoint.json`` is refused with one line
naming it (rerun with ``--restart``); an unreadable shape decision ``shape_i.json`` is decided again.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path

from ..config import ConfigError, IdentificationConfig, config_of_result, loop_table  # noqa: F401 - re-exported
from ..dataset import load_flight_test
from ..diagnosis import attribution as attr
from ..diagnosis.candidates import CANDIDATES, make_candidate
from ..log import get_logger, info
from ..physics.discrepancy import generic_names
from .identify import identification_fingerprint, run_identification, shape_values
from ..nlp.identification import identification_data, validation_maneuvers
from ..pareto.result import write_json
from ..pareto.store import read_checkpoint
from ..provenance import source_sha256
from ..report.loop import LOOP_FILE, limit_statement, load_loop, rejected_discovery, unexplained_statement  # noqa: F401 - load_loop re-exported (studies)
from .loop_steps import (_with_candidate, _without, backward_check, errors_of,  # noqa: F401 (tests)
                         select_shape, term_to_drop, validation_check)
from .run_folder import RunFolder

warning = get_logger(__name__).warning


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
    #: the generic family offered with ``discovery`` when ``generic`` is not given: "standard" or "extended"
    generic_family: str = "standard"
    #: the generic terms offered with ``discovery`` (names of pyomo_heli.physics.discrepancy; default the whole family)
    generic: list | None = None
    #: reject a step whose model makes the validation error rise significantly on any output (paired test)
    validation_rule: bool = True
    #: the validation rule also rejects a significant rise of all outputs' error at once (the joint paired test;
    #: reported in every validation check either way)
    validation_joint: bool = False
    #: after a rejected step: back to the kept model and its next significant term, the rejected terms left out for
    #: the rest of the loop ("next"), or stop with the kept model ("stop", the loops before 2026-11-27)
    after_rejection: str = "next"
    #: how a structure step ranks the screened generic terms: by the p it decides on ("p") or by the raw likelihood
    #: ratio ("likelihood_ratio"; pyomo_heli.diagnosis.discovery.best_fit)
    generic_rank: str = "p"


def loop_settings(cfg: IdentificationConfig) -> LoopSettings:
    """The ``[loop]`` table of an identification config (declared by
    :class:`pyomo_heli.settings.identification.LoopTable`, checked by :func:`pyomo_heli.config.loop_table` when
    the config is read)."""
    table = loop_table(cfg.raw.get("loop", {}), cfg.path, cfg.nlp.input_errors)
    return LoopSettings(**{k: list(v) if isinstance(v, list) else v for k, v in table.model_dump().items()})


class IdentificationFailed(RuntimeError):
    """An iteration's identification converged at no front point: the loop cannot go on (the input was fine)."""


#: the ``point`` of an iteration in loop.json when the direct Eq. 11 solve failed from every start
DIRECT_FAILED = "closest front point (direct solve failed)"


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
    return result.chosen, DIRECT_FAILED if which == "direct" else "closest front point"


def _finished(cfg: IdentificationConfig, folder: Path):
    """A finished identification of the same model, free parameters and config in ``folder``, or None.

    Lets a loop that was stopped resume without redoing finished fronts (nothing finished is lost).
    """
    from ..pareto.result import IdentificationResult

    if not (folder / "chosen.json").is_file():
        return None
    meta = folder / "checkpoint.json"  # written by every identification run (copies in docs/ may lack it)
    fingerprinted = meta.is_file()
    other_code = False
    if fingerprinted:
        from .identify import identification_fingerprint

        checkpoint = read_checkpoint(meta)
        if checkpoint.get("fingerprint") != identification_fingerprint(cfg):
            return None  # another config, data or setting (e.g. resample_inputs): not the same identification
        other_code = checkpoint.get("source") not in (None, source_sha256())
    try:
        res = IdentificationResult.load(folder)
    except (FileNotFoundError, ValueError, KeyError):
        return None
    from .identify import extension_forms

    # the fingerprint holds the config's tables and the dataset's content, so a moved folder resumes;
    # without it (copies) the same config and dataset files must be named
    same_files = fingerprinted or (Path(res.info.get("config", "")).resolve() == Path(cfg.path).resolve()
                                   and Path(res.info.get("dataset", "")).resolve() == Path(cfg.dataset).resolve())
    same = (res.info.get("shape_parameters", {}) == shape_values(cfg.model)
            and res.parameters == [f.name for f in cfg.free]
            and res.info.get("extensions") == [e.name for e in cfg.model.extensions]
            and res.info.get("extension_forms", {}) == extension_forms(cfg.model.extensions)
            and res.info.get("input_reference_s", 0.0) == cfg.input_reference_s
            and len(res.front) == cfg.pareto.points and same_files)
    if same:  # and the recorded maneuvers, dataset content and model (folders that record them)
        from ..provenance import ResultsMismatchError, check_results_match

        try:
            check_results_match(cfg, res, folder, warn=lambda msg: None)
        except ResultsMismatchError:
            return None
    if same and other_code:  # as identify does on resuming points: said, and marked in the record
        warning(f"{folder}: the finished identification was solved by other code (the package changed since); "
                f"reused as stored: rerun with --restart for results of this code alone")
        res.info["resumed_from_other_code"] = True
    return res if same else None


def analysis_settings(cfg: IdentificationConfig) -> dict:
    """What of a config the residual analysis depends on besides the model and its parameters: the inputs'
    resampling and the ``[diagnosis]`` input-noise model, replay and input-path family (``made_with`` of
    :func:`residual_verdict`: another setting is another analysis)."""
    noise = cfg.diagnosis_settings
    return {"resample_hz": cfg.resample_hz, "resample_inputs": cfg.resample_inputs,
            "input_noise": list(noise.input_noise), "replay": noise.replay,
            "input_path_family": noise.input_path_family}


def residual_verdict(cfg: IdentificationConfig, chosen: dict, progress=info) -> dict:
    """When nothing is accepted: is the residual noise only, or an unexplained residual with a signature?

    Uses the residual analysis of :mod:`pyomo_heli.diagnosis.analysis` (trim shapes, whiteness,
    coherence, the records' agreement on each output's bias, the input errors' regression on the flight's signals) on
    the chosen parameters. A failure is reported,
    not raised (the loop's results stand). ``made_with``: the settings it was made with (:func:`analysis_settings`).
    """
    try:
        from ..diagnosis.analysis import diagnose, verdict_status
        from ..diagnosis.residuals import compute_residuals

        d = diagnose(compute_residuals(cfg, chosen, label="chosen"))
    except Exception as exc:  # noqa: BLE001 - the verdict is an addition to finished results
        progress(f"residual diagnosis failed: {exc}")
        return {"status": f"failed: {exc}"}
    status = verdict_status(d.verdict)
    progress(f"residual diagnosis: {status}")
    out = {"status": status, "verdict": d.verdict, "findings": list(d.findings), "record_biases": d.record_biases,
           "input_path": d.input_path, "made_with": analysis_settings(cfg)}
    try:  # what the missing effect looks like at the trims, with no library (a pointer; the status stands)
        from ..dataset import load_flight_test
        from ..diagnosis.trim_forces import implied_forces

        ft = load_flight_test(cfg.dataset)
        forces = implied_forces(cfg.model.with_parameters(**chosen), ft.trims, ft.conventions, label="the model",
                                free=[p.name for p in cfg.free])
        out["trim_forces"] = {**forces.to_dict(), "findings": forces.findings()}
        out["findings"] += out["trim_forces"]["findings"]
        for f in out["trim_forces"]["findings"]:
            progress(f"residual diagnosis: {f}")
    except Exception as exc:  # noqa: BLE001 - as above
        progress(f"steady forces the trims ask for: failed: {exc}")
    return out


def score_test_inputs(cfg: IdentificationConfig, settings: LoopSettings) -> dict:
    """The score test's errors-in-variables arguments: the NLP's input errors, sigmas and AR order, unless the loop
    takes the measured inputs as exact (``[loop] score_inputs = "measured"``) or there are none."""
    if settings.score_inputs == "measured" or not cfg.nlp.input_errors:
        return {}
    return {"input_errors": cfg.nlp.input_errors, "noise_sigma": cfg.nlp.noise_sigma,
            **({"input_error_ar": cfg.nlp.input_error_ar} if cfg.nlp.input_error_ar else {})}


def close_loop(cfg: IdentificationConfig, out, settings: LoopSettings | None = None, progress=info,
               restart: bool = False) -> dict:
    """Run the loop; returns the content of ``loop.json`` (also written after every iteration).

    A rerun on the same ``out`` reuses the finished iterations and shape decisions of the same fingerprint
    (:func:`_finished`); ``restart`` discards them and identifies every iteration afresh."""
    settings = settings or loop_settings(cfg)
    # another command's results folder: refused before anything is done
    with RunFolder(out, "close-loop", cfg, restart) as run:
        ft = load_flight_test(cfg.dataset)
        id_data = identification_data(cfg, ft)
        val_mans = validation_maneuvers(cfg, ft)
        # the folder only once the data loaded (a bad dataset leaves no folder behind), locked for the loop's life;
        # SIGINT/SIGTERM stop it with Interrupted (finished iterations and points stay on disk, a rerun resumes)
        with run.locked():
            return _close_loop(cfg, run, settings, progress, ft, id_data, val_mans)


class LoopMismatchError(ValueError):
    """A finished loop in the folder was made from another config or flight test (the folder given is at fault)."""


def loop_inputs(config: str | Path, dataset: str | Path) -> dict:
    """What ``loop.json`` records of its inputs by content: the config file's text, the flight test's files and
    the package's sources (SHA-256 each; :mod:`pyomo_heli.provenance`)."""
    from ..provenance import config_sha256, dataset_sha256

    try:
        text = config_sha256(config)
    except OSError:  # a config no longer on disk (a run goes on from the parsed one): nothing to record
        text = None
    return {"config_sha256": text, "dataset_sha256": dataset_sha256(dataset), "source_sha256": source_sha256()}


def finished_loop(folder: str | Path, config: str | Path, dataset: str | Path) -> bool:
    """Whether ``folder`` holds a loop that stopped (``loop.json`` with its ``stopped`` message) made from this
    config file and flight test, both compared by content: what a study may reuse instead of running the loop.

    A loop not yet stopped (interrupted, or still running) is False: running close-loop again resumes it. A stopped
    loop made from another config text or flight test raises :class:`LoopMismatchError` naming the folder: reusing
    it would report another study's result. One made by other package sources is reused with a warning; one
    written before these records existed is reused with a warning that it was not checked."""
    doc_file = Path(folder) / LOOP_FILE
    if not doc_file.is_file():
        return False
    doc = json.loads(doc_file.read_text())
    if not doc.get("stopped"):
        return False
    now = loop_inputs(config, dataset)
    if "config_sha256" not in doc:
        warning(f"{folder}: a finished loop written before loops recorded their inputs; reused without checking "
                f"that it was made from {config} and {dataset}")
        return True
    for key, name, what, path in (("config_sha256", "config", "config", config),
                                  ("dataset_sha256", "dataset", "flight test", dataset)):
        if doc.get(key) != now[key]:
            raise LoopMismatchError(f"{folder}: its finished loop was made from another {what} ({doc.get(name)}), "
                                    f"not the content of {path}; give another output folder or remove it")
    if doc.get("source_sha256") != now["source_sha256"]:
        warning(f"{folder}: its finished loop was made by other package sources (the code changed since); reused as "
                f"it is: remove the folder for a result of this code")
    return True


#: where the structure steps of a discovery loop are kept (:func:`stored_step`)
STEPS_DIR = "steps"


def stored_step(folder: Path, inputs: dict, compute, restart: bool = False, progress=info) -> dict:
    """A structure step's result, computed once for these ``inputs`` and kept in ``folder/step_<digest>.json``.

    A loop that was stopped resumes without redoing a step it had finished (the steps after rejected iterations
    included): the result is read back when a step with the same inputs (the identification's fingerprint, the
    package's source, the parameters it starts from, the terms offered) was finished before. The result comes
    back through JSON whether computed now or read, so a resumed loop records the same as one that ran through. A
    damaged file is computed again; ``restart`` recomputes.
    """
    key = json.loads(json.dumps(inputs, sort_keys=True, default=str))
    path = Path(folder) / f"step_{hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]}.json"
    if not restart and path.is_file():
        try:
            doc = json.loads(path.read_text())
        except (OSError, ValueError):
            doc = None
        if isinstance(doc, dict) and doc.get("inputs") == key and "result" in doc:
            progress(f"  reusing the finished structure step in {path}")
            return doc["result"]
    result = compute()
    Path(folder).mkdir(parents=True, exist_ok=True)
    write_json(path, {"inputs": key, "result": result})
    return json.loads(path.read_text())["result"]


def _stop_message(doc: dict, reason: str) -> str:
    """Why the loop stops, and, when nothing was kept after a discovered term the validation rule rejected, what the
    missing effect looks like (that term's shape)."""
    unexplained = rejected_discovery(doc)
    return reason + ("; " + unexplained_statement(*unexplained) if unexplained else "")


def _reject(doc, record, krec, added, reason: str, rejected: list, settings, out, progress) -> bool:
    """The step of ``record`` (adding ``added``) rejected for ``reason`` (the validation rule or the name check),
    ``krec`` the record of the model kept. With ``after_rejection = "stop"`` the loop stops there (``loop.json``
    written; True); otherwise the record says which model the loop goes back to, and the terms left out (False)."""
    record["rejected"] = reason
    what = f"adding {added}" if added else "the step"
    if settings.after_rejection == "stop":
        doc["stopped"] = _stop_message(doc, f"step rejected: {what} {reason}; the model of iteration "
                                            f"{krec['iteration']} is kept")
        write_json(out / LOOP_FILE, doc)
        progress(f"stopped: {doc['stopped']}")
        return True
    # back to the kept model: its structure determination again, the rejected terms left out
    progress(f"step rejected: {what} {reason}; back to the model of iteration {krec['iteration']}, without "
             f"{', '.join(rejected)}")
    record["step_from"] = {"iteration": krec["iteration"], "without": list(rejected)}
    return False


def _entry_level(doc: dict, alpha: float) -> float:
    """The level the loop's terms entered at: the last structure step's alpha / L (Bonferroni over its library);
    ``alpha`` before any step."""
    steps = (r.get("discovery") or {} for r in reversed(doc["iterations"]))
    return next((s["level"] for s in steps if s.get("level")), alpha)


def _close_loop(cfg, run: RunFolder, settings, progress, ft, id_data, val_mans) -> dict:
    out, restart = run.root, run.restart
    run.mark()
    trims = ft.trims.reset_index(drop=True)
    doc = {"config": str(cfg.path), "dataset": str(cfg.dataset), **loop_inputs(cfg.path, cfg.dataset),
           "settings": dataclasses.asdict(settings), "units": "SI (rad, rad/s, m/s, g)", "iterations": [],
           "stopped": None}
    i = 0
    added_shape = None  # the shape rule's record for the candidate added last
    bar = run.progress_bar(settings.max_iterations + 1, "loop iterations", at_most=True)
    added = None  # the term the current iteration added (None: the first, or a backward-check drop)
    kept = None  # (config, record) of the model kept so far: the validation rule's reference
    kept_models = []  # every model kept so far, in order (the name check goes back past the last)
    unchecked = None  # a physical candidate added whose name check has not run (a backward-check drop may come first)
    rejected = []  # terms whose step the validation rule or the name check rejected: not offered again
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
            if settings.uncertainty != "none" and result.chosen is not None and "uncertainty" not in result.chosen:
                # stopped between the front and its standard errors (identify saves the front first): add them now,
                # or the kept model would go on without them (its terms "+- nan", the report the screen's)
                from ..uncertainty.front import add_uncertainty

                progress(f"  iteration {i}: the stored identification has no standard errors (stopped before "
                         f"them): computing them")
                add_uncertainty(result, cfg, identification_data(cfg, ft), out / f"iter_{i}",
                                lambda s: progress("  " + s), points=settings.uncertainty)
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
        record = {
            "iteration": i, "extensions": names, "results_dir": f"iter_{i}",
            "free": [f.name for f in cfg.free], "parameters": chosen,
            "units": {n: cfg.model.parameters.spec(n).unit for n in chosen},
            "shape_parameters": shape_values(cfg.model), "shape_selection": added_shape,
            "point": which, "J_time": point["J_time"], "J_trim": point["J_trim"],
            # Cramer-Rao standard errors at the diagnosed point (None: not computed, or at a bound)
            "standard_errors": (point.get("uncertainty") or {}).get("se"),
            **({"resumed_from_other_code": True} if result.info.get("resumed_from_other_code") else {}),
            **errs}
        doc["iterations"].append(record)
        # the validation rule: a step whose model validates significantly worse on any output is rejected
        if i > 0 and settings.validation_rule and val_mans:
            kcfg, krec = kept
            check = validation_check(kcfg.model, krec["parameters"], cfg.model, chosen, val_mans,
                                     joint=settings.validation_joint)
            record["validation_check"] = check["rows"]
            if check["message"] and not check["rise"]:  # records left out of a passed test: said, not dropped
                record["validation_note"] = check["message"]
            if check["rise"]:
                if added is not None:
                    rejected.append(added)
                if _reject(doc, record, krec, added, check["message"], rejected, settings, out, progress):
                    return doc
                cfg, chosen = kcfg, krec["parameters"]
        elif i > 0 and settings.validation_rule:  # on, with nothing to judge on: said in the record, not silent
            record["validation_note"] = ("no validation record ([data] validation): the validation rule could not "
                                         "judge this step")
            progress(f"  iteration {i}: {record['validation_note']}")
        if not record.get("rejected"):
            kept = (cfg, record)
            kept_models.append(kept)
            doc["final_iteration"] = i
        names = [e.name for e in cfg.model.extensions]
        model = cfg.model.with_parameters(**chosen)
        pool = settings.candidates or list(CANDIDATES)
        left = [n for n in pool if n not in names and n not in rejected]
        att, add, init = None, None, None
        # the backward check once per kept model (not again after a rejected step), at the level the terms entered at
        backward = (backward_check(cfg, record, base_names, _entry_level(doc, settings.alpha))
                    if settings.discovery and not record.get("rejected") else [])
        if backward:
            record["backward_check"] = backward
        b = term_to_drop(backward)
        if b is not None:  # past the iteration limit too; the validation rule judges the model without it as any step
            record["decision"] = {"decision": "dropped", "name": b["name"],
                                  "message": f"backward check: {b['name']} no longer "
                                  f"significant (Wald p = {b['p']:.2g} >= {b['level']:.2g})"}
            write_json(out / LOOP_FILE, doc)
            progress(record["decision"]["message"] + "; removed, not offered again")
            rejected.append(b["name"])
            cfg = _without(cfg, chosen, b["name"])
            added_shape, added = None, None
            i += 1
            continue
        if settings.discovery:
            from ..diagnosis.discovery import discovery_step

            def structure_step(cfg, model, chosen, left):
                family = settings.generic or generic_names(settings.generic_family)
                generic = [n for n in family if n not in rejected]
                # a rejected generic term is not added again, but a physical candidate must still encompass it
                rejected_generic = [n for n in family if n in rejected]
                # the fingerprint holds the config (its [loop] settings too), the data and the model's extensions;
                # the source digest: a step made by other code is not reused
                inputs = {"fingerprint": identification_fingerprint(cfg), "source": source_sha256(),
                          "parameters": chosen, "physical": list(left), "generic": generic,
                          "rejected_generic": rejected_generic}
                return stored_step(out / STEPS_DIR, inputs, lambda: discovery_step(
                    cfg, model, chosen, id_data, physical=left, generic=generic,
                    rejected_generic=rejected_generic, alpha=settings.alpha,
                    ratio=settings.ratio, confound_corr=settings.confound_corr, robust=settings.robust,
                    score_kw=score_test_inputs(cfg, settings), rank=settings.generic_rank, progress=progress),
                    restart, progress)

            step = structure_step(cfg, model, chosen, left)
            # the name check, at the first structure step of a model holding the physical candidate added last
            # (the next iteration's, or after a backward-check drop the one after); not when its step was rejected
            named, unchecked = (unchecked if unchecked in names else None), None
            if named and step.get("generic_significant"):
                # a physical candidate must leave the generic family nothing significant; one that does not
                # describes the missing effect only in part (docs/discovery.md): the step that added it is rejected
                G = step.get("most_significant_generic_fit") or step["best_generic_fit"]
                record["name_check"] = {k: v for k, v in step.items() if k != "attribution"}
                rejected.append(named)
                while named in [e.name for e in kept_models[-1][0].model.extensions]:  # back to before it came in
                    kept_models.pop()
                kcfg, krec = kept = kept_models[-1]
                doc["final_iteration"] = krec["iteration"]
                if _reject(doc, record, krec, named, f"left the generic term {G['name']} significant (p = "
                           f"{G['p']:.2g} < {step['level']:.2g}): a physical candidate must account for the whole "
                           "missing effect (name check)", rejected, settings, out, progress):
                    return doc
                cfg, chosen = kcfg, krec["parameters"]
                names = [e.name for e in cfg.model.extensions]
                model = cfg.model.with_parameters(**chosen)
                left = [n for n in pool if n not in names and n not in rejected]
                step = structure_step(cfg, model, chosen, left)
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
                                 **score_test_inputs(cfg, settings))
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
            doc["stopped"] = _stop_message(doc, "every candidate of the library is in the model" + (
                f" or was rejected ({', '.join(rejected)})" if rejected else ""))
        elif add is None:
            trims = (record["residual_diagnosis"].get("trim_forces") or {}).get("findings", [])
            doc["stopped"] = _stop_message(doc, f"nothing accepted ({decision}): {message}"
                                           + "".join(f"; {f}" for f in trims))
        elif i >= settings.max_iterations:
            doc["stopped"] = _stop_message(doc, f"iteration limit {settings.max_iterations} reached; {add} would be "
                                                "added next" + limit_statement(record))
        write_json(out / LOOP_FILE, doc)
        progress(f"iteration {i} finished" + bar.tick(from_disk=reused))
        if doc["stopped"]:
            progress(f"stopped: {doc['stopped']}")
            return doc
        progress(f"adding {add} with {make_candidate(add).strength} free (estimate {init:.4g})")
        cfg = _with_candidate(cfg, chosen, add, init)
        added = add
        if add in CANDIDATES:
            unchecked = add
        cand = cfg.model.extensions[-1]
        added_shape = None
        if cand.shape_parameters and settings.shape == "time_domain":
            shape_file = out / f"shape_{i + 1}.json"
            if restart and shape_file.is_file():
                shape_file.unlink()
            cfg, added_shape = select_shape(cfg, cand, shape_file, settings.alpha, progress)
        i += 1


