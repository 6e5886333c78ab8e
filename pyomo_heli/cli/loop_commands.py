"""The loops and their diagnosis: ``close-loop``, ``trim-loop``, ``diagnose`` and ``check-effect``."""
from __future__ import annotations

import math
import sys
from pathlib import Path

from .folders import (_check_diagnosis_out, _check_out_dir, _check_out_file, _check_out_not_foreign, _point_parameters,
                      _results_folder, _solver_status_line, _warning)
from .options import UserError

def cmd_close_loop(args) -> int:
    from ..workflows.close_loop import close_loop, loop_settings
    from ..config import load_identification_config
    from ..report.loop import write_loop_report


    overrides = None
    if args.dataset is not None:
        d = Path(args.dataset)
        if not d.is_dir():
            raise UserError(f"option --dataset: folder {args.dataset} not found")
        if not (d / "manifest.json").is_file():  # checked before --out is created
            held = [n for n in ("loop.json", "front.csv", "chosen.json", "starts.csv") if (d / n).is_file()]
            what = f"it holds results ({', '.join(held)}) and" if held else "it"
            raise UserError(f"option --dataset: {args.dataset} is not a flight-test folder: {what} has no "
                            f"manifest.json (a flight test as written by generate-data)")
        overrides = {"data": {"dataset": str(Path(args.dataset).resolve())}}
    _check_out_dir(args.out)
    _check_out_not_foreign(args.out, "close-loop")
    cfg = load_identification_config(args.config, overrides)
    settings = loop_settings(cfg)
    if args.max_iterations is not None:
        if args.max_iterations < 0:
            raise UserError("option --max-iterations must be >= 0")
        settings.max_iterations = args.max_iterations
    from ..workflows.close_loop import IdentificationFailed

    try:
        doc = close_loop(cfg, args.out, settings, restart=args.restart)
    except IdentificationFailed as exc:  # a failed solve, not bad input: exit 1 as identify
        print(f"pyomo-heli close-loop: {exc}", file=sys.stderr)
        return 1
    path = write_loop_report(args.out, cfg, figure_format=args.figure_format)
    print(f"{len(doc['iterations'])} identification(s); stopped: {doc['stopped']}")
    print(f"loop.json and {path} written")
    return 0


def cmd_report_loop(args) -> int:
    """Rewrite ``loop_report.md`` and the figures of a finished close-loop folder from its loop.json (no solve)."""
    import json

    from ..report.loop import LOOP_FILE, write_loop_report

    folder = Path(args.loop_dir)
    f = folder / LOOP_FILE
    if not f.is_file():
        raise UserError(f"{args.loop_dir}: no {LOOP_FILE}; not a results folder of pyomo-heli close-loop")
    try:
        doc = json.loads(f.read_text())
        config, its = args.config or doc["config"], doc["iterations"]
        doc["dataset"], its[0]["results_dir"]
    except (ValueError, KeyError, IndexError, TypeError) as exc:
        raise UserError(f"{f}: not a loop record of close-loop ({exc})") from None
    if not Path(config).is_file():
        raise UserError(f"config {config} (named in {f}) not found; give it with --config")
    from ..workflows.check_effect import loop_iteration

    # the report replays the first and the kept model, so the config is checked against both iterations' results
    # (ResultsMismatchError, one line); a folder made on another machine names a flight test not here: the
    # config's own, when its content is the loop's. Iteration 0 (M0) gives the config on that flight test
    cfg = loop_iteration(folder, 0, config)[2]
    loop_iteration(folder, None, config)
    path = write_loop_report(folder, cfg, figure_format=args.figure_format)
    print(f"{path} written")
    return 0


