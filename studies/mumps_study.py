"""MUMPS scaling study: point A cold at several sizes with several Ipopt/MUMPS option sets (docs/performance.md).

    python studies/mumps_study.py --size 1,2,4,8 --sets base,amd,amf,metis,auto,pivtol1e-8,pivtol1e-4,scaling0 \
        [--repeat 3] [--out results/mumps_study]
    python studies/mumps_study.py --analyse results/mumps_study/results.jsonl     # tables and log-log slopes

The scaling instance of studies/benchmark.py (Case 1 config, maneuvers cropped to 1.5 s, repeated k times).

Each size is built once; for every option set the model's initial values (ParetoSolver.restore_initial_guess)
are restored and point A is solved cold (warm_start "none", as ParetoSolver.point_a). Ipopt's and
MUMPS' own output of every solve is captured (fd 1 redirected) into logs/<size>x_<set>.log and parsed.
"""
from __future__ import annotations

import argparse
import dataclasses
import resource
import json
import math
import os
import re
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from pyomo_heli.benchmark import growth_exponent, repeat_maneuvers  # noqa: E402
from pyomo_heli.config import load_identification_config  # noqa: E402
from pyomo_heli.dataset import load_flight_test  # noqa: E402
from pyomo_heli.nlp.identification import build_identification_nlp, identification_data  # noqa: E402
from pyomo_heli.pareto.front import ParetoSolver  # noqa: E402

DIAG = {"print_level": 5, "print_timing_statistics": "yes", "mumps_print_level": 2}
SETS = {
    "base": {},  # QAMD (6), the adapter default
    "amd": {"mumps_pivot_order": 0},
    "amf": {"mumps_pivot_order": 2},
    "scotch": {"mumps_pivot_order": 3},  # not built into casadi's MUMPS: falls back to METIS
    "pord": {"mumps_pivot_order": 4},  # not built in either: METIS
    "metis": {"mumps_pivot_order": 5},
    "auto": {"mumps_pivot_order": 7},
    "pivtol1e-8": {"mumps_pivtol": 1e-8},
    "pivtol1e-4": {"mumps_pivtol": 1e-4},
    "mem1000": {"mumps_mem_percent": 1000},
    "scaling0": {"mumps_scaling": 0},
    "scal0_piv1e-4": {"mumps_scaling": 0, "mumps_pivtol": 1e-4},
    "mem100": {"mumps_mem_percent": 100},
    "mem20": {"mumps_mem_percent": 20},
    "base_quiet": {"mumps_print_level": 0},
    # no Ipopt/MUMPS output at all (as the benchmark); *_nommap: glibc malloc without mmap for the solve
    "quiet": {"print_level": 0, "mumps_print_level": 0, "print_timing_statistics": "no"},  # timing without MUMPS' printing
    "base_again": {"print_level": 4},  # a different key -> new nlpsol; repeatability of the base run
}


