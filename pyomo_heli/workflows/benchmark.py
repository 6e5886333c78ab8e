"""Performance benchmark: one run, one machine, the same data for every route.

What is measured (all in one process, so the ratios compare like with like):

- model build (Pyomo), solver set-up (NL writing, casadi import, derivative
  functions, ``nlpsol``) and solve time, separately;
- one cold time-domain identification (point A) on the full discretisation;
- the same fit by classic single shooting (``scipy.optimize.least_squares``
  over ``solve_ivp``, nlp/single_shooting.py) from the same initial guess;
- a whole Pareto front (warm-started) and its interior points solved cold
  (``ParetoSettings.cold_check``);
- point A again with the maneuver set repeated k times (``sizes``), for the
  growth of the solve time with the number of samples;
- with ``compare_scaling``: anchor A and a short front solved twice, unscaled and scaled by the IDAES
  Scaler (nlp/scaling.py, the casadi adapter's ``scaling`` switch), each from a fresh build.

Results are a plain dict (JSON on disk, written after every finished size, so
an interrupted run keeps what it finished) and a markdown table. Timings are
wall-clock seconds; only ratios within one run are meaningful on a shared
machine. Run it with ``python studies/benchmark.py`` (see ``--help``).
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..log import info
from ..config import load_identification_config
from ..dataset import load_flight_test
from ..nlp.identification import IdentificationData, build_identification_nlp, identification_data
from ..nlp.single_shooting import fit_single_shooting
from ..pareto.front import ParetoSolver

#: the issue's targets: (ratio key, limit, "max" = value must be at most the limit, "min" = at least)
TARGETS = {
    "front_over_cold_a": (3.0, "max"),
    "shooting_over_full_discretization": (5.0, "min"),
    "shooting_parameter_difference": (1e-3, "max"),
    "setup_share_of_front": (0.30, "max"),
    "solve_time_exponent": (1.1, "max"),
}


@dataclass
class BenchmarkSettings:
    config: Path
    sizes: list = field(default_factory=lambda: [1])
    front: bool = True  # front (warm + cold interior) at the first size
    shooting: str = "rk4"  # "rk4", "rk4-casadi", "solve_ivp" or "none"
    shooting_max_simulations: int | None = 150  # cap of the single-shooting fit (None: until converged)
    #: cold point-A solves per size without a front (the median is the size's solve time): one solve on a shared
    #: machine varies by 10-30 % between runs, enough to move the growth exponent by 0.1 (docs/performance.md)
    repeats: int = 1
    #: also build, set up and solve point A at the first size with every row through the NL file
    #: (``CasadiSettings.point_rows = False``, the route before the point-described rows)
    compare_nl_route: bool = False
    #: the whole benchmark with every row through the NL file (``CasadiSettings.point_rows = False``)
    nl_route: bool = False
    #: also solve anchor A and a front of ``scaling_points`` points at the first size unscaled and scaled
    #: (``[solver] options = { scaling = true }``), each from a fresh build, and compare iterations, times and estimates
    compare_scaling: bool = False
    scaling_points: int = 5
    overrides: dict = field(default_factory=dict)  # config table overrides, as load_identification_config
    command: str = ""


def repeat_maneuvers(data: IdentificationData, k: int) -> IdentificationData:
    """The maneuver set repeated k times (copies renamed ``name~2`` ...); the trims unchanged.

    Repetition multiplies the samples while keeping the optimum (the same
    residuals k times), so the solve-time growth measures the NLP machinery,
    not a different estimation problem.
    """
    if k < 1:
        raise ValueError(f"size must be a positive integer, got {k}")
    mans = [mv if r == 0 else dataclasses.replace(mv, name=f"{mv.name}~{r + 1}")
            for r in range(k) for mv in data.maneuvers]
    return IdentificationData(maneuvers=mans, trims=data.trims)


def _point(p) -> dict:
    d = dataclasses.asdict(p)
    d["epsilon"] = d["epsilon"] if math.isfinite(d["epsilon"]) else None
    return d


def parameter_difference(a: dict, b: dict, scales: dict) -> float:
    """max over parameters of |a - b| / max(|b|, scale): relative, but not blown up by a value at 0."""
    return max(abs(a[n] - b[n]) / max(abs(b[n]), scales[n]) for n in b)


def growth_exponent(samples, times) -> float | None:
    """Slope of log(time) against log(samples) (least squares); None with fewer than 2 sizes."""
    s, t = np.asarray(samples, float), np.asarray(times, float)
    if len(s) < 2 or len(set(s)) < 2 or np.any(t <= 0):
        return None
    return float(np.polyfit(np.log(s), np.log(t), 1)[0])


#: casadi's per-function wall times of one Ipopt call (``solver.stats()``)
_FUNCTION_TIMES = ("nlp_f", "nlp_g", "nlp_grad_f", "nlp_jac_g", "nlp_hess_l")


def solve_breakdown(stats: dict | None, total: float) -> dict | None:
    """Where one solve's wall time ``total`` went: function evaluations (casadi's ``t_wall_nlp_*``) and
    the rest of Ipopt, which is mostly the linear algebra (MUMPS factorisation and solves)."""
    if not stats or "t_wall_nlp_f" not in stats:
        return None
    out = {f: float(stats.get(f"t_wall_{f}", 0.0)) for f in _FUNCTION_TIMES}
    out["total"] = float(total)
    out["ipopt_rest"] = out["total"] - sum(out[f] for f in _FUNCTION_TIMES)
    return out


def measure_size(cfg, base: IdentificationData, k: int, front: bool, progress=info, repeats: int = 1) -> dict:
    """Build, set up and solve point A (and, if ``front``, the whole front) with the maneuvers repeated k times.

    Without the front, point A is solved ``repeats`` times from the same initial point (each solve cold); the
    size's solve time is the median, and every solve's time is kept in ``a_solve_times``.
    """
    data = repeat_maneuvers(base, k)
    samples = sum(len(mv.data) for mv in data.maneuvers)
    t0 = time.perf_counter()
    m = build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp)
    build = time.perf_counter() - t0
    progress(f"size {k}: {samples} samples, NLP built in {build:.1f} s")
    settings = dataclasses.replace(cfg.pareto, cold_check=front)
    t1 = time.perf_counter()
    ps = ParetoSolver(m, settings)
    times, iters = [], []
    if front:
        points = ps.front()
    else:
        points = [ps.point_a()]
        times.append(points[0].wall_time)
        iters.append(points[0].iterations)
        for _ in range(repeats - 1):
            ps.restore_initial_guess()
            again = ps.point_a()
            if again.iterations != points[0].iterations or again.status != points[0].status:
                progress(f"size {k}: a repeated point A took {again.iterations} it ({again.status}), "
                         f"the first {points[0].iterations} it ({points[0].status})")
            times.append(again.wall_time)
            iters.append(again.iterations)
    clock = time.perf_counter() - t1
    a = points[0]
    a_time = float(np.median(times)) if times else a.wall_time
    setup = sum(p.setup_time for p in points)
    row = {
        "size": k, "samples": samples, "maneuvers": len(data.maneuvers),
        "variables": len(getattr(ps.solver, "variables", [])) or None,
        "constraints": len(getattr(ps.solver, "constraints", [])) or None,
        "build_time": build, "setup_time": setup,
        "setup_breakdown": dict(getattr(ps.solver, "setup_breakdown", {})),
        "point_a": _point(a),
        "a_solve_time": a_time, "a_solve_times": times or [a.wall_time],
        "a_solve_iterations": iters or [a.iterations], "a_iterations": a.iterations,
        "a_time_per_iteration": a_time / max(a.iterations, 1),
        "a_solve_breakdown": (solve_breakdown(getattr(ps.solver, "last_stats", None), a.wall_time)
                              if not front else None),
    }
    progress(f"size {k}: set-up {setup:.1f} s, point A {a.status} in {a.iterations} it, {a_time:.2f} s"
             + (f" (median of {len(times)}: {', '.join(f'{t:.2f}' for t in times)})" if len(times) > 1 else ""))
    if front:
        interior = [p for p in points if p.kind == "eps"]
        row["front"] = {
            "points": [_point(p) for p in points],
            "n_points": len(points),
            "all_success": all(p.success for p in points),
            "solve_time": sum(p.wall_time for p in points),
            "iterations": sum(p.iterations for p in points),
            "interior_warm_time": sum(p.wall_time for p in interior),
            "interior_warm_iterations": sum(p.iterations for p in interior),
            "interior_cold_time": sum(p.cold_wall_time or 0.0 for p in interior),
            "interior_cold_iterations": sum(p.cold_iterations or 0 for p in interior),
            "clock_time": clock,  # includes the cold check and the per-point Python work
        }
        f = row["front"]
        progress(f"size {k}: front of {len(points)} points {f['solve_time']:.1f} s solve, "
                 f"{f['interior_warm_iterations']} warm vs {f['interior_cold_iterations']} cold interior iterations")
    return row


def with_point_rows(pareto, point_rows: bool):
    """Front settings whose casadi-ipopt adapter takes the point-rows route ``point_rows`` (its
    ``CasadiSettings.point_rows``, passed as the solver option ``point_rows``) unless the config's
    ``[solver] point_rows`` already chose one."""
    if pareto.solver != "casadi-ipopt":
        return pareto
    return dataclasses.replace(pareto, solver_options={"point_rows": point_rows, **pareto.solver_options})


def measure_nl_route(cfg, base: IdentificationData, k: int, progress=info) -> dict:
    """Build, set-up and point A at size k with every row written to the NL file (no point rows)."""
    data = repeat_maneuvers(base, k)
    t0 = time.perf_counter()
    m = build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp)
    build = time.perf_counter() - t0
    ps = ParetoSolver(m, dataclasses.replace(with_point_rows(cfg.pareto, False), cold_check=False))
    a = ps.point_a()
    row = {"size": k, "build_time": build, "setup_time": a.setup_time,
           "setup_breakdown": dict(getattr(ps.solver, "setup_breakdown", {})), "point_a": _point(a),
           "a_solve_time": a.wall_time, "a_iterations": a.iterations,
           "a_solve_breakdown": solve_breakdown(getattr(ps.solver, "last_stats", None), a.wall_time)}
    progress(f"NL route, size {k}: build {build:.1f} s, set-up {a.setup_time:.1f} s, point A {a.status} in "
             f"{a.iterations} it, {a.wall_time:.2f} s")
    return row


def measure_scaling(cfg, base: IdentificationData, k: int, points: int, progress=info) -> dict:
    """Anchor A and a front of ``points`` points, unscaled then scaled (the adapter's ``scaling`` switch), each on
    a fresh build of size k; per point the iterations, solve time and estimates, and the scaled/unscaled ratios."""
    data = repeat_maneuvers(base, k)
    runs = {}
    for scaled in (False, True):
        m = build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp)
        pareto = dataclasses.replace(cfg.pareto, points=points, cold_check=False,
                                     solver_options={**cfg.pareto.solver_options, "scaling": scaled})
        t0 = time.perf_counter()
        ps = ParetoSolver(m, pareto)
        pts = ps.front()
        runs["scaled" if scaled else "unscaled"] = {
            "points": [_point(p) for p in pts], "setup_time": sum(p.setup_time for p in pts),
            "clock_time": time.perf_counter() - t0,  # scaler, set-up, solves
            "iterations": sum(p.iterations for p in pts), "solve_time": sum(p.wall_time for p in pts),
            "all_success": all(p.success for p in pts)}
        r = runs["scaled" if scaled else "unscaled"]
        progress(f"{'scaled' if scaled else 'unscaled'}: A {pts[0].iterations} it {pts[0].wall_time:.2f} s; front of "
                 f"{len(pts)} points {r['iterations']} it {r['solve_time']:.2f} s")
    u, s = runs["unscaled"], runs["scaled"]
    scales = {f.name: f.scale for f in cfg.free}
    return {**runs, "size": k, "n_points": points,
            "a_iterations_ratio": s["points"][0]["iterations"] / max(u["points"][0]["iterations"], 1),
            "a_time_ratio": s["points"][0]["wall_time"] / u["points"][0]["wall_time"],
            "front_iterations_ratio": s["iterations"] / max(u["iterations"], 1),
            "front_time_ratio": s["solve_time"] / u["solve_time"],
            # relative estimate difference, every point: the scaling must not move the front
            "max_parameter_difference": max(parameter_difference(ps_["parameters"], pu["parameters"], scales)
                                            for ps_, pu in zip(s["points"], u["points"])),
            "max_J_time_difference": max(abs(ps_["J_time"] - pu["J_time"]) / max(abs(pu["J_time"]), 1.0)
                                         for ps_, pu in zip(s["points"], u["points"]))}


def compute_ratios(result: dict) -> dict:
    """The issue's ratios from the raw numbers of one run (also used by the test to check the arithmetic)."""
    r = {}
    sizes = result["sizes"]
    first = sizes[0] if sizes else None
    if first is not None and "front" in first:
        f, a = first["front"], first["a_solve_time"]
        fixed = first["build_time"] + first["setup_time"]
        r["front_over_cold_a"] = f["solve_time"] / a
        r["front_end_to_end_over_a_end_to_end"] = (fixed + f["solve_time"]) / (fixed + a)
        r["warm_over_cold_iterations"] = (f["interior_warm_iterations"] / f["interior_cold_iterations"]
                                          if f["interior_cold_iterations"] else None)
        r["warm_over_cold_time"] = (f["interior_warm_time"] / f["interior_cold_time"]
                                    if f["interior_cold_time"] else None)
        r["setup_share_of_front"] = fixed / (fixed + f["solve_time"])
    nl = result.get("nl_route")
    if nl and first is not None:
        r["nl_route_setup_over_point_rows_setup"] = nl["setup_time"] / first["setup_time"]
        r["nl_route_a_solve_over_point_rows_a_solve"] = nl["a_solve_time"] / first["a_solve_time"]
    sc = result.get("scaling")
    if sc:
        for key in ("a_iterations_ratio", "a_time_ratio", "front_iterations_ratio", "front_time_ratio",
                    "max_parameter_difference", "max_J_time_difference"):
            r[f"scaled_{key}"] = sc[key]
    ss = result.get("single_shooting")
    if ss and first is not None:
        a_total = first["build_time"] + first["setup_time"] + first["a_solve_time"]
        r["shooting_over_full_discretization"] = ss["wall_time"] / a_total
        r["shooting_over_a_solve_only"] = ss["wall_time"] / first["a_solve_time"]
        r["shooting_parameter_difference"] = ss["parameter_difference"]
    if len(sizes) >= 2:
        samples = [s["samples"] for s in sizes]
        r["solve_time_exponent"] = growth_exponent(samples, [s["a_solve_time"] for s in sizes])
        r["time_per_iteration_exponent"] = growth_exponent(samples, [s["a_time_per_iteration"] for s in sizes])
        r["setup_time_exponent"] = growth_exponent(samples, [s["build_time"] + s["setup_time"] for s in sizes])
    return r


def check_targets(ratios: dict) -> dict:
    out = {}
    for key, (limit, kind) in TARGETS.items():
        v = ratios.get(key)
        met = None if v is None else bool(v <= limit if kind == "max" else v >= limit)
        out[key] = {"value": v, "limit": limit, "kind": kind, "met": met}
    return out


def _machine() -> dict:
    load = os.getloadavg() if hasattr(os, "getloadavg") else (None, None, None)
    return {"cpus": os.cpu_count(), "load_average_start": list(load), "python": platform.python_version(),
            "platform": platform.platform(), "date_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime())}


def run_benchmark(settings: BenchmarkSettings, out: str | Path | None = None, progress=info) -> dict:
    """Run every measurement; write ``out`` (JSON) after each finished part; return the result dict."""
    cfg = load_identification_config(settings.config, settings.overrides)
    ft = load_flight_test(cfg.dataset)
    base = identification_data(cfg, ft)  # as identify selects them (its input_reference_s and checks too)
    result = {"command": settings.command, "config": str(settings.config), "overrides": settings.overrides,
              "machine": _machine(), "solver": cfg.pareto.solver, "free_parameters": [f.name for f in cfg.free],
              "front_points": cfg.pareto.points, "sizes": [], "single_shooting": None}

    def save():
        result["ratios"] = compute_ratios(result)
        result["targets"] = check_targets(result["ratios"])
        result["machine"]["load_average_end"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
        if out is not None:
            Path(out).parent.mkdir(parents=True, exist_ok=True)
            Path(out).write_text(json.dumps(result, indent=1, default=float))

    result["route"] = "NL file only" if settings.nl_route else "point rows"
    routed = dataclasses.replace(cfg, pareto=with_point_rows(cfg.pareto, not settings.nl_route))
    for i, k in enumerate(settings.sizes):
        result["sizes"].append(measure_size(routed, base, int(k), settings.front and i == 0, progress,
                                            settings.repeats))
        save()
        if i == 0 and settings.shooting != "none":
            progress(f"single shooting ({settings.shooting}) on size {k} ...")
            data = repeat_maneuvers(base, int(k))
            ss = fit_single_shooting(cfg.model, data.maneuvers, cfg.free, list(cfg.nlp.time_outputs),
                                     integrator=settings.shooting,
                                     max_simulations=settings.shooting_max_simulations)
            a = result["sizes"][0]["point_a"]
            result["single_shooting"] = {
                **dataclasses.asdict(ss),
                "parameter_difference": parameter_difference(a["parameters"], ss.parameters,
                                                             {f.name: f.scale for f in cfg.free}),
                "J_time_difference": abs(a["J_time"] - ss.J_time) / max(abs(ss.J_time), 1.0),
            }
            progress(f"single shooting: {ss.wall_time:.1f} s, {ss.function_evaluations} simulations, "
                     f"{'converged' if ss.converged else 'stopped by the simulation cap'}, "
                     f"parameters {ss.parameters}")
            save()
        if i == 0 and settings.compare_nl_route:
            result["nl_route"] = measure_nl_route(cfg, base, int(k), progress)
            save()
        if i == 0 and settings.compare_scaling:
            progress(f"scaling: anchor A and a front of {settings.scaling_points} points, unscaled and scaled ...")
            result["scaling"] = measure_scaling(routed, base, int(k), settings.scaling_points, progress)
            save()
    save()
    return result


# ---------------------------------------------------------------- printing
def _fmt(v, digits=3):
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(v)
    return f"{v:.{digits}g}"


def _markdown(header: list, rows: list) -> list[str]:
    """The lines of a markdown table: the header, its rule, one line per row (an empty cell is one space)."""
    def line(cells):
        return "|" + "|".join(f" {c} " if c != "" else " " for c in cells) + "|"

    return [line(header), "|" + "---|" * len(header)] + [line(r) for r in rows]


def format_tables(result: dict) -> str:
    """Markdown tables: per size, the front, single shooting, ratios against the targets."""
    lines = ["| size | samples | variables | build [s] | set-up [s] | point A solve [s] | A iterations | s/iteration |",
             "|---|---|---|---|---|---|---|---|"]
    for s in result["sizes"]:
        lines.append(f"| {s['size']}x | {s['samples']} | {_fmt(s['variables'])} | {_fmt(s['build_time'])} | "
                     f"{_fmt(s['setup_time'])} | {_fmt(s['a_solve_time'])} | {s['a_iterations']} | "
                     f"{_fmt(s['a_time_per_iteration'])} |")
    reps = [s for s in result["sizes"] if len(s.get("a_solve_times", [])) > 1]
    if reps:
        lines += ["", "Point A solved cold " + str(len(reps[0]["a_solve_times"])) + " times per size (the table "
                  "gives the median) [s]: "
                  + "; ".join(f"{s['size']}x " + ", ".join(_fmt(t) for t in s["a_solve_times"]) for s in reps)]
    split = [s for s in result["sizes"] if s.get("a_solve_breakdown")]
    if split:
        lines += ["", "Point A's solve per iteration [s]: function evaluations (casadi) and the rest of Ipopt "
                  "(mostly MUMPS)", "",
                  "| size | objective + gradient | constraints + Jacobian | Hessian | rest of Ipopt |",
                  "|---|---|---|---|---|"]
        for s in split:
            b, n = s["a_solve_breakdown"], max(s["a_iterations"], 1)
            lines.append(f"| {s['size']}x | {_fmt((b['nlp_f'] + b['nlp_grad_f']) / n)} | "
                         f"{_fmt((b['nlp_g'] + b['nlp_jac_g']) / n)} | {_fmt(b['nlp_hess_l'] / n)} | "
                         f"{_fmt(b['ipopt_rest'] / n)} |")
    first = result["sizes"][0] if result["sizes"] else None
    if first and first.get("setup_breakdown"):
        b = first["setup_breakdown"]
        lines += ["", "Set-up at size " + f"{first['size']}x [s]: " + ", ".join(f"{k} {_fmt(v)}" for k, v in b.items())]
    if first and "front" in first:
        f = first["front"]
        lines += [""] + _markdown(
            ["point", "kind", "J_time", "J_trim", "warm it", "warm [s]", "cold it", "cold [s]", "status"],
            [[p["index"], p["kind"], f"{p['J_time']:.7g}", f"{p['J_trim']:.5g}", p["iterations"], _fmt(p["wall_time"]),
              _fmt(p["cold_iterations"]), _fmt(p["cold_wall_time"]), p["status"]] for p in f["points"]]
            + [["total", "", "", "", f["iterations"], _fmt(f["solve_time"]),
                f"{f['interior_cold_iterations']} (interior)", f"{_fmt(f['interior_cold_time'])} (interior)", ""]])
    nl = result.get("nl_route")
    if nl:
        lines += ["", "The same size with every row through the NL file (no point rows), same process:", "",
                  "| route | build [s] | set-up [s] | point A solve [s] | A iterations | J_time |",
                  "|---|---|---|---|---|---|"]
        for name, s in (("point rows (above)", first), ("NL file only", nl)):
            lines.append(f"| {name} | {_fmt(s['build_time'])} | {_fmt(s['setup_time'])} | {_fmt(s['a_solve_time'])} | "
                         f"{s['a_iterations']} | {s['point_a']['J_time']:.10g} |")
        lines.append("\nNL-route set-up [s]: " + ", ".join(f"{k} {_fmt(v)}" for k, v in nl["setup_breakdown"].items()))
    sc = result.get("scaling")
    if sc:
        u, s_ = sc["unscaled"], sc["scaled"]
        lines += ["", f"Unscaled and scaled (IDAES Scaler, solver option scaling), size {sc['size']}x, fresh builds, "
                  "same process:", ""] + _markdown(
            ["point", "kind", "unscaled it", "scaled it", "unscaled [s]", "scaled [s]", "J_time unscaled",
             "J_time scaled"],
            [[pu["index"], pu["kind"], pu["iterations"], ps_["iterations"], _fmt(pu["wall_time"]),
              _fmt(ps_["wall_time"]), f"{pu['J_time']:.10g}", f"{ps_['J_time']:.10g}"]
             for pu, ps_ in zip(u["points"], s_["points"])]
            + [["total", "", u["iterations"], s_["iterations"], _fmt(u["solve_time"]), _fmt(s_["solve_time"]), "", ""]])
    ss = result.get("single_shooting")
    if ss:
        a = first["point_a"]
        lines += ["", "| route | wall [s] | J_time | " + " | ".join(ss["parameters"]) + " |",
                  "|---|---|---|" + "---|" * len(ss["parameters"])]
        fd = first["build_time"] + first["setup_time"] + first["a_solve_time"]
        lines.append(f"| full discretisation, point A (build + set-up + solve) | {_fmt(fd)} | {a['J_time']:.9g} | "
                     + " | ".join(f"{a['parameters'][n]:.7g}" for n in ss["parameters"]) + " |")
        stop = "" if ss.get("converged", True) else ", stopped by the cap, not converged"
        lines.append(f"| single shooting ({ss['integrator']}, {ss['function_evaluations']} simulations{stop}) | "
                     f"{_fmt(ss['wall_time'])} | {ss['J_time']:.9g} | "
                     + " | ".join(f"{v:.7g}" for v in ss["parameters"].values()) + " |")
    lines += ["", "| ratio | value | target | met |", "|---|---|---|---|"]
    targets = result.get("targets", {})
    for k, v in result.get("ratios", {}).items():
        t = targets.get(k)
        tgt = "-" if t is None else (f"<= {t['limit']:g}" if t["kind"] == "max" else f">= {t['limit']:g}")
        lines.append(f"| {k} | {_fmt(v, 4)} | {tgt} | {_fmt(t['met']) if t else '-'} |")
    return "\n".join(lines)
