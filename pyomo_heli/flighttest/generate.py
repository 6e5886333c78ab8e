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
from ..ioerrors import visible_entries
from ..physics.model import HelicopterModel
from ..simulation.compiled import simulate_with_feedback
from ..simulation.inputs import InputSignal
from ..simulation.integrate import simulate
from ..simulation.linearize import linearize_float
from ..simulation.trim import trim_sweep
from .config import GeneratorConfig, load_config
from .pilot import pilot_gains, remnant
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


def truth_model_of(dataset: str | Path) -> HelicopterModel:
    """The truth model of a generated flight test: M0 plus the effects of its ``truth.json``, at the parameter
    values recorded there (SI). FileNotFoundError naming ``truth.json`` for a dataset without one (measured
    data has no truth)."""
    f = Path(dataset) / "truth.json"
    if not f.is_file():
        raise FileNotFoundError(f"{f}: no truth.json (only a generated flight test has a truth model)")
    truth = json.loads(f.read_text())
    model = HelicopterModel(extensions=[make_effect(n) for n in truth.get("effects", {})])
    return model.with_parameters(**truth["parameters"])


def simulate_maneuvers(cfg: GeneratorConfig, model: HelicopterModel):
    """Truth trims and noise-free maneuver histories at the simulation rate."""
    speeds = sorted({p.speed for p in cfg.maneuvers} | set(cfg.trim_speeds))
    trims = dict(zip(speeds, trim_sweep(model, speeds)))
    runs = {}
    streams = stream_indices(cfg)
    for k, plan in enumerate(cfg.maneuvers):
        sig = InputSignal(plan.channel, plan.shape, plan.amplitude, plan.step, t_start=plan.t_start + PAD,
                          ramp=plan.ramp, omega_min=plan.omega_min, omega_max=plan.omega_max, dwell=plan.dwell)
        t = np.arange(0.0, plan.duration + 2 * PAD + 1e-9, 1.0 / cfg.sensors.sim_rate)
        if plan.pilot:
            runs[plan.name] = _fly_with_pilot(cfg, model, trims[plan.speed], plan, sig, t, streams[k])
            continue
        runs[plan.name] = simulate(model, trims[plan.speed], t, {plan.channel: sig},
                                   max_step=0.05)  # below the 0.1 s input ramps: no edge is stepped over
    return trims, runs


def pilot_rng(cfg: GeneratorConfig, stream: int) -> np.random.Generator:
    """The pilot's remnant of the maneuver on noise stream ``stream``: the first child of that stream
    (``SeedSequence(seed).spawn(...)[stream].spawn(1)[0]``), so it moves no other draw."""
    return np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(stream, 0)))


def _fly_with_pilot(cfg, model, trim, plan, sig, t, stream) -> pd.DataFrame:
    """A sweep flown with the attitude-holding pilot of flighttest/pilot.py: RK4 with the pilot's state
    feedback at every stage (one step per sample of the simulation rate), the remnant on lon."""
    k_theta, k_q = pilot_gains(linearize_float(model, plan.speed, trim))
    inc = {plan.channel: sig(t)}
    inc["lon"] = inc.get("lon", 0.0 * t) + remnant(pilot_rng(cfg, stream), float(t[0]), float(t[-1]))(t)
    run = simulate_with_feedback(model, trim, t, inc, {"lon": {"theta": -k_theta, "q": -k_q}},
                                 x_ref={"theta": trim.theta}, substeps=1)
    return pd.DataFrame({"t": t, **run})


def _describe(p) -> str:
    """Manifest description of a maneuver plan."""
    if p.shape == "sweep":
        return (f"{p.channel} sweep, {np.degrees(p.amplitude):g} deg, {p.omega_min:g}-{p.omega_max:g} rad/s, "
                f"{p.dwell} dwell cycles, {p.step:g} s long, from t = {p.t_start:g} s"
                + (", pilot holding the attitude on lon" if p.pilot else ""))
    return f"{p.channel} {p.shape}, {np.degrees(p.amplitude):g} deg, step {p.step:g} s, from t = {p.t_start:g} s"


def stream_indices(cfg: GeneratorConfig) -> list[int]:
    """The child of SeedSequence(seed) that each maneuver's noise uses (config order; the trim stream skipped)."""
    trim = len(cfg.maneuvers) if cfg.trim_stream is None else cfg.trim_stream
    return [k if k < trim else k + 1 for k in range(len(cfg.maneuvers))]


def _moved(p) -> list[str]:
    """The inputs a maneuver moves: its channel, and lon where the pilot holds the attitude."""
    return [c for c in ("col", "lon") if c == p.channel or (p.pilot and c == "lon")]


def noise_streams(cfg: GeneratorConfig):
    """One random generator per maneuver (config order) and one for the trims, children of SeedSequence(seed)."""
    n = len(cfg.maneuvers)
    trim = n if cfg.trim_stream is None else cfg.trim_stream
    children = np.random.SeedSequence(cfg.seed).spawn(n + 1)
    maneuvers = [np.random.default_rng(children[k]) for k in stream_indices(cfg)]
    return maneuvers, np.random.default_rng(children[trim])


