"""Solver set-up with the old and the new dense-column rule of the block-wise Hessian (docs/performance.md).

    python studies/profile_setup.py [--max-duration 1.0]

Builds the --quick benchmark instance once per rule and prints the set-up
breakdown of the casadi adapter; the Hessian split sizes show which columns
were treated as dense.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from pyomo_heli.config import load_identification_config  # noqa: E402
from pyomo_heli.identify import build_problem  # noqa: E402
from pyomo_heli.solvers.casadi_ipopt import CasadiIpoptSolver, resolve_options  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--max-duration", type=float, default=1.0)
    args = ap.parse_args(argv)
    cfg = load_identification_config(ROOT / "tests" / "configs" / "small_case1_noisy.toml",
                                      {"data": {"maneuvers": ["lon3211_80kt_a", "coldoublet_hover"],
                                                "max_duration_s": args.max_duration}})
    for pct in (99, 90):
        CasadiIpoptSolver.hessian_dense_percentile = pct
        m, _, _ = build_problem(cfg)
        from pyomo_heli.pareto.front import ParetoSolver

        ps = ParetoSolver(m, cfg.pareto)
        opts, verbose, _ = resolve_options(ps.solver.options, None, "none")
        ps.solver._solver_for(opts, verbose)  # builds the Hessian
        b = ps.solver.setup_breakdown
        print(f"percentile {pct}: {len(ps.solver.variables)} variables, Hessian split {ps.solver._hessian_split}, "
              + ", ".join(f"{k} {v:.2f} s" for k, v in b.items()), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
