"""Identification commands: ``identify``, ``demo``, ``multistart``, ``uncertainty``, ``inspect`` and
``report-linear``."""
from __future__ import annotations

import sys

from .folders import (_check_copy_out, _check_out_dir, _check_out_not_foreign, _results_folder,
                      _solver_status_line, _warning)
from .options import UserError

def cmd_identify(args) -> int:
    from ..config import load_identification_config
    from ..workflows.identify import run_identification

    pareto = {"cold_check": True} if getattr(args, "cold_check", False) else {}
    if getattr(args, "placement", None):  # [pareto] placement ("adaptive": pareto/placement.py)
        pareto["placement"] = args.placement
    overrides = {"pareto": pareto} if pareto else None
    _check_out_dir(args.out)
    _check_out_not_foreign(args.out, "identification")
    cfg = load_identification_config(args.config, overrides)
    from ..log import info

    points = (cfg.pareto.points if cfg.pareto.placement == "uniform"
              else f"adaptive placement, at most {cfg.pareto.max_solves}")
    info(f"identifying {', '.join(f.name for f in cfg.free)} from {cfg.dataset} "
         f"({points} front points, solver {cfg.pareto.solver})")
    result = run_identification(cfg, args.out, uncertainty=getattr(args, "uncertainty", "all"),
                                restart=getattr(args, "restart", False))
    if result.chosen is None:
        print(result)
        print(f"no front point converged; every status is in {args.out}/front.csv", file=sys.stderr)
        return 1
    if not args.no_report and "linear" in cfg.objectives:
        from ..report.linear import write_linear_report

        print(f"report: {write_linear_report(args.out, cfg, figure_format=args.figure_format)}")
    elif not args.no_report:
        from ..report.identification import write_report

        write_report(args.out, cfg, figure_format=args.figure_format)
    print(result)
    print(f"results in {args.out}")
    unreliable = result.info.get("unreliable")
    if unreliable:  # the files are written, marked (chosen.json info.unreliable, report.md); the status says so
        print(f"pyomo-heli identify: {unreliable['reason']}: the utopia point, nadir, epsilon grid and Eq. 11 "
              f"choice are unreliable (marked in {args.out}/chosen.json and the report)", file=sys.stderr)
        return 1
    return 0


@_results_folder(lambda a: a.out or a.results)
def cmd_uncertainty(args) -> int:
    import shutil
    from pathlib import Path

    from ..config import load_identification_config
    from ..nlp.identification import identification_data
    from ..pareto.result import IdentificationResult
    from ..pareto.store import LOCK_FILE, FolderLock
    from ..uncertainty.front import add_uncertainty

    if args.out:
        _check_out_dir(args.out)
        _check_copy_out(args.out, args.results)
    cfg = load_identification_config(args.config)
    result = IdentificationResult.load(args.results)
    if result.info.get("extensions"):  # an iteration of close-loop: the config plus the effects the loop added
        from ..config import config_of_result

        cfg = config_of_result(cfg, result)
    from ..provenance import check_results_match

    notes = []  # records the folder lacks: said once the command has checked everything else
    check_results_match(cfg, result, args.results, warn=notes.append)
    if result.chosen is None:
        raise UserError(f"{Path(args.results) / 'chosen.json'}: no chosen point (no front point converged); "
                        f"no standard errors to compute")
    if "linear" in (result.info.get("objectives") or cfg.objectives):
        # the information holds J_time and J_trim only: a point stationary for J_linear too gets wrong weights
        raise UserError(f"{args.results}: a three-objective front; its standard errors leave J_linear's information "
                        "out (report-linear gives them at the two-objective choice's weights, docs/linear.md)")
    data = identification_data(cfg)
    for note in notes:
        _warning("uncertainty")(note)
    for which in ("time_domain", "chosen"):
        print(_solver_status_line(result, which))
    with FolderLock(args.out or args.results, "uncertainty"):  # no identify may write there meanwhile
        if args.out and Path(args.out).resolve() != Path(args.results).resolve():
            shutil.copytree(args.results, args.out, dirs_exist_ok=True,
                            ignore=shutil.ignore_patterns(LOCK_FILE))
        add_uncertainty(result, cfg, data, args.out or args.results, points=args.points)
    print(f"standard errors in {args.out or args.results} (front.csv, chosen.json, identifiability.csv)")
    return 0


def cmd_multistart(args) -> int:
    from ..config import load_identification_config
    from ..parallel import check_dask_flags
    from ..workflows.multistart import run_multistart

    check_dask_flags(args.workers, args.scheduler)  # before any file is read or written

    _check_out_dir(args.out)
    _check_out_not_foreign(args.out, "multi-start")
    cfg = load_identification_config(args.config)
    problem = "time" if args.epsilon is None else "epsilon"
    from ..log import info
    from ..parallel import dask_executor

    info(f"multi-start of {', '.join(f.name for f in cfg.free)} from {args.starts} random initial guesses "
         f"(seed {args.seed}) on {cfg.dataset}")
    with dask_executor(args.workers, args.scheduler) as executor:
        result = run_multistart(cfg, args.out, starts=args.starts, seed=args.seed, problem=problem,
                                epsilon=args.epsilon, rtol=args.rtol, restart=args.restart, executor=executor)
    print(result)
    print(f"results in {args.out}")
    if result.best is None and args.epsilon is not None:
        print(f"no start converged: the bound J_trim <= {args.epsilon:g} (--epsilon) may be infeasible; "
              f"try an epsilon between the front's J_trim values (front.csv of identify)", file=sys.stderr)
    return 0 if result.best is not None else 1


def cmd_demo(args) -> int:
    from ..resources import demo_config

    config = demo_config()  # package data: works from an installed wheel in any directory
    args.config, args.no_report = str(config), False
    _check_out_dir(args.out)
    args.uncertainty = "chosen"  # standard errors of A, C and the direct solve: keeps the demo's duration
    return cmd_identify(args)


def cmd_inspect(args) -> int:
    from ..config import load_identification_config
    from ..nlp.inspect import inspect_problem

    cfg = load_identification_config(args.config)
    responses = None
    if "linear" in cfg.objectives:  # the three-objective NLP, its [linear] checked as identify checks it
        from ..dataset import load_flight_test
        from ..workflows.identify_linear import coherent_bands, data_responses

        responses = coherent_bands(cfg, data_responses(cfg, load_flight_test(cfg.dataset)), progress=lambda s: None)
    print(inspect_problem(cfg, diagnostics=not args.no_diagnostics, responses=responses))
    return 0


def cmd_report_linear(args) -> int:
    from ..config import load_identification_config
    from ..report.linear import write_linear_report

    cfg = load_identification_config(args.config)
    notes = []  # records the folder lacks (checked against the config before anything is written)
    print(f"report: {write_linear_report(args.out, cfg, warn=notes.append, figure_format=args.figure_format)}")
    for note in notes:
        _warning("report-linear")(note)
    return 0

