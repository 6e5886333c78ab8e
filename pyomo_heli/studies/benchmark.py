"""Rerunnable performance benchmark (see docs/performance.md and pyomo_heli/workflows/benchmark.py).

    python studies/benchmark.py                               # Case 1 config, front + single shooting, size 1x
    python studies/benchmark.py --shooting solve_ivp          # classic shooting over scipy solve_ivp (slow)
    python studies/benchmark.py --size 1,2,4,8 --no-front --no-shooting --repeat 3   # scaling, bundled size (12 min)
    python studies/benchmark.py --size 1,2,4,8 --no-front --no-shooting --max-duration 1.5 --repeat 3   # cropped, 1 min
    python studies/benchmark.py --size 1,2,4,8 --repeat 3 --shooting rk4 --shooting-max-sims 0 --compare-nl-route
                                                              # every target in one run (~30 min, 7 GB)
    python studies/benchmark.py --replay                      # compiled against Python replay (1 min of CPU)
    python studies/benchmark.py --quick                       # seconds; what the test suite runs
    python studies/benchmark.py --no-shooting --compare-nl-route   # + set-up and point A with every row in the NL file
    python studies/benchmark.py --no-front --no-shooting --compare-scaling   # A + 5-point front unscaled vs scaled
    python studies/benchmark.py --tri-vs-bi --out results/tri_vs_bi   # Case 1 bi- then tri-objective, one process

Prints markdown tables and writes JSON (default results/benchmark.json) after
every finished part. Bad options exit with status 2 and a one-line message.
"""
from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the checkout: studies/, tests/configs/

from pyomo_heli.workflows.benchmark import BenchmarkSettings, format_tables, run_benchmark  # noqa: E402
from pyomo_heli.config import ConfigError  # noqa: E402

#: --quick: a tiny instance (two maneuvers cut to 1 s, 3 front points, sizes 1x and 2x) and no single
#: shooting unless --shooting is given: on this flat problem the RK4 fit took 131 s (914 simulations)
#: and the solve_ivp fit 615 s, see docs/performance.md
QUICK = {"config": ROOT / "tests" / "configs" / "small_case1_noisy.toml", "sizes": [1, 2], "shooting": "none",
         "overrides": {"data": {"maneuvers": ["lon3211_80kt_a", "coldoublet_hover"], "max_duration_s": 1.0},
                       "pareto": {"points": 3}}}


