"""Solver set-up of the casadi adapter with two variants of one choice, in one run (docs/performance.md).

    python studies/profile_setup.py [--compare defined-variables|hessian-percentile]
                                    [--config studies/case1.toml] [--max-duration S] [--out FILE.json]

Builds the NLP of the config (maneuvers cropped to --max-duration seconds;
default: the --quick benchmark instance, two maneuvers of 1 s) once per
variant, builds the solver including its Lagrangian Hessian, and prints the
set-up breakdown, the size of the expanded casadi graph and the ratios:

- ``defined-variables``: the collocation blocks' shared intermediates written
  to the NL file once, as defined variables (the default), against inlined
  into every equation that uses them (``export_defined_variables = False``);
- ``hessian-percentile``: the dense-column rule of the block-wise Hessian at
  the 99th against the 90th percentile (the default).

The variants run one after the other in the same process, so their ratio is
the comparison; absolute times depend on the machine's load.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from pyomo_heli.config import ConfigError, load_identification_config  # noqa: E402
from pyomo_heli.identify import build_problem  # noqa: E402
from pyomo_heli.pareto.front import ParetoSolver  # noqa: E402
from pyomo_heli.solvers.casadi_ipopt import CasadiIpoptSolver, CasadiSettings, resolve_options  # noqa: E402

#: variant name -> CasadiSettings fields; the first is the default, the second the alternative
COMPARISONS = {
    "defined-variables": {"defined variables (default)": {"export_defined_variables": True},
                          "inlined": {"export_defined_variables": False}},
    "hessian-percentile": {"90th percentile (default)": {"hessian_dense_percentile": 90},
                           "99th percentile": {"hessian_dense_percentile": 99}},
}
#: the adapter's set-up stages (CasadiIpoptSolver.setup_breakdown)
STAGES = ("nl_write", "casadi_import", "expand", "jacobian", "hessian", "nlpsol")


def measure(cfg, attributes: dict) -> dict:
    """Build the NLP and the solver with the given adapter settings; seconds per stage."""
    t0 = time.perf_counter()
    m, _, _ = build_problem(cfg)
    build = time.perf_counter() - t0
    ParetoSolver(m, cfg.pareto)  # scales the objectives and builds the front's objective on the model
    s = CasadiIpoptSolver(m, cfg.pareto.solver_options, CasadiSettings(**attributes))  # the adapter measured
    opts, verbose, _ = resolve_options(s.options, None, "none")
    s._solver_for(opts, verbose)  # builds the Hessian
    row = {"variables": len(s.variables), "graph_instructions": s.graph_instructions, "build": build}
    row.update(s.setup_breakdown)
    row["set-up"] = sum(s.setup_breakdown.values())
    row["hessian_split"] = s._hessian_split
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--compare", choices=sorted(COMPARISONS), default="defined-variables")
    ap.add_argument("--config", default=None, help="identification config (default: the --quick benchmark instance)")
    ap.add_argument("--max-duration", type=float, default=1.0, help="crop every maneuver to this many seconds")
    ap.add_argument("--out", default=None, help="write the rows as JSON here")
    args = ap.parse_args(argv)
    try:
        if args.config is None:
            cfg = load_identification_config(ROOT / "tests" / "configs" / "small_case1_noisy.toml",
                                              {"data": {"maneuvers": ["lon3211_80kt_a", "coldoublet_hover"],
                                                        "max_duration_s": args.max_duration}})
        else:
            cfg = load_identification_config(args.config, {"data": {"max_duration_s": args.max_duration}})
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rows = {}
    for name, attributes in COMPARISONS[args.compare].items():
        rows[name] = measure(cfg, attributes)
        r = rows[name]
        stages = ", ".join(f"{k} {r[k]:.2f}" for k in STAGES)
        print(f"{name}: {r['variables']} variables, {r['graph_instructions']} graph instructions, "
              f"build {r['build']:.2f} s, set-up {r['set-up']:.2f} s ({stages}), Hessian split {r['hessian_split']}",
              flush=True)
    (a, ra), (b, rb) = rows.items()
    print(f"\n{b} / {a}: graph instructions {rb['graph_instructions'] / ra['graph_instructions']:.2f}, "
          f"set-up {rb['set-up'] / ra['set-up']:.2f}, "
          + ", ".join(f"{k} {rb[k] / max(ra[k], 1e-9):.2f}" for k in STAGES))
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps({"compare": args.compare, "config": args.config or "quick instance",
                                              "max_duration_s": args.max_duration, "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
