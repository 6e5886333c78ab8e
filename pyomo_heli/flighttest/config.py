"""The generator config of a synthetic flight test (a TOML file).

See data/bo105_synthetic.toml for a commented example. Units in key names
(``_deg``, ``_kt``, ``_s``, ``_hz``) are converted to SI here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import re

from ..tomlfile import read_toml

from ..dataset.schema import (G_RANGE_M_S2, INPUT_CHANNELS, MANEUVER_QUANTITIES, MASS_RANGE_KG, MIN_SAMPLES,
                              NAME_PATTERN, RHO_RANGE_KG_M3, ROLES, SAMPLE_RATE_RANGE_HZ, SPEED_RANGE_KT)
from ..physics.parameters import bo105
from ..simulation.inputs import SHAPES, InputSignal, InputSpecError
from ..units import DEG, KT, SENSOR_SIGMA_KEYS
from .sensors import DEFAULT_SIGMA, DEFAULT_VIBRATION, SensorConfig
from .truth_effects import all_effects


class ConfigError(ValueError):
    """A bad generator config; the message names the file and key."""


@dataclass
class ManeuverPlan:
    name: str
    role: str
    speed: float  # m/s
    channel: str
    shape: str
    amplitude: float  # rad
    step: float  # s
    duration: float  # s
    t_start: float = 2.0
    ramp: float = 0.1
    #: sweep only (shape "sweep", ``step`` = whole sweep length): frequency range [rad/s], dwell cycles
    omega_min: float = 0.3
    omega_max: float = 20.0
    dwell: int = 2
    #: sweep only: flown with the pilot holding the attitude (flighttest/pilot.py); default true for sweeps
    pilot: bool = False


@dataclass
class GeneratorConfig:
    name: str
    aircraft: str
    description: str
    seed: int
    parameters: dict  # overrides of the nominal table (SI)
    effects: dict  # effect name -> {param: value}
    sensors: SensorConfig
    noise: bool
    trim_speeds: list  # m/s
    trim_sigma: dict
    trim_offset: dict
    maneuvers: list = field(default_factory=list)
    #: SeedSequence child that draws the trim noise; None = the child after the last maneuver
    #: (generate.py, docs/flight_test.md section 5)
    trim_stream: int | None = None


def _get(d: dict, key: str, where: str, typ=None, default=...):
    if key not in d:
        if default is ...:
            raise ConfigError(f"{where}: missing key '{key}'")
        return default
    v = d[key]
    if typ is float and isinstance(v, int) and not isinstance(v, bool):
        v = float(v)
    if typ is not None and not isinstance(v, typ):
        raise ConfigError(f"{where}: key '{key}' must be {typ.__name__}, got {v!r}")
    return v


#: recognised keys of each generator table (the tables with free names, [truth.parameters],
#: [truth.effects.*], [sensors.sigma] and [sensors.vibration], are checked against their vocabularies)
TOP_KEYS = ("dataset", "truth", "sensors", "trims", "maneuvers")
DATASET_KEYS = ("name", "aircraft", "description", "seed", "trim_stream")
TRUTH_KEYS = ("parameters", "effects")
SENSOR_KEYS = ("noise", "sim_rate_hz", "record_rate_hz", "antialias_hz", "sigma", "vibration",
               "tas_sigma_low_speed_m_s")
TRIM_KEYS = ("speeds_kt", "sigma_col_deg", "sigma_lon_deg", "sigma_theta_deg", "offset_col_deg", "offset_lon_deg",
             "offset_theta_deg")
MANEUVER_KEYS = ("name", "role", "speed_kt", "channel", "shape", "amplitude_deg", "step_s", "duration_s",
                 "t_start_s", "ramp_s", "omega_min_rad_s", "omega_max_rad_s", "dwell_cycles", "pilot")
#: keys only a frequency sweep takes
SWEEP_KEYS = ("omega_min_rad_s", "omega_max_rad_s", "dwell_cycles", "pilot")
#: plausible |amplitude| of a maneuver input: the dataset format's limit of the recorded input column
INPUT_LIMITS = {q.si: (q.limit, q.limit_text) for q in MANEUVER_QUANTITIES if q.si in INPUT_CHANNELS}


def _known(d: dict, keys, where: str) -> None:
    """A misspelt key must not be silently ignored."""
    for k in d:
        if k not in keys:
            raise ConfigError(f"{where}: unknown key '{k}'; recognised keys: {', '.join(keys)}")


def _number(v, key: str, where: str, lo: float | None = None, hi: float | None = None, lo_open: bool = False,
            unit: str = "") -> float:
    """``v`` as a finite float within lo..hi (lo excluded with ``lo_open``), else a ConfigError naming ``key``."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ConfigError(f"{where}: key '{key}' must be a number, got {v!r}")
    x = float(v)
    u = f" {unit}" if unit else ""
    if not math.isfinite(x):
        raise ConfigError(f"{where}: key '{key}' must be a finite number, got {v!r}")
    if lo is not None and (x <= lo if lo_open else x < lo):
        raise ConfigError(f"{where}: key '{key}' must be {'>' if lo_open else '>='} {lo:g}{u}, got {x:g}")
    if hi is not None and x > hi:
        raise ConfigError(f"{where}: key '{key}' must be <= {hi:g}{u}, got {x:g}")
    return x