class OutputFolderError(ValueError):
    """``out`` holds data that generating would overwrite or mix with (one line naming the folder)."""


#: results folders of the other commands, recognised by these files: never a place for a flight test
_RESULT_MARKERS = ("checkpoint.json", "front.csv", "chosen.json", "loop.json", "starts.csv", "multistart.json")


def _listed(paths, root: Path, at_most: int = 5) -> str:
    names = [p.relative_to(root).as_posix() + ("/" if p.is_dir() else "") for p in paths]
    return ", ".join(names[:at_most]) + (f", ... ({len(names)} in all)" if len(names) > at_most else "")


def flight_test_files(out: Path) -> list[Path]:
    """The files of the flight test in ``out``: manifest, trim table, truth and every maneuver file the manifest
    lists, plus CSV files left in ``maneuvers/`` (the writer's default place, e.g. orphans of an older version)."""
    files = [out / "manifest.json", out / "truth.json", out / "trims.csv"]
    try:
        man = json.loads((out / "manifest.json").read_text(encoding="utf-8-sig"))
    except (OSError, ValueError):
        man = {}
    if isinstance(man, dict):
        rels = [man.get("trim_file")] + [e.get("file") for e in man.get("maneuvers", []) if isinstance(e, dict)] \
            if isinstance(man.get("maneuvers", []), list) else [man.get("trim_file")]
        for rel in rels:
            if isinstance(rel, str) and rel and not Path(rel).is_absolute() and ".." not in Path(rel).parts:
                files.append(out / rel)
    if (out / "maneuvers").is_dir():
        files += list((out / "maneuvers").glob("*.csv"))
    seen, unique = set(), []
    for f in files:
        if f.is_file() and f not in seen:
            seen.add(f)
            unique.append(f)
    return unique


def check_output_folder(out: str | Path, force: bool = False) -> None:
    """Refuse an ``out`` that holds data (OutputFolderError, one line naming the folder), unless ``force``.

    - a new or empty folder: fine;
    - a flight test (``manifest.json``): refused unless ``force``, which replaces it (its old files are deleted
      by :func:`clear_flight_test` once the new one has been simulated, so none is left orphaned);
    - a results folder of another command (``checkpoint.json``, ``front.csv``, ``loop.json``, ...): refused,
      ``force`` or not;
    - a folder holding other files: refused unless ``force``, which writes the flight test beside them.
    """
    out = Path(out)
    present = visible_entries(out)
    if not present:
        return
    results = [out / n for n in _RESULT_MARKERS if (out / n).exists()]
    if results:
        raise OutputFolderError(f"option --out: {out} holds pyomo-heli results ({_listed(results, out)}), not a "
                                f"flight test; choose another --out")
    if (out / "manifest.json").is_file():
        if force:
            return
        old = flight_test_files(out)
        raise OutputFolderError(f"option --out: {out} already holds a flight test ({_listed(old, out)}); "
                                f"generate-data does not overwrite data: choose another --out, or give --force "
                                f"to replace it")
    if not force:
        raise OutputFolderError(f"option --out: {out} holds other files ({_listed(present, out)}) and no flight "
                                f"test; choose a new or empty folder, or give --force to write beside them")


def clear_flight_test(out: Path) -> list[Path]:
    """Delete the flight test in ``out`` (see :func:`flight_test_files`) before a new one is written there;
    returns the deleted files. Folders left empty are removed; nothing else is touched."""
    gone = flight_test_files(out)
    for f in gone:
        f.unlink()
    for d in sorted({f.parent for f in gone}, key=lambda p: -len(p.parts)):
        if d != out and d.is_dir() and not any(d.iterdir()):
            d.rmdir()
    return gone


def generate(cfg: GeneratorConfig, out: str | Path, force: bool = False) -> Path:
    """Write the dataset (manifest, maneuver tables, trims) and truth.json to ``out``.

    ``out`` must be new or empty (:func:`check_output_folder`); ``force`` replaces a flight test there (its old
    files are deleted after the simulation, just before the new ones are written) or writes beside other files.
    """
    from ..dataset import write_flight_test

    out = Path(out)
    check_output_folder(out, force)
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
                       "inputs": _moved(p), "description": _describe(p)}
                      for p in cfg.maneuvers],
    }
    if (out / "manifest.json").is_file():  # --force on a flight test: none of its files may outlive it
        clear_flight_test(out)
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


def generate_from_file(config: str | Path, out: str | Path, seed: int | None = None, force: bool = False) -> Path:
    """Generate the flight test of ``config`` into ``out``; ``seed`` replaces its [dataset] seed (another noise
    realisation of the same flight test: truth, maneuvers, trims and noise levels unchanged). ``force``: see
    :func:`generate`."""
    check_output_folder(out, force)  # before the config's checks too: nothing is read or simulated in vain
    cfg = load_config(config)
    if seed is not None:
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
        import dataclasses

        cfg = dataclasses.replace(cfg, seed=seed)
    return generate(cfg, out, force=force)
