"""The cost of the third objective: the bi-objective and the tri-objective identification in one process.

``python studies/benchmark.py --tri-vs-bi`` runs ``studies/case1.toml`` (J_time, J_trim: anchors, front,
Eq. 11 choice and direct solve) and then ``studies/case1_tri.toml`` (J_time, J_trim, J_linear: anchors A,
B, C, the row minima, the epsilon grid, the choices and the direct solve), each from its own build, in
one process on one core, and reports for each the CPU time of the process (user + system, with any child
process: what the run costs, little moved by other load on a shared machine) and the wall time, and their ratios.
Neither run computes standard errors or writes the report (those are the same work for both and not
part of the identification); each run's folder holds its front as ``pyomo-heli identify`` writes it.

Issue 31's target: the tri-objective run costs less than 3 times the bi-objective one.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

from ..config import load_identification_config
from ..log import info
from .identify import run_identification

#: the issue's limit on (tri-objective cost) / (bi-objective cost)
TRI_OVER_BI_LIMIT = 3.0


def _cpu() -> float:
    """CPU seconds of this process and its finished children (user + system)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _timed(cfg, out: Path, progress) -> dict:
    c0, w0 = _cpu(), time.perf_counter()
    res = run_identification(cfg, out, progress=progress, restart=True, uncertainty=False)
    cpu, wall = _cpu() - c0, time.perf_counter() - w0
    front = res.front
    grid = front[front["kind"] == "eps"]
    return {"config": str(cfg.path), "out": str(out), "cpu_s": cpu, "wall_s": wall,
            "solves": int(len(front)), "grid_points": int(len(grid)),
            "iterations": int(front["iterations"].clip(lower=0).sum()),
            "max_iterations_grid": int(grid["iterations"].max()) if len(grid) else 0,
            "failed": int((~front["success"].astype(bool)).sum()),
            "chosen": res.chosen.get("parameters") if isinstance(res.chosen, dict) else None}


def run_tri_vs_bi(bi_config, tri_config, out, overrides: dict | None = None, progress=info,
                  tri_out=None) -> dict:
    """Run ``bi_config`` then ``tri_config`` into ``out/bi`` and ``tri_out`` (default ``out/tri``); return (and
    write ``out/tri_vs_bi.json``) their CPU and wall times and the ratios tri / bi."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    folders = {"bi": out / "bi", "tri": Path(tri_out) if tri_out is not None else out / "tri"}
    cfgs = {name: load_identification_config(path, overrides) for name, path in (("bi", bi_config),
                                                                                 ("tri", tri_config))}
    result = {}
    for name, cfg in cfgs.items():
        progress(f"[{name}] {cfg.path} -> {folders[name]}")
        result[name] = _timed(cfg, folders[name], progress)
        progress(f"[{name}] CPU {result[name]['cpu_s']:.1f} s, wall {result[name]['wall_s']:.1f} s")
    result["cpu_ratio"] = result["tri"]["cpu_s"] / result["bi"]["cpu_s"]
    result["wall_ratio"] = result["tri"]["wall_s"] / result["bi"]["wall_s"]
    result["limit"] = TRI_OVER_BI_LIMIT
    result["met"] = bool(result["cpu_ratio"] < TRI_OVER_BI_LIMIT)
    result["overrides"] = overrides or {}
    (out / "tri_vs_bi.json").write_text(json.dumps(result, indent=2, default=str))
    return result


def format_tri_vs_bi(r: dict) -> str:
    """A markdown table of the two runs and the ratios."""
    lines = ["| run | config | CPU [s] | wall [s] | solves | grid points | iterations | max it. (grid) | failed |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name in ("bi", "tri"):
        x = r[name]
        lines.append(f"| {name} | {Path(x['config']).name} | {x['cpu_s']:.1f} | {x['wall_s']:.1f} | {x['solves']} | "
                     f"{x['grid_points']} | {x['iterations']} | {x['max_iterations_grid']} | {x['failed']} |")
    lines.append("")
    lines.append(f"tri / bi: CPU {r['cpu_ratio']:.2f}, wall {r['wall_ratio']:.2f} "
                 f"(target: CPU < {r['limit']:g}: {'met' if r['met'] else 'NOT met'})")
    return "\n".join(lines)