def _speed(v, key: str, where: str) -> float:
    """A trim speed [kt] within the dataset format's model speed range (what check-data accepts)."""
    lo, hi = SPEED_RANGE_KT
    x = _number(v, key, where, unit="kt")
    if not lo <= x <= hi:
        raise ConfigError(f"{where}: key '{key}' = {x:g} kt is outside the model speed range {lo:g}..{hi:g} kt "
                          "of the dataset format")
    return x


def _maneuver(mv, where: str, record_rate: float) -> ManeuverPlan:
    if not isinstance(mv, dict):
        raise ConfigError(f"{where}: must be a table of maneuver keys, got {mv!r}")
    named = f"{where} ('{mv['name']}')" if isinstance(mv.get("name"), str) else where
    _known(mv, MANEUVER_KEYS, named)
    name = _get(mv, "name", where, str)
    if not re.fullmatch(NAME_PATTERN, name):
        raise ConfigError(f"{named}: key 'name' is not a valid name: use only letters, digits, '_' and '-'")
    where = named
    role = _get(mv, "role", where, str)
    if role not in ROLES:
        raise ConfigError(f"{where}: role must be one of {', '.join(ROLES)}, got {role!r}")
    channel = _get(mv, "channel", where, str)
    if channel not in INPUT_CHANNELS:
        raise ConfigError(f"{where}: key 'channel' must be one of {', '.join(INPUT_CHANNELS)}, got {channel!r}")
    shape = _get(mv, "shape", where, str)
    if shape not in SHAPES:
        raise ConfigError(f"{where}: key 'shape' must be one of {', '.join(SHAPES)}, got {shape!r}")
    speed = _speed(_get(mv, "speed_kt", where, float), "speed_kt", where)
    limit, limit_text = INPUT_LIMITS[channel]
    amplitude = _number(_get(mv, "amplitude_deg", where, float), "amplitude_deg", where, unit="deg")
    if abs(amplitude * DEG) > limit:
        raise ConfigError(f"{where}: key 'amplitude_deg' = {amplitude:g} deg is beyond the plausible input "
                          f"limit {limit_text} of the dataset format")
    if amplitude == 0:  # check-data refuses a record whose declared input never moves
        raise ConfigError(f"{where}: key 'amplitude_deg' = 0: the maneuver's input '{channel}' would never move "
                          f"(the dataset format refuses a record that excites no declared input)")
    step = _number(_get(mv, "step_s", where, float), "step_s", where, lo=0.0, lo_open=True, unit="s")
    duration = _number(_get(mv, "duration_s", where, float), "duration_s", where, lo=0.0, lo_open=True, unit="s")
    if duration < (MIN_SAMPLES - 1) / record_rate:  # check-data needs MIN_SAMPLES samples
        raise ConfigError(f"{where}: key 'duration_s' = {duration:g} s gives fewer than {MIN_SAMPLES} samples at "
                          f"record_rate_hz = {record_rate:g}")
    t_start = _number(_get(mv, "t_start_s", where, float, 2.0), "t_start_s", where, lo=0.0, unit="s")
    if t_start >= duration:  # a record of the trim alone: its declared input would never move (check-data)
        raise ConfigError(f"{where}: key 't_start_s' = {t_start:g} s lies {'at' if t_start == duration else 'after'} "
                          f"the end of the record (duration_s = {duration:g} s): the input would not be recorded")
    ramp = _number(_get(mv, "ramp_s", where, float, 0.1), "ramp_s", where, lo=0.0, unit="s")
    sweep = {}
    if shape != "sweep":
        for k in SWEEP_KEYS:
            if k in mv:
                raise ConfigError(f"{where}: key '{k}' applies only to shape 'sweep', not {shape!r}")
    else:
        sweep["omega_min"] = _number(_get(mv, "omega_min_rad_s", where, float, 0.3), "omega_min_rad_s", where,
                                     lo=0.0, lo_open=True, unit="rad/s")
        sweep["omega_max"] = _number(_get(mv, "omega_max_rad_s", where, float, 20.0), "omega_max_rad_s", where,
                                     lo=sweep["omega_min"], lo_open=True, unit="rad/s")
        dwell = _get(mv, "dwell_cycles", where, int, 2)
        if isinstance(dwell, bool) or dwell < 0:
            raise ConfigError(f"{where}: key 'dwell_cycles' must be an integer >= 0, got {dwell!r}")
        sweep["dwell"] = dwell
        pilot = _get(mv, "pilot", where, bool, True)
        if not isinstance(pilot, bool):
            raise ConfigError(f"{where}: key 'pilot' must be true or false, got {pilot!r}")
        sweep["pilot"] = pilot
        try:  # the shape's own checks (length against dwell and lowest period)
            InputSignal(channel, shape, amplitude * DEG, step, omega_min=sweep["omega_min"],
                        omega_max=sweep["omega_max"], dwell=dwell)
        except InputSpecError as exc:
            raise ConfigError(f"{where}: key 'step_s' (the sweep length): {exc}") from None
        if t_start + step > duration:
            raise ConfigError(f"{where}: key 'step_s' = {step:g} s (the sweep length) from t_start_s = {t_start:g} s "
                              f"runs past duration_s = {duration:g} s")
    return ManeuverPlan(name=name, role=role, speed=speed * KT, channel=channel, shape=shape,
                        amplitude=amplitude * DEG, step=step, duration=duration, t_start=t_start, ramp=ramp, **sweep)


