"""Composite frequency responses of the bundled sweep set against the exact linear response.

    python -m pyomo_heli.studies.sweep_check             # noise-free sweeps (the truth simulated again)
    python -m pyomo_heli.studies.sweep_check --noisy     # the recorded sweeps of data/bo105_synthetic
    python -m pyomo_heli.studies.sweep_check --duration 190 --amplitude-deg 0.05   # other sweeps (noise-free)

With ``--noisy`` it also prints J_r of Eq. 9 with ``[linear] weighting = "tischler_remple"`` (20 points
per response) for the truth model and for M0 without the wake on the tail.

The noise-free records are the truth histories of the sweeps of ``data/bo105_synthetic.toml`` (M0 + the
wake on the tail, pilot holding the attitude), taken at the record rate without sensors. The reference
is the central-difference linearisation of the same truth model at its trim
(``simulation.linearize.linearize_float``). Prints, per response, the coherent band (composite coherence
>= 0.6) and the largest gain and phase errors in it, and the frequencies where 0.5 dB or 3 deg is exceeded.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from ..dataset import load_flight_test
from ..dataset.frequency_response import DEFAULT_PAIRS, sweep_responses
from ..dataset.schema import Maneuver
from ..flighttest.config import load_config
from ..flighttest.generate import PAD, _moved, simulate_maneuvers, truth_model
from ..simulation.linearize import linearize_float

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "data" / "bo105_synthetic.toml"


def noise_free_sweeps(config=CONFIG, names=None, duration=None, amplitude=None):
    """Noise-free records (Maneuver objects at the record rate) of the pilot-flown sweeps of ``config``,
    the truth model and its trims. ``duration`` [s] changes the length of every sweep record (the sweep
    law over that length, the same dwell), ``amplitude`` [rad] the sweep amplitude."""
    import dataclasses

    cfg = load_config(config)
    plans = [p for p in cfg.maneuvers if p.shape == "sweep" and (names is None or p.name in names)]
    if duration is not None:
        plans = [dataclasses.replace(p, step=duration - p.t_start - 1.0, duration=duration) for p in plans]
    if amplitude is not None:
        plans = [dataclasses.replace(p, amplitude=amplitude) for p in plans]
    cfg = dataclasses.replace(cfg, maneuvers=plans, trim_speeds=[], trim_stream=None)
    model = truth_model(cfg)
    trims, runs = simulate_maneuvers(cfg, model)
    dec = cfg.sensors.decimation
    records = []
    for p in plans:
        run = runs[p.name].iloc[::dec].reset_index(drop=True)
        keep = (run.t >= PAD - 1e-9) & (run.t <= PAD + p.duration + 1e-9)
        data = run[keep].reset_index(drop=True)
        data = data.assign(t=data.t - PAD)
        records.append(Maneuver(p.name, p.role, p.speed, _moved(p), data))
    return records, model, trims


def errors(fr, lin) -> dict:
    """Band and largest errors of one composite response against the linear model."""
    k = fr.coherent
    ratio = fr.T[k] / lin.frequency_response(fr.output, fr.input, fr.omega[k])
    db, deg = np.abs(20 * np.log10(np.abs(ratio))), np.abs(np.degrees(np.angle(ratio)))
    w = fr.omega[k]
    bad = (db > 0.5) | (deg > 3.0)
    band = f"{w.min():.2f}-{w.max():.2f}" if k.any() else "-"
    return {"response": fr.label, "bins": int(k.sum()), "band_rad_s": band,
            "max_dB": float(db.max()) if k.any() else np.nan, "max_deg": float(deg.max()) if k.any() else np.nan,
            "above_0.5dB_or_3deg_rad_s": " ".join(f"{x:.2f}" for x in w[bad]),
            "max_dB_above": float(db[w > w[bad].max()].max()) if bad.any() and (w > w[bad].max()).any() else np.nan,
            "max_deg_above": float(deg[w > w[bad].max()].max()) if bad.any() and (w > w[bad].max()).any() else np.nan}


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noisy", action="store_true", help="the recorded sweeps of data/bo105_synthetic")
    ap.add_argument("--duration", type=float, help="noise-free sweeps regenerated with records this long [s] "
                    "(bundled: 95)")
    ap.add_argument("--amplitude-deg", type=float, help="noise-free sweeps regenerated with this amplitude [deg] "
                    "(bundled: 0.2)")
    args = ap.parse_args(argv)
    if args.noisy and (args.duration or args.amplitude_deg):
        ap.error("--noisy uses the recorded sweeps; --duration and --amplitude-deg regenerate noise-free ones")
    if args.duration is not None and not args.duration > 10:
        ap.error(f"--duration must be more than 10 s, got {args.duration:g}")
    if args.amplitude_deg is not None and not args.amplitude_deg > 0:
        ap.error(f"--amplitude-deg must be positive, got {args.amplitude_deg:g}")
    records, model, trims = noise_free_sweeps(
        duration=args.duration, amplitude=None if args.amplitude_deg is None else np.radians(args.amplitude_deg))
    if args.noisy:
        ft = load_flight_test(ROOT / "data" / "bo105_synthetic")
        records = ft.frequency()
    rows = []
    for fr in sweep_responses(records, DEFAULT_PAIRS):
        V = min(trims, key=lambda v: abs(v - fr.speed))
        rows.append(errors(fr, linearize_float(model, V, trims[V])))
    table = pd.DataFrame(rows)
    with pd.option_context("display.width", 200, "display.max_columns", 20, "display.max_colwidth", 60):
        print(table.to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    if args.noisy:
        from ..dataset.frequency_response import tischler_remple_points
        from ..nlp.objectives import j_linear_value
        from ..physics.model import HelicopterModel
        from ..simulation.trim import trim_float

        band = [tischler_remple_points(r).band() for r in sweep_responses(records, DEFAULT_PAIRS)]
        for name, m in (("truth", model), ("M0", HelicopterModel())):
            lins = {V: linearize_float(m, V, trim_float(m, V)) for V in {r.speed for r in band}}
            js = [j_linear_value([r], [lins[r.speed].frequency_response(r.output, r.input, r.omega)]) for r in band]
            print(f"J_r (tischler_remple) of {name}: " + ", ".join(f"{r.label} {j:.1f}" for r, j in zip(band, js)))
    return table


if __name__ == "__main__":
    main()
