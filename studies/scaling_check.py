"""Point A with and without the IDAES scaling of :mod:`pyomo_heli.nlp.scaling`: Ipopt iterations and estimates.

Both solves go through the NL file (``point_rows=False``; the compiled point rows are written for the
unscaled variables) from the same initial guess, objective J_time / |J_time(initial guess)| as point A.

    python studies/scaling_check.py --maneuvers lon3211_80kt_a --max-duration 3
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import pyomo.environ as pyo

from _study_args import positive_float
from pyomo_heli.config import load_identification_config
from pyomo_heli.nlp.identification import build_identification_nlp, identification_data, set_objective
from pyomo_heli.nlp.parameters import free_parameter_values
from pyomo_heli.nlp.scaling import IdentificationScaler
from pyomo_heli.solvers.casadi_ipopt import CasadiIpoptSolver

ROOT = Path(__file__).resolve().parent.parent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "tests" / "configs" / "small_case1_noisy.toml"))
    ap.add_argument("--maneuvers", default="lon3211_80kt_a", help="comma-separated maneuver names")
    ap.add_argument("--max-duration", type=positive_float, default=3.0, help="record length used [s]")
    args = ap.parse_args(argv)
    cfg = load_identification_config(args.config, overrides={
        "data": {"maneuvers": args.maneuvers.split(","), "max_duration_s": args.max_duration}})
    data = identification_data(cfg)

    def fresh():
        m = build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp)
        set_objective(m, m.J_time / max(abs(pyo.value(m.J_time)), 1.0))
        return m

    m = fresh()
    r = CasadiIpoptSolver(m, {"point_rows": False}).solve("none")
    print(f"unscaled: {r.status}, {r.iterations} iterations, {free_parameter_values(m)}")
    m2 = fresh()
    t0 = time.perf_counter()
    IdentificationScaler().scale_model(m2)
    scaled = pyo.TransformationFactory("core.scale_model").create_using(m2, rename=False)
    t_scale = time.perf_counter() - t0
    r2 = CasadiIpoptSolver(scaled, {"point_rows": False}).solve("none")
    pyo.TransformationFactory("core.scale_model").propagate_solution(scaled, m2)
    print(f"scaled:   {r2.status}, {r2.iterations} iterations, {free_parameter_values(m2)} "
          f"(scaling factors and scaled copy {t_scale:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