def load_config(path: str | Path) -> GeneratorConfig:
    path = Path(path)
    raw = read_toml(path, ConfigError)
    w = str(path)
    _known(raw, TOP_KEYS, w)
    ds = _get(raw, "dataset", w, dict)
    _known(ds, DATASET_KEYS, f"{w} [dataset]")
    truth = _get(raw, "truth", w, dict, {})
    _known(truth, TRUTH_KEYS, f"{w} [truth]")
    params = {}
    nominal = bo105()
    for k, v in _get(truth, "parameters", f"{w} [truth]", dict, {}).items():
        if k not in nominal:
            raise ConfigError(f"{w} [truth.parameters]: unknown parameter name '{k}'")
        params[k] = _number(v, k, f"{w} [truth.parameters]")
    try:
        nominal = nominal.with_values(**params)  # the parameter table's own domain checks, if any
    except (KeyError, ValueError) as exc:
        raise ConfigError(f"{w} [truth.parameters]: {exc.args[0] if exc.args else exc}") from None
    # the manifest's mass and atmosphere come from these: check-data's plausible ranges
    for k, (lo, hi), unit in (("m", MASS_RANGE_KG, "kg"), ("rho", RHO_RANGE_KG_M3, "kg/m^3"),
                              ("g", G_RANGE_M_S2, "m/s^2")):
        if not lo <= nominal[k] <= hi:
            raise ConfigError(f"{w} [truth.parameters]: {k} = {nominal[k]:g} {unit} is outside the plausible range "
                              f"{lo:g}..{hi:g} {unit} of the dataset format (manifest check)")
    effects = {}
    TRUTH_EFFECTS = all_effects()
    for name, eff in _get(truth, "effects", f"{w} [truth]", dict, {}).items():
        if name not in TRUTH_EFFECTS:
            raise ConfigError(f"{w} [truth.effects]: unknown effect '{name}'; choose from "
                              f"{', '.join(sorted(TRUTH_EFFECTS))}")
        if not isinstance(eff, dict):
            raise ConfigError(f"{w} [truth.effects]: '{name}' must be a table of its parameters, got {eff!r}")
        known = [s.name for s in TRUTH_EFFECTS[name]().parameters()]
        for k in eff:
            if k not in known:
                raise ConfigError(f"{w} [truth.effects.{name}]: unknown parameter name '{k}'; "
                                  f"use {', '.join(known)}")
        effects[name] = {k: _number(v, k, f"{w} [truth.effects.{name}]") for k, v in eff.items()}

    sen = _get(raw, "sensors", w, dict, {})
    ws = f"{w} [sensors]"
    _known(sen, SENSOR_KEYS, ws)
    noise = bool(_get(sen, "noise", ws, bool, True))
    sigma = dict(DEFAULT_SIGMA) if noise else {}
    vib = dict(DEFAULT_VIBRATION) if noise else {}
    conv = SENSOR_SIGMA_KEYS
    for table, target in (("sigma", sigma), ("vibration", vib)):
        # checked with noise = false too (then unused): a misspelt channel must not wait for noise = true
        for k, v in _get(sen, table, ws, dict, {}).items():
            if k not in conv:
                raise ConfigError(f"{w} [sensors.{table}]: unknown channel '{k}'; use {', '.join(conv)}")
            x = _number(v, k, f"{w} [sensors.{table}]", lo=0.0)
            if noise:
                target[conv[k][0]] = x * conv[k][1]
    sim_rate = _number(_get(sen, "sim_rate_hz", ws, float, 400.0), "sim_rate_hz", ws, lo=0.0, lo_open=True,
                       unit="Hz")
    record_rate = _number(_get(sen, "record_rate_hz", ws, float, 50.0), "record_rate_hz", ws, lo=0.0,
                          lo_open=True, unit="Hz")
    if not SAMPLE_RATE_RANGE_HZ[0] <= record_rate <= SAMPLE_RATE_RANGE_HZ[1]:  # check-data's plausible rates
        raise ConfigError(f"{ws}: key 'record_rate_hz' = {record_rate:g} Hz is outside the plausible "
                          f"{SAMPLE_RATE_RANGE_HZ[0]:g}..{SAMPLE_RATE_RANGE_HZ[1]:,.0f} Hz of the dataset format")
    antialias = _number(_get(sen, "antialias_hz", ws, float, 10.0), "antialias_hz", ws, lo=0.0, lo_open=True,
                        unit="Hz")
    tas_low = _number(_get(sen, "tas_sigma_low_speed_m_s", ws, float, 1.0), "tas_sigma_low_speed_m_s", ws, lo=0.0)
    try:
        sensors = SensorConfig(sim_rate=sim_rate, record_rate=record_rate, antialias_hz=antialias,
                               sigma=sigma, vibration=vib, tas_sigma_low_speed=tas_low if noise else 0.0)
    except ValueError as exc:  # rates that do not fit together
        raise ConfigError(f"{ws}: {exc}") from None
    tr = _get(raw, "trims", w, dict)
    wt = f"{w} [trims]"
    _known(tr, TRIM_KEYS, wt)
    speeds_kt = _get(tr, "speeds_kt", wt, list)
    speeds = [_speed(v, f"speeds_kt[{j}]", wt) * KT for j, v in enumerate(speeds_kt)]
    spread = {k: DEG * _number(_get(tr, k, wt, float, d), k, wt, lo=0.0, unit="deg")
              for k, d in (("sigma_col_deg", 0.05), ("sigma_lon_deg", 0.05), ("sigma_theta_deg", 0.1),
                           ("offset_col_deg", 0.05), ("offset_lon_deg", 0.05), ("offset_theta_deg", 0.1))}
    ts = {"col": spread["sigma_col_deg"], "lon": spread["sigma_lon_deg"],
          "theta": spread["sigma_theta_deg"]} if noise else {}
    to = {"col": spread["offset_col_deg"], "lon": spread["offset_lon_deg"],
          "theta": spread["offset_theta_deg"]} if noise else {}

    plans = [_maneuver(mv, f"{w} [[maneuvers]] #{i + 1}", record_rate)
             for i, mv in enumerate(_get(raw, "maneuvers", w, list))]
    names = [p.name for p in plans]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ConfigError(f"{w} [[maneuvers]]: duplicate maneuver names ({', '.join(dup)})")
    if not any(p.role == "identification" for p in plans):
        raise ConfigError(f"{w} [[maneuvers]]: no maneuver has role 'identification'; the dataset needs at least "
                          "one")
    wd = f"{w} [dataset]"
    seed = _get(ds, "seed", wd, int)
    if isinstance(seed, bool) or seed < 0:
        raise ConfigError(f"{wd}: key 'seed' must be an integer >= 0, got {seed!r}")
    trim_stream = _get(ds, "trim_stream", wd, int, None)
    if trim_stream is not None and (isinstance(trim_stream, bool) or not 0 <= trim_stream <= len(plans)):
        raise ConfigError(f"{wd}: key 'trim_stream' must be an integer from 0 to the number of maneuvers "
                          f"({len(plans)}), got {trim_stream!r}")
    return GeneratorConfig(name=_get(ds, "name", wd, str), aircraft=_get(ds, "aircraft", wd, str),
                           description=_get(ds, "description", wd, str, ""), seed=int(seed),
                           parameters=params, effects=effects, sensors=sensors, noise=noise, trim_speeds=speeds,
                           trim_sigma=ts, trim_offset=to, maneuvers=plans, trim_stream=trim_stream)


def flight_test_noise(generator_config: str | Path) -> tuple[dict, dict]:
    """(sigma, trim_sigma) in SI of a flight-test generator config (e.g. data/bo105_synthetic.toml).

    A trim point's noise is its averaging noise and its not-quite-steady offset
    together: sqrt(sigma^2 + offset^2).
    """
    cfg = load_config(generator_config)
    sigma = dict(cfg.sensors.sigma)
    trim = {k: math.hypot(cfg.trim_sigma.get(k, 0.0), cfg.trim_offset.get(k, 0.0))
            for k in set(cfg.trim_sigma) | set(cfg.trim_offset)}
    return sigma, trim
