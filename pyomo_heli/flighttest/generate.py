"""Generate a synthetic flight test from a config: truth simulation + sensors.

Deterministic: one ``numpy.random.SeedSequence(seed)`` is split into one
child stream per maneuver (in config order) and one for the trim points, so
the same config gives byte-identical files. The trim stream is the child after
the last maneuver unless ``[dataset] trim_stream`` names its index; the
maneuvers then take the other children in order. Appending a maneuver leaves
the other maneuvers' noise unchanged; with ``trim_stream`` set to the old
number of maneuvers it leaves the trim rows unchanged too (docs/flight_test.md
section 5).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from ..channels import OUTPUTS
from ..physics.model import HelicopterModel
from ..simulation.inputs import InputSignal
from ..simulation.integrate import simulate
from ..simulation.trim import trim_sweep
from .config import GeneratorConfig, load_config
from .sensors import average_trim, record
from .truth_effects import make_effect

GENERATOR_VERSION = 1
#: steady record kept before and after each maneuver so that the zero-phase
#: anti-alias filter has no edge transient inside the delivered record [s]
PAD = 1.0
RECORDED = OUTPUTS


def truth_model(cfg: GeneratorConfig) -> HelicopterModel:
    """M0 plus the configured truth effects, at the configured parameter values."""
    effects = [make_effect(n) for n in cfg.effects]
    model = HelicopterModel(extensions=effects)
    values = dict(cfg.parameters)
    for v in cfg.effects.values():
        values.update(v)
    return model.with_parameters(**values)


def simulate_maneuvers(cfg: GeneratorConfig, model: HelicopterModel):
    """Truth trims and noise-free maneuver histories at the simulation rate."""
    speeds = sorted({p.speed for p in cfg.maneuvers} | set(cfg.trim_speeds))
    trims = dict(zip(speeds, trim_sweep(model, speeds)))
    runs = {}
    for plan in cfg.maneuvers:
        sig = InputSignal(plan.channel, plan.shape, plan.amplitude, plan.step, t_start=plan.t_start + PAD,
                          ramp=plan.ramp, omega_min=plan.omega_min, omega_max=plan.omega_max, dwell=plan.dwell)
        t = np.arange(0.0, plan.duration + 2 * PAD + 1e-9, 1.0 / cfg.sensors.sim_rate)
        runs[plan.name] = simulate(model, trims[plan.speed], t, {plan.channel: sig},
                                   max_step=0.05)  # below the 0.1 s input ramps: no edge is stepped over
    return trims, runs


def _describe(p) -> str:
    """Manifest description of a maneuver plan."""
    if p.shape == "sweep":
        return (f"{p.channel} sweep, {np.degrees(p.amplitude):g} deg, {p.omega_min:g}-{p.omega_max:g} rad/s, "
                f"{p.dwell} dwell cycles, {p.step:g} s long, from t = {p.t_start:g} s")
    return f"{p.channel} {p.shape}, {np.degrees(p.amplitude):g} deg, step {p.step:g} s, from t = {p.t_start:g} s"


def noise_streams(cfg: GeneratorConfig):
    """One random generator per maneuver (config order) and one for the trims, children of SeedSequence(seed)."""
    n = len(cfg.maneuvers)
    trim = n if cfg.trim_stream is None else cfg.trim_stream
    children = np.random.SeedSequence(cfg.seed).spawn(n + 1)
    maneuvers = [np.random.default_rng(children[k if k < trim else k + 1]) for k in range(n)]
    return maneuvers, np.random.default_rng(children[trim])


def generate(cfg: GeneratorConfig, out: str | Path) -> Path:
    """Write the dataset (manifest, maneuver tables, trims) and truth.json to ``out``."""
    from ..dataset import write_flight_test

    out = Path(out)
    model = truth_model(cfg)
    trims, runs = simulate_maneuvers(cfg, model)
    maneuver_streams, trim_rng = noise_streams(cfg)
    maneuvers = {}
    for plan, rng in zip(cfg.maneuvers, maneuver_streams):
        run = runs[plan.name]
        channels = {k: run[k].to_numpy() for k in RECORDED + ("col", "lon")}
        rec = record(run["t"].to_numpy(), channels, cfg.sensors, rng, plan.speed)
        frame = pd.DataFrame({k: rec[k] for k in ("t", "col", "lon") + RECORDED})
        keep = (frame.t >= PAD - 1e-9) & (frame.t <= PAD + plan.duration + 1e-9)
        frame = frame[keep].reset_index(drop=True)
        frame["t"] = np.round(frame["t"] - PAD, 9)
        maneuvers[plan.name] = frame
    rows = []
    # level trims plus the start trim of every identification maneuver (the paper's 14 + 10)
    level = [(v, "level") for v in cfg.trim_speeds] + [(p.speed, p.name) for p in cfg.maneuvers
                                                       if p.role == "identification"]
    for v, source in level:
        tp = trims[v]
        vals = average_trim({"col": tp.col, "lon": tp.lon, "theta": tp.theta}, cfg.trim_sigma, cfg.trim_offset,
                            trim_rng)
        rows.append({"V": v, "gamma_fp": 0.0, **vals, "source": source})
    manifest = {
        "aircraft": cfg.aircraft,
        "description": cfg.description,
        "atmosphere": {"rho_kg_m3": model.parameters["rho"], "g_m_s2": model.parameters["g"]},
        "mass_kg": model.parameters["m"],
        "maneuvers": [{"name": p.name, "role": p.role, "trim_speed_kt": round(p.speed / 0.514444444444, 6),
                       "inputs": [p.channel], "description": _describe(p)}
                      for p in cfg.maneuvers],
    }
    write_flight_test(out, manifest, maneuvers, pd.DataFrame(rows))
    truth = {
        "note": "Ground truth for evaluation only; identification code never reads this file.",
        "generator_version": GENERATOR_VERSION,
        "seed": cfg.seed,
        "effects": cfg.effects,
        "parameters": model.parameters.to_dict(),
        "noise": cfg.noise,
        "sensor_sigma_si": dict(sorted(cfg.sensors.sigma.items())),
        "trim_sigma_si": cfg.trim_sigma,
        "trim_offset_si": cfg.trim_offset,
    }
    (out / "truth.json").write_text(json.dumps(truth, indent=2, sort_keys=True) + "\n")
    return out


def generate_from_file(config: str | Path, out: str | Path, seed: int | None = None) -> Path:
    """Generate the flight test of ``config`` into ``out``; ``seed`` replaces its [dataset] seed (another noise
    realisation of the same flight test: truth, maneuvers, trims and noise levels unchanged)."""
    cfg = load_config(config)
    if seed is not None:
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
        import dataclasses

        cfg = dataclasses.replace(cfg, seed=seed)
    return generate(cfg, out)