def parse_log(text: str) -> dict:
    r = {}
    m = re.search(r"Number of Iterations\.*:\s*(\d+)", text)
    r["iterations"] = int(m.group(1)) if m else None
    for key in ("LinearSystemFactorization", "LinearSystemSymbolicFactorization", "LinearSystemBackSolve",
                "OverallAlgorithm", "PDSystemSolverTotal", "LinearSystemScaling",
                "LinearSystemStructureConverter", "Function Evaluations"):
        m = re.search(re.escape(key) + r"\.*:\s*([\d.eE+-]+) \(sys:\s*([\d.eE+-]+) wall:\s*([\d.eE+-]+)\)", text)
        if m:
            r[key] = {"cpu": float(m.group(1)), "wall": float(m.group(3))}
    # MUMPS statistics (ICNTL(4)=2): one block per analysis (JOB 1) / factorisation (JOB 2) / solve (JOB 3)
    jobs = re.findall(r"with JOB, N, NNZ =\s*(-?\d+)\s+(\d+)\s+(\d+)", text)
    r["n_analysis"] = sum(1 for j in jobs if j[0] == "1")
    r["n_factorizations_mumps"] = sum(1 for j in jobs if j[0] == "2")
    r["n_solves_mumps"] = sum(1 for j in jobs if j[0] == "3")
    r["kkt_n_nnz"] = sorted({(int(j[1]), int(j[2])) for j in jobs if j[0] in "123"})
    f = lambda pat, conv=float: [conv(x.replace("D", "E")) for x in re.findall(pat, text)]
    r["t_analysis"] = sum(f(r"Elapsed time in analysis driver\s*=\s*([\d.]+)"))
    r["t_fact_list"] = f(r"Elapsed time in factorization driver\s*=\s*([\d.]+)")
    r["t_fact"] = sum(r["t_fact_list"])
    r["t_solve_driver"] = sum(f(r"Elapsed time in solve driver\s*=\s*([\d.]+)"))
    r["flops_est_analysis"] = f(r"RINFOG\(1\) Operations during elimination \(estim\)=\s*([\d.DE+-]+)")
    r["flops_fact"] = f(r"\(3\) Operations in node elimination\s*=\s*([\d.DE+-]+)")
    r["factor_entries"] = f(r"INFOG \(29\) Number of entries in factors\s*=\s*([\d.DE+-]+)")
    r["delayed_pivots"] = f(r"INFOG \(13\) Number of delayed pivots\s*=\s*(\d+)", int)
    r["max_front"] = f(r"INFOG \(11\) Maximum front size\s*=\s*(\d+)", int)
    r["max_front_est"] = f(r"Maximum frontal size \(estimated\)\s*=\s*(\d+)", int)
    r["factor_space_est"] = f(r"INFOG\(3\) Real space for factors \(estimated\)=\s*(\d+)", int)
    r["mem_used_mb"] = f(r"Memory effectively used, total in Mbytes\s*\(INFOG\(22\)\):\s*(\d+)", int)
    order = re.findall(r"Ordering based on\s*(\S+)", text)
    r["ordering"] = sorted(set(order))
    # regularisation column of the iteration table
    rg = re.findall(r"^\s*\d+r?\s+[-\d.e+]+\s+[\d.e+-]+\s+[\d.e+-]+\s+[-\d.e+]+\s+[\d.e+-]+\s+([-\d.]+)\s", text, re.M)
    r["lg_rg"] = rg
    r["iters_with_regularisation"] = sum(1 for x in rg if x != "-")
    r["restoration_iters"] = len(re.findall(r"^\s*\d+r\s", text, re.M))
    m = re.search(r"EXIT: (.*)", text)
    r["exit"] = m.group(1).strip() if m else None
    return r


import ctypes  # noqa: E402

_libc = ctypes.CDLL("libc.so.6")
M_TRIM_THRESHOLD, M_MMAP_MAX = -1, -4


def set_nommap(on: bool):
    """glibc malloc: no mmap for big blocks and no trimming (MUMPS' workspace reuses heap pages), or back."""
    if on:
        _libc.mallopt(M_MMAP_MAX, 0)
        _libc.mallopt(M_TRIM_THRESHOLD, ctypes.c_int(2**31 - 1))
    else:
        _libc.mallopt(M_MMAP_MAX, 65536)
        _libc.mallopt(M_TRIM_THRESHOLD, 128 * 1024)
        _libc.malloc_trim(0)


