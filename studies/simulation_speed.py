"""The RK4 simulation in Python against the same RK4 evaluated by casadi, in one run (docs/performance.md).

    python studies/simulation_speed.py [--config studies/case2.toml] [--repeat 3] [--out FILE.json]

For every maneuver of the config (resampled and cropped as the identification
does), at the config's initial parameters: the outputs of
``simulate(..., method="rk4", substeps=4)`` (Python) and of
``simulation.compiled.simulate_outputs`` (casadi; the first call, which builds
the casadi functions, is timed separately), the best of ``--repeat`` timings
of each, their ratio and the largest difference relative to each output's
magnitude. Both start from the same float trim (not timed).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from pyomo_heli.config import ConfigError, load_identification_config  # noqa: E402
from pyomo_heli.nlp.identification import identification_data  # noqa: E402
from pyomo_heli.simulation.compiled import simulate_outputs  # noqa: E402
from pyomo_heli.simulation.integrate import sampled, simulate  # noqa: E402
from pyomo_heli.simulation.trim import trim_float  # noqa: E402

OUTPUTS = ["q", "theta", "n_x", "n_z", "TAS", "beta_0"]


def best_of(fn, repeat: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "studies" / "case2.toml"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", help="write the rows as JSON here")
    args = ap.parse_args(argv)
    try:
        cfg = load_identification_config(args.config)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    model = cfg.model.with_parameters(**{f.name: f.initial for f in cfg.free})
    data = identification_data(cfg)
    rows = []
    print("| maneuver | samples | Python RK4 [s] | casadi RK4 [s] | first casadi call [s] | ratio "
          "| max rel. difference |")
    print("|---|---|---|---|---|---|---|")
    for mv in data.maneuvers:
        t = mv.data["t"].to_numpy()
        inc = mv.increments()
        tp = trim_float(model, mv.trim_speed)
        t0 = time.perf_counter()
        simulate_outputs(model, tp, t, inc, OUTPUTS, 4)
        first = time.perf_counter() - t0
        t_py, df = best_of(lambda: simulate(model, tp, t, {k: sampled(t, v) for k, v in inc.items()},
                                            method="rk4", substeps=4), args.repeat)
        t_ca, y = best_of(lambda: simulate_outputs(model, tp, t, inc, OUTPUTS, 4), args.repeat)
        diff = max(float(np.max(np.abs(y[o] - df[o].to_numpy())) / max(np.max(np.abs(df[o].to_numpy())), 1e-12))
                   for o in OUTPUTS)
        rows.append({"maneuver": mv.name, "samples": len(t), "python": t_py, "casadi": t_ca, "first_casadi": first,
                     "ratio": t_py / t_ca, "max_rel_difference": diff})
        print(f"| {mv.name} | {len(t)} | {t_py:.3f} | {t_ca:.4f} | {first:.3f} | {t_py / t_ca:.1f} | {diff:.1e} |")
    total_py, total_ca = sum(r["python"] for r in rows), sum(r["casadi"] for r in rows)
    print(f"\nall maneuvers: Python {total_py:.2f} s, casadi {total_ca:.3f} s, ratio {total_py / total_ca:.1f}; "
          f"largest relative difference {max(r['max_rel_difference'] for r in rows):.1e}")
    if args.out:
        Path(args.out).write_text(json.dumps({"config": args.config, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
