"""Tri-objective identification run: data -> frequency responses -> NLP with J_linear -> 2-D front.

Called by :func:`pyomo_heli.workflows.identify.run_identification` when a config's
``[objectives] use`` includes "linear". Files written into ``out`` (each front
point as soon as it is solved):

- ``frequency_responses.csv``: the data frequency responses on the full
  frequency grid, with coherence, input power and the coherent-band flag;
- ``front.csv``: anchors A, B, C and the grid points (J_time, J_trim, J_linear,
  both bounds, grid position, parameters, solver status);
- ``chosen.json``, ``time_domain.json`` as for the bi-objective run; ``chosen``
  is the tri-objective Eq. 11 choice and ``info.bi_objective`` the two-objective
  choice on the grid row whose J_linear bound is inactive.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict

import pandas as pd

from ..log import format_parameters, info
from ..dataset import load_flight_test
from ..dataset.frequency_response import (frequency_responses, save_responses, sweep_responses,
                                          tischler_remple_points)
from ..nlp.identification import build_identification_nlp, identification_data
from ..pareto.result import IdentificationResult
from ..pareto.epsilon import INFEASIBLE
from ..pareto.steps import starts_note
from ..pareto.tri_front import TriParetoSolver, utopia_distance_n
from ..provenance import provenance_info
from .identify import built_message
from ..units import KT
from .run_folder import RunFolder


def _point_dict(p) -> dict:
    d = asdict(p)
    for k in ("epsilon", "epsilon_linear"):
        d[k] = None if not math.isfinite(d[k]) else d[k]
    return d


def data_responses(cfg, ft):
    """Frequency responses of the config's identification maneuvers (full record rate); with
    ``[linear] weighting = "tischler_remple"`` the composite responses of the sweep records (role
    "frequency", estimator ``[linear] sweep_*``), each band cut to ``sweep_points`` (20) logarithmically spaced
    frequencies."""
    lin = cfg.linear
    if lin.weighting == "tischler_remple":
        sweeps = ft.frequency()
        if not sweeps:
            raise ValueError(f"{cfg.path} [linear]: weighting = 'tischler_remple' needs sweep records (role "
                             f"'frequency') in {cfg.dataset}; it has none")
        out = [tischler_remple_points(r, lin.sweep_points)
               for r in sweep_responses(sweeps, lin.pairs, lin.speeds, lin.composite)]
        offered = sweeps
    else:
        offered = ft.identification() if cfg.maneuvers == "identification" else [ft.maneuvers[n] for n in
                                                                                 cfg.maneuvers]
        out = frequency_responses(offered, lin.pairs, lin.speeds, lin.spectral)
    # every flight condition asked for must give every pair: one left out silently would leave J_linear a part
    if lin.speeds is not None:
        got = {(round(r.speed, 6), r.output, r.input) for r in out}
        missing = [(v, o, i) for v in lin.speeds for o, i in lin.pairs
                   if not any(abs(sp - v) < 1e-3 and (o, i) == (go, gi) for sp, go, gi in got)]
        if missing:
            have = sorted({round(float(mv.trim_speed) / KT, 3) for mv in offered})
            raise ValueError(f"{cfg.path} [linear] speeds_kt: no response for "
                             + ", ".join(f"{o}/{i} at {v / KT:g} kt" for v, o, i in missing)
                             + f" (no record at that speed moves that input alone; records at {have} kt)")
    return out


def _finite(v) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None


def coherent_bands(cfg, responses, saved=None, progress=info) -> list:
    """Each response's coherent band (what J_linear fits), each named with its bins; a response with none is an
    error naming the config's [linear] (left out, J_linear would hold the other responses alone). ``saved``: the
    file that holds every bin, named in the error."""
    band = [r.band() for r in responses]
    for r in band:
        progress(f"  frequency response {r.label}: {len(r.omega)} coherent bins"
                 + (f", {r.omega.min():.2f}..{r.omega.max():.2f} rad/s" if len(r.omega) else ""))
    empty = [r.label for r in band if not len(r.omega)]
    if empty:
        raise ValueError(f"{cfg.path} [linear]: no coherent bin in {', '.join(empty)} (coherence_min, "
                         f"input_power_min, omega_min..omega_max" + (f"; every bin is in {saved}" if saved else "")
                         + "): loosen them or leave the pair or speed out")
    return band


def run_tri_identification(cfg, run: RunFolder, progress=info) -> IdentificationResult:
    """The tri-objective run in the claimed and locked folder ``run`` (see the module docstring)."""
    out = run.root
    t0 = time.perf_counter()
    ft = load_flight_test(cfg.dataset)
    data = identification_data(cfg, ft)
    responses = data_responses(cfg, ft)
    if not responses:
        raise ValueError(f"{cfg.path} [linear]: no maneuver at speeds_kt moves exactly one input of the pairs")
    save_responses(responses, out / "frequency_responses.csv")
    band = coherent_bands(cfg, responses, out / "frequency_responses.csv", progress)
    m = build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp, responses=band)
    t_build = time.perf_counter() - t0
    progress(built_message(data, f"{sum(len(r.omega) for r in band)} frequency points", t_build))
    table = run.front("front.csv")  # rewritten as each point finishes

    def on_point(p):
        table.add(p.row())
        params = format_parameters(p.parameters, cfg.model.parameters)
        note = f"; {p.note}" if p.note else ""
        progress(f"  point {p.index:>2} {p.kind:<3} ({p.i_trim},{p.i_linear}) J_time={p.J_time:.6g} "
                 f"J_trim={p.J_trim:.6g} J_linear={p.J_linear:.6g} {params} "
                 f"[{p.status}{note}, {p.iterations} it, {p.wall_time:.1f} s{', from ' + p.start if p.start else ''}]"
                 + bar.tick())

    t1 = time.perf_counter()
    ps = TriParetoSolver(m, cfg.pareto, cfg.linear.points, on_point=on_point)
    setup = time.perf_counter() - t1
    # anchors A, B, C, the (J_trim points x J_linear points) grid less A itself, and the direct Eq. 11 solve
    placement = None
    if cfg.pareto.placement == "adaptive":  # anchors, a coarse 3 x 3 grid, refinement (pareto/placement_nd.py)
        from ..pareto.placement_nd import AdaptiveFrontN
        from ..uncertainty.front import point_standard_errors

        bar = run.progress_bar(cfg.pareto.max_solves + 1, "front points", at_most=True)
        # each point's standard errors at the weights its solve is stationary for (its J_trim multiplier); the
        # information holds J_time and J_trim only, J_linear's curvature is left out (docs/results.md)
        placement = AdaptiveFrontN(ps, cfg.pareto.max_solves, lambda p: point_standard_errors(
            cfg, data, p.parameters, "eps" if p.kind == "C" else p.kind, multiplier=_finite(p.multiplier_trim)),
            spacing=cfg.pareto.spacing, progress=progress)
        placement.run()
        ps.eps_trim, ps.eps_linear = ps.axes
    else:
        bar = run.progress_bar(ps.counts[0] * ps.counts[1] + 3, "front points")
        ps.front()
    chosen, _, utopia, nadir = ps.choose()
    bi, _, bi_utopia, bi_nadir = ps.choose(("time", "trim"), row_linear=0)
    direct = ps.direct_choice(chosen)
    on_point(direct)
    if placement is not None:
        placement.compare_direct(chosen, direct)
    progress(f"  chosen (3 objectives): point {chosen.index} {chosen.kind}; bi-objective choice: point {bi.index}; "
             f"direct Eq. 11 solve: {direct.status}" + starts_note(direct))
    front = pd.DataFrame(table.rows).sort_values("index").reset_index(drop=True)
    ok = front["success"].astype(bool) & front["kind"].isin(["A", "B", "C", "eps"])
    front["utopia_distance"] = float("nan")
    front.loc[ok, "utopia_distance"] = utopia_distance_n(front.loc[ok, ["J_time", "J_trim", "J_linear"]].to_numpy(),
                                                         utopia, nadir)
    table.write(front)
    params = [f.name for f in cfg.free]
    result = IdentificationResult(
        front=front, parameters=params, units={n: cfg.model.parameters.spec(n).unit for n in params},
        utopia=utopia, nadir=nadir, chosen=_point_dict(chosen), direct=_point_dict(direct),
        time_domain=_point_dict(ps.anchor_points["A"]),
        info={"config": str(cfg.path), "dataset": str(cfg.dataset), "objectives": list(cfg.objectives),
              "build_time": t_build, "solver_setup_time": setup, "total_time": time.perf_counter() - t0,
              "maneuvers": [mv.name for mv in data.maneuvers], "solver": cfg.pareto.solver,
              "grid": list(placement.coarse if placement is not None else ps.counts),
              "eps_trim": list(ps.eps_trim), "eps_linear": list(ps.eps_linear),
              "bi_objective": {"chosen": _point_dict(bi), "utopia": list(bi_utopia), "nadir": list(bi_nadir)},
              "failed_points": int((~front["success"].astype(bool)).sum()),
              "infeasible_points": int((front["status"] == INFEASIBLE).sum()),
              "row_minima": ps.row_solves,  # least J_linear under each row's J_trim bound (a priori infeasibility)
              "mean_iterations_grid": float(front.loc[front.kind == "eps", "iterations"].mean()),
              "max_iterations_grid": int(front.loc[front.kind == "eps", "iterations"].max()),
              # the Eq. 11 choice under both nadir rules ([pareto] nadir picks `chosen`)
              "eq11_by_nadir": ps.choices(),
              **({"placement": placement.summary.to_dict()} if placement is not None else {}), **provenance_info(cfg)})
    result.save(out)
    return result
