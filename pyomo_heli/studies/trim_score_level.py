"""How often does the trim-only score test fire when nothing is missing, and does it find a real effect?

    python studies/score_test_level.py --trims --seeds 0-11 [--truth m0|wake] [--noise-deg 0.2]

Every seed writes a trim-only flight test like the real Bo-105 one (docs/real_data.md): collective every
10 kt from hover, cyclic from 3 kt, attitude from 6 kt (each channel at its own speeds), root collective,
an unknown pitch-attitude datum (0.8 deg), seeded Gaussian noise of ``--noise-deg`` on every point. The truth
is M0 at f_e = 1.4 m^2, x_h = 0.02 m (``--truth m0``: nothing missing, every candidate's true strength is zero)
or that plus the truth simulator's wake-on-tail effect E1, K_lamT = 1.5 (``--truth wake``, written
independently of the candidates). It identifies f_e, x_h, a and the datum from the nominal table (nothing
held out) and prints, per seed, the score test's decision and every testable candidate's p-value
(:func:`pyomo_heli.diagnosis.trim_attribution.score_trims`, level 0.01 over the testable candidates), then the
fraction of p-values below 0.05 and 0.01 and the count of seeds with an acceptance.
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from pyomo_heli.dataset import write_flight_test
from pyomo_heli.dataset.schema import KT, TrimConventions
from pyomo_heli.flighttest.truth_effects import make_effect
from pyomo_heli.nlp.parameters import FreeParameter
from pyomo_heli.physics.conventions import TrimOutputDatum
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.workflows.trim_loop import TrimLoopConfig, predict, run_trim_loop

from .args import positive_float

DEG = math.pi / 180.0
SPEEDS_KT = {"col": range(0, 106, 10), "lon": range(3, 106, 10), "theta": range(6, 106, 10)}


def seed_range(text: str) -> range:
    try:
        a, _, b = text.partition("-")
        lo, hi = int(a), int(b or a)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--seeds {text!r}: use FIRST-LAST, e.g. 0-11") from None
    if lo < 0 or hi < lo:
        raise argparse.ArgumentTypeError(f"--seeds {text!r}: need 0 <= FIRST <= LAST")
    return range(lo, hi + 1)


def one_seed(seed: int, truth: str, noise_deg: float, folder: Path) -> dict:
    conv = TrimConventions(collective_station=0.0, theta_datum=None)
    ext = (TrimOutputDatum(),) + ((make_effect("wake_on_tail"),) if truth == "wake" else ())
    values = {"f_e": 1.4, "x_h": 0.02, "theta_datum": 0.8 * DEG, **({"K_lamT": 1.5} if truth == "wake" else {})}
    model = HelicopterModel(extensions=ext).with_parameters(**values)
    rng = np.random.default_rng(seed)
    rows = []
    for ch, kts in SPEEDS_KT.items():
        y = predict(model, conv, [v * KT for v in kts], [ch] * len(kts))
        for v, val in zip(kts, y):
            rows.append({"V": v * KT, "gamma_fp": 0.0, "col": np.nan, "lon": np.nan, "theta": np.nan,
                         ch: val + rng.normal(0.0, noise_deg * DEG)})
    manifest = {"aircraft": f"Bo-105 (synthetic trims, {truth})", "atmosphere": {"rho_kg_m3": 1.225, "g_m_s2": 9.81},
                "mass_kg": 2200.0, "maneuvers": [], "conventions": conv.to_manifest()}
    ds = write_flight_test(folder / "ds", manifest, {}, pd.DataFrame(rows))
    p = HelicopterModel().parameters
    free = [FreeParameter("f_e", p["f_e"], 0.3, 3.0, 1.0), FreeParameter("x_h", p["x_h"], -0.3, 0.3, 0.1),
            FreeParameter("a", p["a"], 4.0, 7.0, 6.0)]
    cfg = TrimLoopConfig(path=folder / "study.toml", dataset=ds, holdout_every=0, free=free, max_iterations=0)
    return run_trim_loop(cfg, folder / "out", progress=lambda *_: None)["iterations"][0]["score_test"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="score_test_level.py --trims", description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=seed_range, default=seed_range("0-11"), help="FIRST-LAST (default 0-11)")
    ap.add_argument("--truth", choices=("m0", "wake"), default="m0")
    ap.add_argument("--noise-deg", type=positive_float, default=0.2, help="noise sigma of every point [deg]")
    args = ap.parse_args(argv)
    ps, accepted, by = [], 0, {"white": [], "hc0": [], "hc3": []}
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            st = one_seed(seed, args.truth, args.noise_deg, Path(tmp))
        rows = [r for r in st["scores"] if r["testable"]]
        ps += [r["p_value"] for r in rows]
        for key in by:
            by[key] += [r["p_by_variance"][key] for r in rows]
        accepted += st["decision"] == "accepted"
        print(f"seed {seed}: {st['decision']}" + (f" ({st['accepted']})" if st["accepted"] else "") + "; p: "
              + ", ".join(f"{r['name']} {r['p_value']:.3g}" for r in rows), flush=True)
    ps = np.array(ps)
    print(f"{len(args.seeds)} seeds, truth {args.truth}, noise {args.noise_deg:g} deg: {ps.size} p-values, "
          f"{np.mean(ps < 0.05):.1%} below 0.05, {np.mean(ps < 0.01):.1%} below 0.01; acceptances {accepted}")
    for key, v in by.items():
        v = np.array(v)
        print(f"  variance {key}: {np.mean(v < 0.05):.1%} below 0.05, {np.mean(v < 0.01):.1%} below 0.01, "
              f"{int(np.sum(v < 0.01 / 4))} below 0.01/4")
    return 0


if __name__ == "__main__":
    sys.exit(main())