def parse_sizes(text: str) -> list[int]:
    try:
        sizes = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size: expected integers like 1,2,4,8, got {text!r}") from None
    if not sizes or any(s < 1 for s in sizes):
        raise argparse.ArgumentTypeError(f"--size: expected positive integers like 1,2,4,8, got {text!r}")
    return sizes


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", type=Path, default=ROOT / "studies" / "case1.toml", help="identification config")
    ap.add_argument("--size", type=parse_sizes, default=[1],
                    help="comma-separated repeat factors of the maneuver set, e.g. 1,2,4,8 (front and single "
                         "shooting run at the first)")
    ap.add_argument("--points", type=int, help="front points (default: the config's)")
    ap.add_argument("--max-duration", type=float, help="crop every maneuver to this many seconds")
    ap.add_argument("--warm-start", choices=["continuation", "full", "primal", "none"],
                    help="warm start of the front points (default: the config's; full = primal + duals, "
                         "continuation = full with the barrier from tol/10)")
    ap.add_argument("--no-front", action="store_true", help="point A only (no front, no cold front)")
    ap.add_argument("--shooting", choices=["solve_ivp", "rk4", "rk4-casadi", "none"], default=None,
                    help="integrator of the single-shooting fit (rk4: fixed-step in Python, rk4-casadi: the same "
                         "evaluated by casadi, solve_ivp: scipy adaptive; see docs/performance.md), or none")
    ap.add_argument("--no-shooting", action="store_true", help="same as --shooting none")
    ap.add_argument("--shooting-max-sims", type=int, default=150,
                    help="stop the single-shooting fit after about this many simulations (0: no cap)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="cold point-A solves per size without a front; the median is the size's solve time")
    ap.add_argument("--compare-nl-route", action="store_true",
                    help="also set up and solve point A (first size) with every row through the NL file")
    ap.add_argument("--nl-route", action="store_true",
                    help="every row through the NL file (no point rows), as before 2026-11-24 afternoon")
    ap.add_argument("--compare-scaling", action="store_true",
                    help="also solve anchor A and a short front (--scaling-points) unscaled and scaled by the IDAES "
                         "Scaler (solver option scaling), each from a fresh build; prints iterations and time ratios")
    ap.add_argument("--scaling-points", type=int, default=5, help="front points of --compare-scaling (default 5)")
    ap.add_argument("--quick", action="store_true", help="tiny instance in seconds (ignores --config/--size)")
    ap.add_argument("--tri-vs-bi", action="store_true",
                    help="run --config (default studies/case1.toml) and --tri-config (default studies/case1_tri.toml) "
                         "in this process and print both CPU and wall times and the ratio; --out is then a folder")
    ap.add_argument("--tri-config", type=Path, default=ROOT / "studies" / "case1_tri.toml",
                    help="the tri-objective config of --tri-vs-bi")
    ap.add_argument("--tri-out", type=Path, help="--tri-vs-bi: the tri-objective run's results folder (default: "
                                                 "OUT/tri; the bi-objective run goes to OUT/bi)")
    ap.add_argument("--replay", action="store_true",
                    help="time the replay of the bundled flight test's maneuvers (M0 at its truth parameters) by the "
                         "compiled RK4 and by the Python RK4 in this process; print both, the ratio and the largest "
                         "difference (no --out)")
    ap.add_argument("--out", type=Path, default=Path("results") / "benchmark.json", help="JSON output")
    args = ap.parse_args(argv)
    if args.tri_vs_bi:
        return _tri_vs_bi(ap, args)
    if args.replay:
        return _replay_speed()
    from .args import out_file
    out_file(ap, args.out)  # before the benchmark runs, not after
    overrides: dict = {}
    if args.points is not None:
        if args.points < 2:
            ap.exit(2, f"benchmark: --points must be at least 2, got {args.points}\n")
        overrides["pareto"] = {"points": args.points}
    if args.warm_start is not None:
        overrides["pareto"] = {**overrides.get("pareto", {}), "warm_start": args.warm_start}
    if args.max_duration is not None:
        if args.max_duration <= 0:
            ap.exit(2, f"benchmark: --max-duration must be positive, got {args.max_duration}\n")
        overrides["data"] = {"max_duration_s": args.max_duration}
    if args.scaling_points < 2:
        ap.exit(2, f"benchmark: --scaling-points must be at least 2, got {args.scaling_points}\n")
    if args.repeat < 1:
        ap.exit(2, f"benchmark: --repeat must be at least 1, got {args.repeat}\n")
    config, sizes = args.config, args.size
    if args.quick:
        config, sizes = QUICK["config"], QUICK["sizes"]
        overrides = {k: {**QUICK["overrides"].get(k, {}), **overrides.get(k, {})}
                     for k in set(QUICK["overrides"]) | set(overrides)}
    shooting = "none" if args.no_shooting else (args.shooting or (QUICK["shooting"] if args.quick else "rk4"))
    command = "python studies/benchmark.py " + " ".join(shlex.quote(a) for a in (argv if argv is not None
                                                                                 else sys.argv[1:]))
    settings = BenchmarkSettings(config=config, sizes=sizes, front=not args.no_front, shooting=shooting,
                                 shooting_max_simulations=args.shooting_max_sims or None,
                                 overrides=overrides, command=command.strip(), repeats=args.repeat,
                                 compare_nl_route=args.compare_nl_route, nl_route=args.nl_route,
                                 compare_scaling=args.compare_scaling, scaling_points=args.scaling_points)
    return _run_and_print(lambda progress: run_benchmark(settings, args.out, progress=progress), format_tables,
                          args.out)


def _replay_speed() -> int:
    """``--replay``: the replays the validation, the residual diagnosis and the record-bias test run, both ways."""
    import time

    import numpy as np

    from pyomo_heli.dataset import load_flight_test
    from pyomo_heli.physics.model import HelicopterModel
    from pyomo_heli.simulation.replay import replay
    from pyomo_heli.simulation.trim import trim_float

    ft = load_flight_test(ROOT / "data" / "bo105_synthetic")
    model = HelicopterModel()
    mans = list(ft.maneuvers.values())
    trims = {mv.name: trim_float(model, mv.trim_speed) for mv in mans}
    replay(model, mans[0], trims[mans[0].name])  # the compiled functions are built once per model structure
    runs, times = {}, {}
    for compiled in (True, False):
        t0 = time.process_time()
        runs[compiled] = {mv.name: replay(model, mv, trims[mv.name], compiled=compiled) for mv in mans}
        times[compiled] = time.process_time() - t0
    diff = max(float(np.max(np.abs(runs[True][n][o].to_numpy() - runs[False][n][o].to_numpy())))
               for n in runs[True] for o in ("q", "theta", "n_x", "n_z", "TAS", "beta_0"))
    samples = sum(len(mv.data) for mv in mans)
    print(f"replay of {len(mans)} maneuvers ({samples} samples), CPU time: compiled {times[True]:.2f} s, "
          f"Python {times[False]:.2f} s, ratio {times[False] / times[True]:.1f}x; largest output difference "
          f"{diff:.2e} (SI)")
    return 0


def _run_and_print(run, format_result, written) -> int:
    """Run ``run(progress)`` printing its progress, then its formatted result; a bad config is exit 2."""
    try:
        result = run(lambda msg: print(msg, flush=True))
    except ConfigError as exc:
        print(f"benchmark: {exc}", file=sys.stderr)
        return 2
    print()
    print(format_result(result))
    print(f"\nwritten: {written}")
    return 0


def _tri_vs_bi(ap, args) -> int:
    from pyomo_heli.workflows.tri_vs_bi import format_tri_vs_bi, run_tri_vs_bi

    if args.out.suffix == ".json":
        ap.exit(2, f"benchmark: --tri-vs-bi writes a folder; --out {args.out} names a .json file\n")
    overrides = {}
    if args.max_duration is not None:
        if args.max_duration <= 0:
            ap.exit(2, f"benchmark: --max-duration must be positive, got {args.max_duration}\n")
        overrides["data"] = {"max_duration_s": args.max_duration}
    return _run_and_print(lambda progress: run_tri_vs_bi(args.config, args.tri_config, args.out, overrides,
                                                         progress=progress, tri_out=args.tri_out),
                          format_tri_vs_bi, args.out / "tri_vs_bi.json")


if __name__ == "__main__":
    sys.exit(main())
