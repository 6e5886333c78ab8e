"""The flight-test generator config (``pyomo-heli generate-data``; e.g. data/bo105_synthetic.toml).

Units are in the key names (``_deg``, ``_kt``, ``_s``, ``_hz``, ``_rad_s``); pyomo_heli.flighttest.config
converts them to SI. The rules against the dataset format's plausible ranges, the truth effects and the
input shapes' own checks are the loader's (:func:`pyomo_heli.flighttest.config.load_config`).
"""
from __future__ import annotations

from typing import Literal, Optional

from pydantic import Field, model_validator

from ..channels import INPUTS
from .base import Table
from .common import Finite, sigma_table

#: maneuver roles (pyomo_heli.dataset.schema.ROLES) and input shapes (pyomo_heli.simulation.inputs.SHAPES);
#: tests/test_settings.py keeps them equal
ROLES = ("identification", "validation", "frequency")
SHAPES = ("3211", "doublet", "step", "pulse", "sweep")
#: keys only a frequency sweep takes
SWEEP_KEYS = ("omega_min_rad_s", "omega_max_rad_s", "dwell_cycles", "pilot")


class GenTable(Table):
    """A generator table: messages say "key 'x'"."""

    word = "key"
    unknown_style = "key"


class DatasetTable(GenTable):
    """``[dataset]``: the flight test's name and its random numbers."""

    messages = {"seed": "key 'seed' must be an integer >= 0, got {v!r}",
                "trim_stream": "key 'trim_stream' must be an integer >= 0, got {v!r}"}

    name: str = Field(description="the flight test's name (manifest.json)")
    aircraft: str = Field(description="the aircraft (manifest.json)")
    description: str = Field("", description="free text (manifest.json)")
    seed: int = Field(ge=0, description="seed of every random number (numpy SeedSequence)")
    trim_stream: Optional[int] = Field(None, ge=0, description="SeedSequence child that draws the trim noise "
                                                               "(0..number of maneuvers; default: the child after "
                                                               "the last maneuver)")


class TruthTable(GenTable):
    """``[truth]``: the truth model: nominal Bo-105 with these values and effects."""

    parameters: dict[str, Finite] = Field(default_factory=dict, description="parameter values [SI] replacing "
                                                                            "the nominal table")
    effects: dict[str, dict[str, Finite]] = Field(default_factory=dict, description="truth effects, "
                                                                                    "[truth.effects.<name>] with "
                                                                                    "their parameters [SI]")


SensorSigmaTable = sigma_table("SensorSigmaTable", positive=False, unknown_style="channel",
                               doc="White measurement noise sigma per channel, display units in the key names.")
VibrationTable = sigma_table("VibrationTable", positive=False, unknown_style="channel",
                             doc="Rotor-harmonic vibration amplitude per channel, display units in the key names.")


class SensorsTable(GenTable):
    """``[sensors]``: simulation and recording rates and the sensor noise."""

    noise: bool = Field(True, description="add sensor noise, vibration and trim scatter")
    sim_rate_hz: Finite = Field(400.0, gt=0, description="simulation rate [Hz]")
    record_rate_hz: Finite = Field(50.0, gt=0, description="recorded sample rate [Hz]")
    antialias_hz: Finite = Field(10.0, gt=0, description="anti-alias filter corner [Hz]")
    sigma: SensorSigmaTable = Field(default_factory=SensorSigmaTable,
                                    description="noise sigmas replacing the defaults (model_spec.md section 5)")
    vibration: VibrationTable = Field(default_factory=VibrationTable,
                                      description="vibration amplitudes replacing the defaults")
    tas_sigma_low_speed_m_s: Finite = Field(1.0, ge=0, description="extra airspeed noise at low speed [m/s]")


class TrimsTable(GenTable):
    """``[trims]``: the measured trim points."""

    speeds_kt: list[Finite] = Field(description="trim speeds [kt] (display unit), within the dataset format's "
                                                "model speed range")
    sigma_col_deg: Finite = Field(0.05, ge=0, description="averaging noise of the collective [deg]")
    sigma_lon_deg: Finite = Field(0.05, ge=0, description="averaging noise of the longitudinal cyclic [deg]")
    sigma_theta_deg: Finite = Field(0.1, ge=0, description="averaging noise of the pitch attitude [deg]")
    offset_col_deg: Finite = Field(0.05, ge=0, description="not-quite-steady offset sigma, collective [deg]")
    offset_lon_deg: Finite = Field(0.05, ge=0, description="not-quite-steady offset sigma, longitudinal [deg]")
    offset_theta_deg: Finite = Field(0.1, ge=0, description="not-quite-steady offset sigma, pitch attitude [deg]")


class ManeuverTable(GenTable):
    """``[[maneuvers]]``: one recorded maneuver."""

    messages = {"role": (None, "role must be identification or validation, got {v!r}"),
                "channel": (None, "key 'channel' must be one of " + ", ".join(INPUTS) + ", got {v!r}"),
                "shape": (None, "key 'shape' must be one of " + ", ".join(SHAPES) + ", got {v!r}"),
                "dwell_cycles": "key 'dwell_cycles' must be an integer >= 0, got {v!r}"}

    name: str = Field(description="record name: letters, digits, '_' and '-'")
    role: Literal[ROLES] = Field(description="identification, validation or frequency (sweeps for J_linear)")
    speed_kt: Finite = Field(description="trim speed [kt] (display unit)")
    channel: Literal[INPUTS] = Field(description="the input excited")
    shape: Literal[SHAPES] = Field(description="the input shape")
    amplitude_deg: Finite = Field(description="input amplitude [deg] (display unit), not 0")
    step_s: Finite = Field(gt=0, description="step length [s] (sweep: the whole sweep's length)")
    duration_s: Finite = Field(gt=0, description="record length [s]")
    t_start_s: Finite = Field(2.0, ge=0, description="input start [s], before duration_s")
    ramp_s: Finite = Field(0.1, ge=0, description="ramp time of each input step [s]")
    omega_min_rad_s: Optional[Finite] = Field(None, gt=0, description="sweep only: lowest frequency [rad/s] "
                                                                      "(default 0.3)")
    omega_max_rad_s: Optional[Finite] = Field(None, gt=0, description="sweep only: highest frequency [rad/s] "
                                                                      "(default 20)")
    dwell_cycles: Optional[int] = Field(None, ge=0, description="sweep only: cycles dwelt at omega_min "
                                                                "(default 2)")
    pilot: Optional[bool] = Field(None, description="sweep only: flown with the pilot holding the attitude "
                                                    "(flighttest/pilot.py; default true)")

    @model_validator(mode="after")
    def _sweep_keys(self):
        from .base import fail

        if self.shape != "sweep":
            given = [k for k in SWEEP_KEYS if getattr(self, k) is not None]
            if given:
                fail(None, "\n".join(f"key '{k}' applies only to shape 'sweep', not {self.shape!r}" for k in given))
        return self


class GeneratorFile(GenTable):
    """A flight-test generator config: the tables of a TOML file read by ``pyomo-heli generate-data``."""

    dataset: DatasetTable
    truth: TruthTable = Field(default_factory=TruthTable)
    sensors: SensorsTable = Field(default_factory=SensorsTable)
    trims: TrimsTable
    maneuvers: list[ManeuverTable] = Field(description="the maneuvers, one [[maneuvers]] table each")
