"""Which warm start makes a front cheap? Iterations per front point for several Ipopt start options.

    python studies/warm_start_study.py tests/configs/small_case1_noisy.toml --max-duration 2
    python studies/warm_start_study.py studies/case1.toml --anchor-b           # full size, ~10 min

On one NLP (built once), point A is solved cold; then the interior points of an 11-point front are
solved along the epsilon grid from A, once per start option (each chain from A's solution, its
multipliers rescaled to the front's objective scale as in ParetoSolver.front). With ``--anchor-b``
the two stages of anchor B (min J_trim from A, then min J_time at J_trim's minimum from the first
stage's solution) are solved with several barrier starts. Prints iterations per point and the
largest difference of the front's objective from the first option's (the same front).
Numbers quoted in docs/performance.md come from this script.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pyomo_heli.config import load_identification_config  # noqa: E402
from pyomo_heli.identify import build_problem  # noqa: E402
from pyomo_heli.pareto.front import FRONT_STEP_OPTIONS, ParetoSolver, _Snapshot, epsilon_grid  # noqa: E402
from pyomo_heli.solvers import scale_multipliers  # noqa: E402

PUSH_1E3 = {"warm_start_bound_push": 1e-3, "warm_start_mult_bound_push": 1e-3}
PUSH_1E8 = FRONT_STEP_OPTIONS
CHAINS = [  # (label, warm-start mode, extra Ipopt options, options of the first step off A, predictor)
    ("primal (Ipopt mu_init 0.1)", "primal", None, None, "none"),
    ("full (mu_init 1e-4)", "full", None, None, "none"),
    ("full, mu_init 1e-6", "full", {"mu_init": 1e-6}, None, "none"),
    ("full, mu_init 1e-8", "full", {"mu_init": 1e-8}, None, "none"),
    ("continuation (mu_init tol/10)", "continuation", None, None, "none"),
    ("continuation, pushes 1e-3", "continuation", PUSH_1E3, PUSH_1E3, "none"),
    ("continuation, 1e-3 on step 1", "continuation", None, PUSH_1E3, "none"),
    ("same + secant predictor", "continuation", None, PUSH_1E3, "secant"),
    ("same, mu_init 1e-10", "continuation", {"mu_init": 1e-10}, PUSH_1E3, "secant"),
    ("same, pushes 1e-8", "continuation", PUSH_1E8, PUSH_1E3, "secant"),
]
TIGHT = {"bound_push": 1e-8, "bound_frac": 1e-8, "slack_bound_push": 1e-8, "slack_bound_frac": 1e-8}
B_FIRST = [("Ipopt default", None), ("mu_init 1e-4", {"mu_init": 1e-4}), ("mu_init 1e-6", {"mu_init": 1e-6}),
           ("1e-6, pushes 1e-8", {"mu_init": 1e-6, **TIGHT})]
B_SECOND = [("Ipopt default", None), ("mu_init 1e-9", {"mu_init": 1e-9}), ("mu_init 1e-6", {"mu_init": 1e-6}),
            ("1e-6, pushes 1e-8", {"mu_init": 1e-6, **TIGHT})]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("config", type=Path)
    ap.add_argument("--max-duration", type=float, help="crop every maneuver to this many seconds")
    ap.add_argument("--points", type=int, default=11)
    ap.add_argument("--anchor-b", action="store_true", help="also compare the start options of anchor B")
    ap.add_argument("--b-options", type=lambda t: [int(x) for x in t.split(",")],
                    help="indices into B_FIRST/B_SECOND to run (default: all)")
    ap.add_argument("--chains", type=lambda t: [int(x) for x in t.split(",")],
                    help="indices into CHAINS to run (default: all), e.g. 0,6,7")
    args = ap.parse_args(argv)
    over = {"data": {"max_duration_s": args.max_duration}} if args.max_duration else {}
    cfg = load_identification_config(args.config, over)
    m, _, _ = build_problem(cfg)
    ps = ParetoSolver(m, cfg.pareto)
    a = ps.point_a()
    print(f"A: {a.iterations} iterations, {a.wall_time:.2f} s, J_trim {a.J_trim:.6g}", flush=True)
    snap_a = _Snapshot(m)
    scale = max(abs(a.J_time), 1.0)
    b1 = ps._solve("trim", -1, "B1", math.inf, "primal")
    eps = epsilon_grid(a.J_trim, b1.J_trim, args.points)
    ref = None
    chains = [c for i, c in enumerate(CHAINS) if args.chains is None or i in args.chains]
    for label, mode, opts, first, predictor in chains:
        snap_a.restore()
        scale_multipliers(m, ps.s_time / scale)
        its, times, J = [], [], []
        last, previous = _Snapshot(m), None
        for k in range(1, args.points - 1):
            if previous is not None and predictor == "secant":  # as ParetoSolver.front
                last.extrapolated(previous, (eps[k] - eps[k - 1]) / (eps[k - 1] - eps[k - 2])).restore()
            p = ps._solve("time", k, "eps", float(eps[k]), mode, first if k == 1 else opts, scale=scale)
            its.append(p.iterations if p.success else f"{p.iterations}({p.status})")
            times.append(p.wall_time)
            J.append(p.J_time)
            previous, last = (last if k > 1 else None), _Snapshot(m)
        ref = np.array(J) if ref is None else ref
        total = sum(i if isinstance(i, int) else 0 for i in its)
        print(f"{label:32s} iterations {its} total {total}, {sum(times):.1f} s; "
              f"max |J_time - first| {np.max(np.abs(np.array(J) - ref)):.2e}", flush=True)
    if args.anchor_b:
        for label, opts in [c for i, c in enumerate(B_FIRST) if args.b_options is None or i in args.b_options]:
            snap_a.restore()
            p = ps._solve("trim", -1, "B1", math.inf, "primal", opts)
            print(f"B first stage, {label:14s}: {p.iterations} iterations, {p.wall_time:.2f} s, J_trim {p.J_trim:.10f}",
                  flush=True)
        snap_a.restore()
        b1 = ps._solve("trim", -1, "B1", math.inf, "primal")
        snap_b1 = _Snapshot(m)
        eps_b = b1.J_trim * (1 + ps.settings.lexicographic_tol) + 1e-12
        for label, opts in [c for i, c in enumerate(B_SECOND) if args.b_options is None or i in args.b_options]:
            snap_b1.restore()
            p = ps._solve("time", args.points - 1, "B", eps_b, "primal", opts, scale=scale)
            print(f"B second stage, {label:14s}: {p.iterations} iterations, {p.wall_time:.2f} s, J_time {p.J_time:.6f}",
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
