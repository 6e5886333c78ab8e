"""The generator config of a synthetic flight test (a TOML file).

See data/bo105_synthetic.toml for a commented example. Units in key names
(``_deg``, ``_kt``, ``_s``, ``_hz``) are converted to SI here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import re

from ..settings import ConfigError, Problems, read_settings  # noqa: F401 - ConfigError: the one error type
from ..settings.generator import SWEEP_KEYS, GeneratorFile  # noqa: F401 - SWEEP_KEYS re-exported

from ..dataset.schema import (G_RANGE_M_S2, INPUT_CHANNELS, MANEUVER_QUANTITIES, MASS_RANGE_KG, MIN_SAMPLES,
                              NAME_PATTERN, RHO_RANGE_KG_M3, SAMPLE_RATE_RANGE_HZ, SPEED_RANGE_KT)
from ..physics.parameters import bo105
from ..settings.common import SIGMA_MAX_SI
from ..simulation.inputs import InputSignal, InputSpecError
from ..units import DEG, KT, SENSOR_SIGMA_KEYS
from .sensors import DEFAULT_SIGMA, DEFAULT_VIBRATION, SensorConfig
from .truth_effects import all_effects


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


#: plausible |amplitude| of a maneuver input: the dataset format's limit of the recorded input column
INPUT_LIMITS = {q.si: (q.limit, q.limit_text) for q in MANEUVER_QUANTITIES if q.si in INPUT_CHANNELS}


def _speed_problem(x: float, key: str) -> str | None:
    """A speed [kt] outside the dataset format's model speed range (what check-data accepts), else None."""
    lo, hi = SPEED_RANGE_KT
    if not lo <= x <= hi:
        return f"key '{key}' = {x:g} kt is outside the model speed range {lo:g}..{hi:g} kt of the dataset format"
    return None


def _maneuver(mv, problems: Problems, where: str, record_rate: float) -> ManeuverPlan | None:
    """A [[maneuvers]] table (checked field by field already) against the dataset format and its own shape."""
    n0 = len(problems.lines)

    def bad(message):
        problems.add(where, message)

    if not re.fullmatch(NAME_PATTERN, mv.name):
        bad("key 'name' is not a valid name: use only letters, digits, '_' and '-'")
    speed = mv.speed_kt
    if (msg := _speed_problem(speed, "speed_kt")) is not None:
        bad(msg)
    limit, limit_text = INPUT_LIMITS[mv.channel]
    amplitude = mv.amplitude_deg
    if abs(amplitude * DEG) > limit:
        bad(f"key 'amplitude_deg' = {amplitude:g} deg is beyond the plausible input limit {limit_text} of the "
            f"dataset format")
    if amplitude == 0:  # check-data refuses a record whose declared input never moves
        bad(f"key 'amplitude_deg' = 0: the maneuver's input '{mv.channel}' would never move (the dataset format "
            f"refuses a record that excites no declared input)")
    step, duration, t_start = mv.step_s, mv.duration_s, mv.t_start_s
    if duration < (MIN_SAMPLES - 1) / record_rate:  # check-data needs MIN_SAMPLES samples
        bad(f"key 'duration_s' = {duration:g} s gives fewer than {MIN_SAMPLES} samples at record_rate_hz = "
            f"{record_rate:g}")
    elif t_start >= duration:  # a record of the trim alone: its declared input would never move (check-data)
        bad(f"key 't_start_s' = {t_start:g} s lies {'at' if t_start == duration else 'after'} the end of the record "
            f"(duration_s = {duration:g} s): the input would not be recorded")
    sweep = {}
    if mv.shape == "sweep":
        sweep = {"omega_min": 0.3 if mv.omega_min_rad_s is None else mv.omega_min_rad_s,
                 "omega_max": 20.0 if mv.omega_max_rad_s is None else mv.omega_max_rad_s,
                 "dwell": 2 if mv.dwell_cycles is None else mv.dwell_cycles,
                 "pilot": True if mv.pilot is None else mv.pilot}
        if not sweep["omega_max"] > sweep["omega_min"]:
            bad(f"key 'omega_max_rad_s' must be > {sweep['omega_min']:g} rad/s, got {sweep['omega_max']:g}")
        else:
            try:  # the shape's own checks (length against dwell and lowest period)
                InputSignal(mv.channel, mv.shape, amplitude * DEG, step, omega_min=sweep["omega_min"],
                            omega_max=sweep["omega_max"], dwell=sweep["dwell"])
            except InputSpecError as exc:
                bad(f"key 'step_s' (the sweep length): {exc}")
        if t_start + step > duration:
            bad(f"key 'step_s' = {step:g} s (the sweep length) from t_start_s = {t_start:g} s runs past duration_s = "
                f"{duration:g} s")
    elif mv.ramp_s > step:  # (a multistep cut by the record's end is allowed: short test records are)
        bad(f"key 'ramp_s' = {mv.ramp_s:g} s is longer than a pulse (step_s = {step:g} s)")
    if len(problems.lines) > n0:
        return None
    return ManeuverPlan(name=mv.name, role=mv.role, speed=speed * KT, channel=mv.channel, shape=mv.shape,
                        amplitude=amplitude * DEG, step=step, duration=duration, t_start=t_start, ramp=mv.ramp_s,
                        **sweep)