def cmd_trim_loop(args) -> int:
    """Trim-only closed loop (pyomo_heli.workflows.trim_loop): report, figures and trim_loop.json in --out."""
    from ..workflows.trim_loop import TrimIdentificationFailed, load_trim_loop_config, run_trim_loop, write_trim_report

    _check_out_dir(args.out)
    cfg = load_trim_loop_config(args.config)
    try:
        doc = run_trim_loop(cfg, args.out)
    except TrimIdentificationFailed as exc:  # a failed solve, not bad input: exit 1 as identify
        print(f"pyomo-heli trim-loop: {exc}", file=sys.stderr)
        return 1
    path = write_trim_report(cfg, doc, args.out)
    print(f"{len(doc['iterations'])} identification(s); stopped: {doc['stopped']}")
    print(f"{path}, trim_curves.png, trim_residuals.png and trim_loop.json written")
    return 0


def _data_rate_hz(cfg) -> tuple[float, str]:
    """Sample rate [Hz] of the residuals a diagnosis of ``cfg`` tests: [data] resample_hz, else the slowest maneuver."""
    if cfg.resample_hz:
        return float(cfg.resample_hz), f"[data] resample_hz of config {cfg.path}"
    from ..dataset import load_flight_test

    ft = load_flight_test(cfg.dataset)
    sel = cfg.maneuvers
    names = set(sel) if not isinstance(sel, str) else {n for n, mv in ft.maneuvers.items() if mv.role == sel}
    if not isinstance(cfg.validation, str) and cfg.validation:
        names |= set(cfg.validation)
    rates = [ft.maneuvers[n].sample_rate for n in names if n in ft.maneuvers]
    rates = [r for r in rates if math.isfinite(r)]
    return (min(rates) if rates else math.inf), f"dataset {cfg.dataset} of config {cfg.path}"


@_results_folder(lambda a: a.out or a.results_dir)
def cmd_diagnose(args) -> int:

    from ..config import load_result_config
    from ..dataset import load_flight_test
    from ..diagnosis.analysis import diagnose
    from ..diagnosis.residuals import compute_residuals
    from ..diagnosis.trim_forces import implied_forces
    from ..pareto.result import IdentificationResult
    from ..report.diagnosis import write_diagnosis_report

    if not 0 < args.alpha < 1:
        raise UserError(f"--alpha must lie in (0, 1), got {args.alpha}")
    if args.out is not None:
        _check_out_dir(args.out)
        _check_diagnosis_out(args.out, args.results_dir)
    res = IdentificationResult.load(args.results_dir)
    # the config (given, or named in chosen.json) plus a close-loop iteration's effects, checked against the folder
    notes = []  # records the folder lacks: said once the command has checked everything else
    cfg = load_result_config(args.results_dir, args.config, res, warn=notes.append)
    parameters = _point_parameters(res, args.point, args.results_dir)
    rate, source = _data_rate_hz(cfg)
    if args.test_rate_hz > rate * (1 + 1e-9):
        raise UserError(f"option --test-rate-hz: {args.test_rate_hz:g} Hz is above the sample rate of the data "
                        f"({rate:g} Hz, {source}); the whiteness test cannot sample faster than the data")
    for note in notes:
        _warning("diagnose")(note)
    label = "multi-objective (C)" if args.point == "chosen" else "time-domain (A)"
    out = Path(args.out or args.results_dir)
    print(f"diagnosing {label} of {args.results_dir} (config {cfg.path})")
    print(_solver_status_line(res, args.point))
    r = compute_residuals(cfg, parameters, label, test_rate_hz=args.test_rate_hz)
    if not args.no_residuals:
        r.save(out / f"residuals_{args.point}")
    d = diagnose(r, alpha=args.alpha, test_rate_hz=args.test_rate_hz, seed=args.seed)
    d.save(out / "diagnosis.json")
    ft = load_flight_test(cfg.dataset)
    model = cfg.model.with_parameters(**parameters) if parameters else cfg.model
    forces = implied_forces(model, ft.trims, ft.conventions, label=label,
                            free=[n for n in parameters if n in model.parameters])
    forces.save(out)
    cmd = "pyomo-heli diagnose " + " ".join(sys.argv[1:][1:]) if sys.argv[1:2] == ["diagnose"] else None
    write_diagnosis_report(out, r, d, results_dir=args.results_dir, command=cmd, figure_format=args.figure_format,
                           forces=forces)
    print(d)
    print(forces.summary().to_string(index=False, float_format=lambda x: f"{x:.4g}"))
    print(f"wrote {out / 'diagnosis.json'}, {out / 'diagnosis.md'}, {out / 'implied_forces.csv'} and figures")
    return 0


