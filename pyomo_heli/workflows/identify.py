"""Run an identification from a config: data -> NLP -> Pareto front -> results on disk.

This is the orchestration the command line and the studies call; it sits
above the dataset, NLP and Pareto rooms and below the command line.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, replace
from pathlib import Path

import pandas as pd

from ..config import IdentificationConfig
from ..log import format_parameters, info
from ..nlp.identification import build_problem
from ..physics.extensions import extension_forms  # noqa: F401 - re-exported
from ..pareto.front import ParetoSolver, utopia_distance
from ..pareto.placement import AdaptiveFront
from ..pareto.result import IdentificationResult
from ..pareto.steps import starts_note
from ..pareto.store import fingerprint
from ..provenance import provenance_info
from .run_folder import RunFolder
from ..report.identification import mean_cold_iterations, mean_interior_iterations


#: what the anchors define: unreliable when one of them did not converge (chosen.json info.unreliable)
UNRELIABLE_WITHOUT_ANCHORS = ("utopia", "nadir", "epsilon grid", "utopia_distance", "chosen", "direct")


def shape_values(model) -> dict:
    """name -> value of the shape parameters of a model's extensions (e.g. the wake's profile order n_wt).

    Shape parameters are fixed model parameters chosen by the closed loop's shape rule, so they must be part of
    what tells one identification apart from another (fingerprint, reuse of a finished iteration).
    """
    return {n: float(model.parameters[n]) for e in model.extensions for n in getattr(e, "shape_parameters", ())}


def _point_dict(p) -> dict:
    d = asdict(p)
    d["epsilon"] = None if not math.isfinite(d["epsilon"]) else d["epsilon"]
    return d


def built_message(data, what: str, seconds: float) -> str:
    """The line that reports the NLP built: maneuvers, trim points, ``what`` (trim blocks, frequency points)."""
    return (f"built NLP: {len(data.maneuvers)} maneuvers, {len(data.trims)} trim points, {what} in "
            f"{seconds:.1f} s")


def identification_fingerprint(cfg: IdentificationConfig) -> str:
    """What must not change between a killed run and its resumption: the config (after overrides) and data.

    With extensions (e.g. a candidate the closed loop added, which is not in the config's text), also their
    forms and the free parameters, so that points of an older form of an effect are not resumed.
    """
    extra = ({"extensions": extension_forms(cfg.model.extensions), "free": [f.name for f in cfg.free]}
             if cfg.model.extensions else {})
    if shape_values(cfg.model):
        extra["shape"] = shape_values(cfg.model)
    # [diagnosis] only sets the residual analysis's input-noise model: changing it must not discard fronts
    raw = {k: v for k, v in cfg.raw.items() if k != "diagnosis"}
    # [data] resample_inputs by the value it resolves to, not by its spelling: the default changed from
    # "sample" to "project" (2026-11-25), so a config without the key must not resume a store of picked
    # inputs, and one that now says "sample" must still resume the stores made before the key existed
    if "data" in raw:
        raw["data"] = {k: v for k, v in raw["data"].items() if k != "resample_inputs"}
    if cfg.resample_inputs != "sample" and cfg.resample_hz:
        extra["resample_inputs"] = cfg.resample_inputs
    return fingerprint(raw, cfg.dataset, command="identify", **extra)


def run_identification(cfg: IdentificationConfig, out: str | Path, progress=info,
                       restart: bool = False, uncertainty: bool | str = False) -> IdentificationResult:
    """Solve anchors, front and choice; write each front point to ``out/front.csv`` as it finishes.

    Each finished point goes to ``out/front.csv`` (a readable table) and to
    ``out/points/`` (its exact record and full solution). Running again on the
    same ``out`` resumes: finished points are loaded, the rest is solved from
    the last finished point's stored solution, and the results equal those of
    an uninterrupted run. A folder holding points of another config is
    refused (StoreMismatchError) unless ``restart`` discards them.

    uncertainty: True or "all": then add Cramer-Rao standard errors of every
    front point and the identifiability at the chosen point
    (pyomo_heli.uncertainty.front); "chosen": only for A, the chosen point and
    the direct solve; False or "none": skip. The command line's default is "all".

    The folder is locked for the run (a second run on it is refused, FolderBusyError naming the holder).
    SIGINT or SIGTERM stops the run with :class:`~pyomo_heli.interrupts.Interrupted`: the point being solved
    is not stored, finished points stay on disk, and a rerun resumes to the uninterrupted run's results.

    A folder holding another command's results (close-loop's ``loop.json`` and ``iter_*/``, multistart's
    ``starts.csv``) is refused (StoreMismatchError, one line naming the folder), ``restart`` or not. A stored
    point that cannot be read is solved again with a warning (:mod:`pyomo_heli.pareto.store`).
    """
    with RunFolder(out, "identification", cfg, restart) as run, run.locked():
        if "linear" in getattr(cfg, "objectives", ()):
            from .identify_linear import run_tri_identification

            return run_tri_identification(cfg, run, progress)  # uncertainty, resume: two-objective runs only
        return _run_identification(cfg, run, progress, uncertainty)


def _run_identification(cfg, run: RunFolder, progress, uncertainty) -> IdentificationResult:
    out = run.root
    store = run.store(identification_fingerprint(cfg), progress)
    t0 = time.perf_counter()
    m, data, ft = build_problem(cfg)
    t_build = time.perf_counter() - t0
    progress(built_message(data, f"{len(data.speeds)} trim blocks", t_build))
    table = run.front("front.csv")  # rewritten as each point finishes
    bar = run.progress_bar(cfg.pareto.max_solves if cfg.pareto.placement == "adaptive" else cfg.pareto.points,
                           "front points")

    def on_point(p):
        table.add(p.row())
        params = format_parameters(p.parameters, cfg.model.parameters)
        from_disk = getattr(p, "from_disk", False)
        where = " (from disk)" if from_disk else ""
        progress(f"  point {p.index:>2} {p.kind:<3} J_time={p.J_time:.6g} J_trim={p.J_trim:.6g} {params} "
                 f"[{p.status}, {p.iterations} it, {p.wall_time:.1f} s]{where}" + bar.tick(from_disk))

    t1 = time.perf_counter()
    adaptive = cfg.pareto.placement == "adaptive"
    # adaptive: B is point 1 and the epsilon points are numbered in the order they are solved
    ps = ParetoSolver(m, replace(cfg.pareto, points=2) if adaptive else cfg.pareto, on_point=on_point, store=store)
    setup = time.perf_counter() - t1
    placement = None
    if adaptive:
        from ..uncertainty.front import point_standard_errors

        placement = AdaptiveFront(ps, cfg.pareto.max_solves, lambda p: point_standard_errors(
            cfg, data, p.parameters, p.kind, p.multiplier_trim),
                                  spacing=cfg.pareto.spacing, on_point=on_point, progress=progress)
        points = placement.run()
    else:
        points = ps.front()
    chosen, dist = ps.choose()
    utopia, nadir = ps.utopia_nadir()
    if chosen is not None:
        direct = ps.direct_choice(chosen)
        if placement is not None:
            placement.compare_direct(chosen, direct)
        progress(f"  chosen: front point {chosen.index} (Eq. 11); direct Eq. 11 solve: {direct.status}"
                 + starts_note(direct))
    else:
        direct = None
        progress("  no front point converged: nothing to choose (statuses in front.csv)")
    front = pd.DataFrame(table.rows).sort_values("index").reset_index(drop=True)
    ok = front["success"].astype(bool)
    front["utopia_distance"] = float("nan")
    if ok.any():
        front.loc[ok, "utopia_distance"] = utopia_distance(front.loc[ok, "J_time"], front.loc[ok, "J_trim"],
                                                           utopia, nadir)
    params = [f.name for f in cfg.free]
    failed = front.loc[~ok, ["index", "kind", "status"]].to_dict("records")
    anchor_failures = ps.anchor_failures()
    for line in anchor_failures:
        progress(f"  warning: {line}: utopia, nadir, epsilon grid and the Eq. 11 choice are unreliable")
    result = IdentificationResult(
        front=front, parameters=params, units={n: cfg.model.parameters.spec(n).unit for n in params},
        utopia=utopia, nadir=nadir, chosen=_point_dict(chosen) if chosen is not None else None,
        direct=_point_dict(direct) if direct is not None else None,
        time_domain=_point_dict(points[0]),
        info={"config": str(cfg.path), "dataset": str(cfg.dataset), "build_time": t_build,
              "solver_setup_time": setup, "total_time": time.perf_counter() - t0,
              "maneuvers": [mv.name for mv in data.maneuvers], "extensions": [e.name for e in cfg.model.extensions],
              "extension_forms": extension_forms(cfg.model.extensions),
              "shape_parameters": shape_values(cfg.model),
              "input_reference_s": cfg.input_reference_s,
              "solver": cfg.pareto.solver,
              "failed_points": failed,
              # the Eq. 11 choice under both nadir rules (pareto.epsilon.NADIR_RULES; [pareto] nadir picks `chosen`)
              "eq11_by_nadir": ps.choices() if chosen is not None else None,
              # an anchor that did not converge (after its retries) spoils everything derived from the anchors
              "unreliable": ({"reason": "; ".join(anchor_failures),
                              "quantities": list(UNRELIABLE_WITHOUT_ANCHORS)
                              + (["time-domain estimate (A) and its replays"]
                                 if any(f.startswith("anchor A ") for f in anchor_failures) else [])}
                             if anchor_failures else None),
              "resumed_points": sum(bool(getattr(p, "from_disk", False)) for p in points),
              # resumed points solved by other code (the package changed since they were stored): said, not hidden
              **({"resumed_from_other_code": True}
                 if store.other_code and any(getattr(p, "from_disk", False) for p in points) else {}),
              "mean_iterations_front": mean_interior_iterations(front),
              "mean_iterations_front_cold": mean_cold_iterations(front),
              **({"placement": placement.summary.to_dict()} if placement is not None else {}),
              **provenance_info(cfg)})  # the config by content, the data's hash, the model: checked by readers
    result.save(out)
    if uncertainty and uncertainty != "none" and result.chosen is not None:
        from ..uncertainty.front import add_uncertainty

        t2 = time.perf_counter()
        add_uncertainty(result, cfg, data, out, progress, points="chosen" if uncertainty == "chosen" else "all")
        result.info["uncertainty_time"] = time.perf_counter() - t2
        result.save(out)
    return result