def load_config(path: str | Path) -> GeneratorConfig:
    """Read and check a generator config (declared in :mod:`pyomo_heli.settings.generator`): every error of the
    fields at once, then every error of the rules against the dataset format, the truth effects and the shapes."""
    path = Path(path)
    s, problems = read_settings(path, GeneratorFile)

    params = dict(s.truth.parameters)
    nominal = bo105()
    for k in params:
        if k not in nominal:
            problems.add("truth.parameters", f"unknown parameter name '{k}'")
    if not problems:
        try:
            nominal = nominal.with_values(**params)  # the parameter table's own domain checks, if any
        except (KeyError, ValueError) as exc:
            problems.add("truth.parameters", f"{exc.args[0] if exc.args else exc}")
        # the manifest's mass and atmosphere come from these: check-data's plausible ranges
        for k, (lo, hi), unit in (("m", MASS_RANGE_KG, "kg"), ("rho", RHO_RANGE_KG_M3, "kg/m^3"),
                                  ("g", G_RANGE_M_S2, "m/s^2")):
            if not lo <= nominal[k] <= hi:
                problems.add("truth.parameters", f"{k} = {nominal[k]:g} {unit} is outside the plausible range "
                                                 f"{lo:g}..{hi:g} {unit} of the dataset format (manifest check)")
    effects = {}
    TRUTH_EFFECTS = all_effects()
    by_class = {}  # one effect under two of its names would be applied twice (truth.json would record it once)
    for name, eff in s.truth.effects.items():
        if name not in TRUTH_EFFECTS:
            problems.add("truth.effects", f"unknown effect '{name}'; choose from {', '.join(sorted(TRUTH_EFFECTS))}")
            continue
        if TRUTH_EFFECTS[name] in by_class:
            problems.add("truth.effects", f"'{name}' and '{by_class[TRUTH_EFFECTS[name]]}' name the same effect; "
                                          "give it once")
            continue
        by_class[TRUTH_EFFECTS[name]] = name
        known = [p.name for p in TRUTH_EFFECTS[name]().parameters()]
        for k in eff:
            if k not in known:
                problems.add(f"truth.effects.{name}", f"unknown parameter name '{k}'; use {', '.join(known)}")
        effects[name] = dict(eff)

    sen = s.sensors
    noise = sen.noise
    for key, v in sen.sigma.model_dump(exclude_none=True).items():
        if v * SENSOR_SIGMA_KEYS[key][1] > SIGMA_MAX_SI:
            problems.add("sensors.sigma", f"'{key}' = {v!r} is not a sensor noise sigma (above {SIGMA_MAX_SI:g} in "
                                          "SI: rad, rad/s, g or m/s); a unit slip?")
    sigma = dict(DEFAULT_SIGMA) if noise else {}
    vib = dict(DEFAULT_VIBRATION) if noise else {}
    if noise:  # checked with noise = false too (then unused): a misspelt channel must not wait for noise = true
        for table, target in ((sen.sigma, sigma), (sen.vibration, vib)):
            for k, v in table.model_dump(exclude_none=True).items():
                target[SENSOR_SIGMA_KEYS[k][0]] = v * SENSOR_SIGMA_KEYS[k][1]
    record_rate = sen.record_rate_hz
    sensors = None
    if not SAMPLE_RATE_RANGE_HZ[0] <= record_rate <= SAMPLE_RATE_RANGE_HZ[1]:  # check-data's plausible rates
        problems.add("sensors", f"key 'record_rate_hz' = {record_rate:g} Hz is outside the plausible "
                                f"{SAMPLE_RATE_RANGE_HZ[0]:g}..{SAMPLE_RATE_RANGE_HZ[1]:,.0f} Hz of the dataset format")
    else:
        try:
            sensors = SensorConfig(sim_rate=sen.sim_rate_hz, record_rate=record_rate, antialias_hz=sen.antialias_hz,
                                   sigma=sigma, vibration=vib, tas_sigma_low_speed=sen.tas_sigma_low_speed_m_s
                                   if noise else 0.0)
        except ValueError as exc:  # rates that do not fit together
            problems.add("sensors", str(exc))
    tr = s.trims
    for j, v in enumerate(tr.speeds_kt):
        if (msg := _speed_problem(v, f"speeds_kt[{j}]")) is not None:
            problems.add("trims", msg)
    speeds = [v * KT for v in tr.speeds_kt]
    ts = {"col": DEG * tr.sigma_col_deg, "lon": DEG * tr.sigma_lon_deg,
          "theta": DEG * tr.sigma_theta_deg} if noise else {}
    to = {"col": DEG * tr.offset_col_deg, "lon": DEG * tr.offset_lon_deg,
          "theta": DEG * tr.offset_theta_deg} if noise else {}

    plans = [_maneuver(mv, problems, f"[[maneuvers]] #{i + 1} ('{mv.name}')", record_rate)
             for i, mv in enumerate(s.maneuvers)]
    names = [mv.name for mv in s.maneuvers]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        problems.add("[[maneuvers]]", f"duplicate maneuver names ({', '.join(dup)})")
    if not any(mv.role == "identification" for mv in s.maneuvers):
        problems.add("[[maneuvers]]", "no maneuver has role 'identification'; the dataset needs at least one")
    ds = s.dataset
    if ds.trim_stream is not None and not ds.trim_stream <= len(s.maneuvers):
        problems.add("dataset", f"key 'trim_stream' must be an integer from 0 to the number of maneuvers "
                                f"({len(s.maneuvers)}), got {ds.trim_stream!r}")
    problems.raise_if_any()
    return GeneratorConfig(name=ds.name, aircraft=ds.aircraft, description=ds.description, seed=int(ds.seed),
                           parameters=params, effects=effects, sensors=sensors, noise=noise, trim_speeds=speeds,
                           trim_sigma=ts, trim_offset=to, maneuvers=plans, trim_stream=ds.trim_stream)


def flight_test_noise(generator_config: str | Path) -> tuple[dict, dict, tuple[float, dict]]:
    """(sigma, trim_sigma, low_speed) in SI of a flight-test generator config (e.g. data/bo105_synthetic.toml).

    A trim point's noise is its averaging noise and its not-quite-steady offset
    together: sqrt(sigma^2 + offset^2). ``low_speed``: (speed, {output: sigma}), the sigmas that replace
    ``sigma``'s in maneuvers trimmed below that speed (the airspeed's, ``[sensors] tas_sigma_low_speed_m_s``).
    """
    cfg = load_config(generator_config)
    sigma = dict(cfg.sensors.sigma)
    trim = {k: math.hypot(cfg.trim_sigma.get(k, 0.0), cfg.trim_offset.get(k, 0.0))
            for k in set(cfg.trim_sigma) | set(cfg.trim_offset)}
    return sigma, trim, (float(cfg.sensors.low_speed), {"TAS": float(cfg.sensors.tas_sigma_low_speed)})
