"""The generator config of a synthetic flight test (a TOML file).

See data/bo105_synthetic.toml for a commented example. Units in key names
(``_deg``, ``_kt``, ``_s``, ``_hz``) are converted to SI here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from ..tomlfile import read_toml

from ..physics.parameters import bo105
from ..units import DEG, KT, SENSOR_SIGMA_KEYS
from .sensors import DEFAULT_SIGMA, DEFAULT_VIBRATION, SensorConfig
from .truth_effects import TRUTH_EFFECTS


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


def load_config(path: str | Path) -> GeneratorConfig:
    path = Path(path)
    raw = read_toml(path, ConfigError)
    w = str(path)
    ds = _get(raw, "dataset", w, dict)
    truth = _get(raw, "truth", w, dict, {})
    params = {}
    nominal = bo105()
    for k, v in _get(truth, "parameters", f"{w} [truth]", dict, {}).items():
        if k not in nominal:
            raise ConfigError(f"{w} [truth.parameters]: unknown parameter name '{k}'")
        params[k] = float(v)
    effects = {}
    for name, eff in _get(truth, "effects", f"{w} [truth]", dict, {}).items():
        if name not in TRUTH_EFFECTS:
            raise ConfigError(f"{w} [truth.effects]: unknown effect '{name}'; choose from "
                              f"{', '.join(sorted(TRUTH_EFFECTS))}")
        known = [s.name for s in TRUTH_EFFECTS[name]().parameters()]
        for k in eff:
            if k not in known:
                raise ConfigError(f"{w} [truth.effects.{name}]: unknown parameter name '{k}'; "
                                  f"use {', '.join(known)}")
        effects[name] = {k: float(v) for k, v in eff.items()}

    sen = _get(raw, "sensors", w, dict, {})
    noise = bool(_get(sen, "noise", f"{w} [sensors]", bool, True))
    sigma = dict(DEFAULT_SIGMA) if noise else {}
    vib = dict(DEFAULT_VIBRATION) if noise else {}
    conv = SENSOR_SIGMA_KEYS
    for table, target in (("sigma", sigma), ("vibration", vib)) if noise else ():
        for k, v in _get(sen, table, f"{w} [sensors]", dict, {}).items():
            if k not in conv:
                raise ConfigError(f"{w} [sensors.{table}]: unknown channel '{k}'; use {', '.join(conv)}")
            target[conv[k][0]] = float(v) * conv[k][1]
    sensors = SensorConfig(
        sim_rate=float(_get(sen, "sim_rate_hz", w, float, 400.0)),
        record_rate=float(_get(sen, "record_rate_hz", w, float, 50.0)),
        antialias_hz=float(_get(sen, "antialias_hz", w, float, 10.0)),
        sigma=sigma, vibration=vib,
        tas_sigma_low_speed=float(_get(sen, "tas_sigma_low_speed_m_s", w, float, 1.0)) if noise else 0.0,
    )
    tr = _get(raw, "trims", w, dict)
    speeds = [float(v) * KT for v in _get(tr, "speeds_kt", f"{w} [trims]", list)]
    if any(v < 0 or v > 150 * KT for v in speeds):
        raise ConfigError(f"{w} [trims]: speeds_kt must lie in 0..150 kt")
    ts = {"col": DEG * float(_get(tr, "sigma_col_deg", w, float, 0.05)),
          "lon": DEG * float(_get(tr, "sigma_lon_deg", w, float, 0.05)),
          "theta": DEG * float(_get(tr, "sigma_theta_deg", w, float, 0.1))} if noise else {}
    to = {"col": DEG * float(_get(tr, "offset_col_deg", w, float, 0.05)),
          "lon": DEG * float(_get(tr, "offset_lon_deg", w, float, 0.05)),
          "theta": DEG * float(_get(tr, "offset_theta_deg", w, float, 0.1))} if noise else {}

    plans = []
    for i, mv in enumerate(_get(raw, "maneuvers", w, list)):
        where = f"{w} [[maneuvers]] #{i + 1}"
        role = _get(mv, "role", where, str)
        if role not in ("identification", "validation"):
            raise ConfigError(f"{where}: role must be identification or validation, got {role!r}")
        plans.append(ManeuverPlan(
            name=_get(mv, "name", where, str), role=role, speed=float(_get(mv, "speed_kt", where, float)) * KT,
            channel=_get(mv, "channel", where, str), shape=_get(mv, "shape", where, str),
            amplitude=float(_get(mv, "amplitude_deg", where, float)) * DEG, step=float(_get(mv, "step_s", where, float)),
            duration=float(_get(mv, "duration_s", where, float)), t_start=float(_get(mv, "t_start_s", where, float, 2.0)),
            ramp=float(_get(mv, "ramp_s", where, float, 0.1))))
    names = [p.name for p in plans]
    if len(set(names)) != len(names):
        raise ConfigError(f"{w} [[maneuvers]]: duplicate maneuver names")
    return GeneratorConfig(name=_get(ds, "name", f"{w} [dataset]", str), aircraft=_get(ds, "aircraft", w, str),
                           description=_get(ds, "description", w, str, ""), seed=int(_get(ds, "seed", w, int)),
                           parameters=params, effects=effects, sensors=sensors, noise=noise, trim_speeds=speeds,
                           trim_sigma=ts, trim_offset=to, maneuvers=plans)