def solve_captured(ps, opts: dict, log: Path):
    ps.restore_initial_guess()
    sys.stdout.flush()
    fd = os.open(str(log), os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    saved = os.dup(1)
    os.dup2(fd, 1)
    try:
        ru0 = resource.getrusage(resource.RUSAGE_SELF)
        t0 = time.perf_counter()
        p = ps._solve("time", 0, "A", math.inf, "none", options=opts)
        clock = time.perf_counter() - t0
        ru1 = resource.getrusage(resource.RUSAGE_SELF)
        p.rusage = {"minflt": ru1.ru_minflt - ru0.ru_minflt, "majflt": ru1.ru_majflt - ru0.ru_majflt,
                    "utime": ru1.ru_utime - ru0.ru_utime, "stime": ru1.ru_stime - ru0.ru_stime,
                    "maxrss_mb": ru1.ru_maxrss / 1024}
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)
        os.close(fd)
    return p, clock


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", default="1,8")
    ap.add_argument("--sets", default="base,amd,amf,pord,auto")
    ap.add_argument("--max-duration", type=float, default=1.5)
    ap.add_argument("--repeat", type=int, default=1, help="rounds over the sets (interleaved)")
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "mumps_study",
                    help="folder for results.jsonl, results.txt and the solver logs")
    ap.add_argument("--analyse", type=Path, metavar="JSONL", help="only print the tables of a results.jsonl")
    args = ap.parse_args()
    if args.analyse:
        analyse(args.analyse)
        return
    unknown = [n for n in args.sets.split(",") if n.removesuffix("_nommap") not in SETS]
    if unknown:
        ap.error(f"--sets: unknown option set(s) {unknown}; choose from {', '.join(SETS)}")
    LOGS = args.out / "logs"
    LOGS.mkdir(parents=True, exist_ok=True)
    args.json = args.out / "results.jsonl"
    overrides = {"data": {"max_duration_s": args.max_duration}}
    cfg = load_identification_config(ROOT / "studies" / "case1.toml", overrides)
    ft = load_flight_test(cfg.dataset)
    base = identification_data(cfg, ft)
    for k in [int(s) for s in args.size.split(",")]:
        data = repeat_maneuvers(base, k)
        samples = sum(len(mv.data) for mv in data.maneuvers)
        t0 = time.perf_counter()
        m = build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp)
        ps = ParetoSolver(m, dataclasses.replace(cfg.pareto, cold_check=False))
        print(f"[{time.strftime('%H:%M:%S')}] size {k}: {samples} samples, {len(ps.solver.variables)} vars, "
              f"build+NL {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
        for name in [n for rep in range(args.repeat) for n in args.sets.split(",")]:
            nommap = name.endswith("_nommap")
            opts = {**DIAG, **SETS[name.removesuffix("_nommap")]}
            set_nommap(nommap)
            log = LOGS / f"{k}x_{name}.log"
            setup0 = ps.solver._pending_setup
            p, clock = solve_captured(ps, opts, log)
            set_nommap(False)
            r = parse_log(log.read_text(errors="replace"))
            stats = ps.solver.last_stats
            fun = sum(float(stats.get(f"t_wall_{f}", 0.0)) for f in
                      ("nlp_f", "nlp_g", "nlp_grad_f", "nlp_jac_g", "nlp_hess_l"))
            row = {"size": k, "samples": samples, "set": name, "options": SETS[name.removesuffix("_nommap")], "nommap": nommap, "status": p.status,
                   "iterations": p.iterations, "wall": p.wall_time, "setup": p.setup_time, "fun": fun,
                   "J_time": p.J_time, **p.rusage, **r}
            with open(args.json, "a") as f:
                f.write(json.dumps(row) + "\n")
            nf = r["n_factorizations_mumps"]
            tf = r["t_fact"]
            fl, ent, dl = r["flops_fact"], r["factor_entries"], r["delayed_pivots"]
            avg = lambda v: (sum(v) / len(v)) if v else float("nan")
            line = (f"{k}x {name:11s} it={p.iterations:3d} nfac={nf:3d} nsolve={r['n_solves_mumps']:4d} "
                    f"reg_it={r['iters_with_regularisation']:2d} resto={r['restoration_iters']} "
                    f"solve={p.wall_time:7.2f}s fun={fun:6.2f} t_fact={tf:6.2f} t/fac={tf / max(nf, 1):.4f} "
                    f"t_ana={r['t_analysis']:5.2f} t_solvedrv={r['t_solve_driver']:5.2f} "
                    f"flops/fac={avg(fl):.3g} entries={avg(ent):.3g} delayed={avg(dl):.0f} "
                    f"maxfront={max(r['max_front'] or [0])} J={p.J_time:.8g} {p.status} order={r['ordering']} "
                    f"nlpsol_setup={p.setup_time - setup0:.1f} minflt={p.rusage['minflt']} stime={p.rusage['stime']:.2f} utime={p.rusage['utime']:.2f}")
            print(line, file=sys.stderr, flush=True)
            with open(args.out / "results.txt", "a") as f:
                f.write(line + "\n")
        del ps, m


def analyse(path):
    """Tables per option set and size (medians of repeats) and 1x->8x log-log slopes against samples."""
    import collections

    rows = [json.loads(l) for l in open(path)]
    its = {r["size"]: r["iterations"] for r in rows if r["iterations"]}
    for r in rows:  # quiet runs: no log to parse; same path as the logged runs (deterministic)
        if r["iterations"] is None:
            r["iterations"] = its.get(r["size"])
    by = collections.defaultdict(list)
    for r in rows:
        by[(r["set"], r["size"])].append(r)
    sets = list(dict.fromkeys(r["set"] for r in rows))
    def slope(xs, ys):
        e = growth_exponent(xs, ys)  # the benchmark's fit; None when it cannot be fitted
        return float("nan") if e is None else e
    def med(v): return float(np.median(v))
    print("| set | size | runs | iterations | factorisations | MUMPS solves | solve [s] | functions [s] | factorisation [s] | per factorisation [s] | MUMPS solve phase [s] | analysis [s] | rest [s] | flops/fact | factor entries | delayed pivots |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for s in sets:
        for k in sorted({r["size"] for r in rows}):
            g = by.get((s, k))
            if not g: continue
            it = [r["iterations"] for r in g]; nf = [r["n_factorizations_mumps"] for r in g]
            w = [r["wall"] for r in g]; fn = [r["fun"] for r in g]; tf = [r["t_fact"] for r in g]
            sd = [r["t_solve_driver"] for r in g]; an = [r["t_analysis"] for r in g]
            rest = [r["wall"] - r["fun"] - r["t_fact"] - r["t_solve_driver"] - r["t_analysis"] for r in g]
            fl = g[0]["flops_fact"]; en = g[0]["factor_entries"]; dl = g[0]["delayed_pivots"]
            its = "/".join(str(x) for x in sorted(set(it))); nfs = "/".join(str(x) for x in sorted(set(nf)))
            print(f"| {s} | {k}x | {len(g)} | {its} | {nfs} | {med([r['n_solves_mumps'] for r in g]):.0f} | {med(w):.2f} | {med(fn):.2f} | {med(tf):.2f} | "
                  f"{med([a / max(b, 1) for a, b in zip(tf, nf)]):.4f} | {med(sd):.2f} | {med(an):.3f} | {med(rest):.2f} | "
                  f"{np.mean(fl) if fl else float('nan'):.3g} | {np.mean(en) if en else float('nan'):.3g} | {np.mean(dl) if dl else float('nan'):.0f} |")
    print()
    print("log-log slopes against samples over the sizes present (medians of repeats)")
    print("| set | sizes | solve | solve/iteration | factorisation total | per factorisation | factorisations | MUMPS solve phase | analysis | functions | flops/fact | factor entries |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for s in sets:
        ks = sorted(k for (ss, k) in by if ss == s)
        if len(ks) < 2: continue
        sm = [by[(s, k)][0]["samples"] for k in ks]
        M = lambda f: [med([f(r) for r in by[(s, k)]]) for k in ks]
        vals = [slope(sm, M(lambda r: r["wall"])), slope(sm, M(lambda r: r["wall"] / r["iterations"])),
                slope(sm, M(lambda r: r["t_fact"])), slope(sm, M(lambda r: r["t_fact"] / max(r["n_factorizations_mumps"], 1))),
                slope(sm, M(lambda r: r["n_factorizations_mumps"])), slope(sm, M(lambda r: r["t_solve_driver"])),
                slope(sm, M(lambda r: r["t_analysis"])), slope(sm, M(lambda r: r["fun"])),
                slope(sm, M(lambda r: np.mean(r["flops_fact"]))), slope(sm, M(lambda r: np.mean(r["factor_entries"])))]
        print(f"| {s} | {','.join(map(str, ks))} | " + " | ".join(f"{v:.3f}" for v in vals) + " |")


if __name__ == "__main__":
    main()