def load_effect(spec: str):
    """``--effect``: a library name (``lon_rigging``, ``dM_col``) or ``FILE.py:CLASS`` / ``MODULE:CLASS``, an
    extension class of one's own, built with no arguments; its strength needs bounds (the NLP frees it within
    them). UserError naming the option otherwise."""
    import importlib
    import importlib.util

    from ..diagnosis.candidates import as_candidate, make_candidate
    from ..physics.extensions import Extension

    if ":" not in spec:
        try:
            return make_candidate(spec)
        except KeyError as exc:
            raise UserError(f"option --effect: {exc.args[0]}; or FILE.py:CLASS for an effect of your own") from None
    where, _, name = spec.rpartition(":")
    if where.endswith(".py"):
        if not Path(where).is_file():
            raise UserError(f"option --effect: file {where} not found")
        mod_spec = importlib.util.spec_from_file_location(Path(where).stem, where)
        module = importlib.util.module_from_spec(mod_spec)
        mod_spec.loader.exec_module(module)
    else:
        try:
            module = importlib.import_module(where)
        except ImportError as exc:
            raise UserError(f"option --effect: cannot import module {where!r} ({exc})") from None
    cls = getattr(module, name, None)
    if not (isinstance(cls, type) and issubclass(cls, Extension)):
        raise UserError(f"option --effect: {where} has no extension class {name!r} (a subclass of "
                        f"pyomo_heli.physics.extensions.Extension)")
    try:
        return as_candidate(cls())
    except ValueError as exc:
        raise UserError(f"option --effect: {exc}") from None


def cmd_check_effect(args) -> int:
    import json

    from ..workflows.check_effect import check_effect

    effect = load_effect(args.effect)
    against = None if args.against == "none" else args.against
    if args.json is not None:
        _check_out_file(args.json, "--json")
    r = check_effect(args.loop_dir, effect, iteration=args.iteration, config=args.config, against=against)
    t = r["term"]
    print(f"{effect.name} at iteration {r['iteration']} of {args.loop_dir}: {t['strength']} = {t['estimate']:.4g} "
          f"+- {t['se']:.2g}; LR {t['LR']:.3g} (time {t['LR_time']:.3g}, trim {t['LR_trim']:.3g}), corrected "
          f"{t['LR_robust']:.3g} on df {t['df']:.3g}; solve {t['status']}")
    print(f"p = {t['p']:.2g} ({r['criterion']}) {'<' if r['significant'] else '>='} level {r['level']:.2g}: "
          + ("significant" if r["significant"] else "not significant")
          + (f"; significant from |{t['strength']}| >= {t['detectable']:.2g}"
             if math.isfinite(t.get("detectable", math.nan)) else ""))
    e = r.get("encompassing")
    if e and "LR_G_given_P" in e:
        g = r["against"]["name"]
        verdict = ("encompasses it: explains the data as well as the generic term" if e["encompasses"]
                   else "equivalent to it on these data" if e["equivalent"]
                   else f"does not explain what {g} explains")
        print(f"against {g}: with {effect.name} fitted {g} adds LR {e['LR_G_given_P']:.3g} (p = "
              f"{e['p_G_given_P']:.2g}); {effect.name} adds LR {e['LR_P_given_G']:.3g} (p = {e['p_P_given_G']:.2g}) "
              f"to {g}: {verdict}")
    elif e:
        print(f"against {r['against']['name']}: {e.get('note', 'the joint solve failed')}; no encompassing test")
    if args.json is not None:
        Path(args.json).write_text(json.dumps(r, indent=1, default=float))
        print(f"wrote {args.json}")
    return 0
