"""The flight-test manifest (``manifest.json`` of a dataset folder; docs/data_format.md), declared once.

The declaration gives the keys the reader accepts and requires (:mod:`pyomo_heli.dataset.reader` takes its key
tables from here) and the JSON Schema of ``pyomo-heli schema manifest``. The reader checks the values itself,
every problem of the folder in one pass, against the data (plausible ranges, files, trim speeds, inputs).
"""
from __future__ import annotations

from typing import Literal, Optional, Union

from pydantic import Field

from ..channels import INPUTS
from .base import Table
from .common import Finite

#: the format's name and version (pyomo_heli.dataset.schema.FORMAT_NAME / FORMAT_VERSION;
#: tests/test_settings.py keeps them equal)
FORMAT_NAME = "pyomo_heli-flighttest"
FORMAT_VERSION = 1


class Atmosphere(Table):
    """``atmosphere``: the day's air."""

    rho_kg_m3: Finite = Field(gt=0, description="air density [kg/m^3]")
    g_m_s2: Finite = Field(gt=0, description="surface gravity [m/s^2]")


class Conventions(Table):
    """``conventions``: how the recorded trim channels relate to the model's (format section 4)."""

    collective_station: Optional[Finite] = Field(None, ge=0, le=1, description="r/R of the blade station the "
                                                                               "recorded collective is the pitch of "
                                                                               "(0: root; default: the model's r_ref)")
    lon_sign: Literal[1, -1] = Field(1, description="1: recorded lon positive aft; -1: positive forward")
    theta_datum_deg: Union[Finite, Literal["estimate"]] = Field(
        0.0, description="recorded pitch attitude minus body-axis attitude [deg] (display unit), within +-15 deg, "
                         "or \"estimate\" when unknown")


class Accuracy(Table):
    """``accuracy``: the stated accuracy of the records."""

    angle_deg: Optional[Finite] = Field(None, ge=0, description="angle accuracy [deg] (display unit)")
    speed_kt: Optional[Finite] = Field(None, ge=0, description="airspeed accuracy [kt] (display unit)")
    description: Optional[str] = Field(None, description="free text")


class ManeuverEntry(Table):
    """An entry of ``maneuvers``: one record."""

    name: str = Field(pattern=r"^[A-Za-z0-9_-]+$", description="record name: letters, digits, '_' and '-'")
    file: str = Field(description="the record's CSV file, '/'-separated, relative to the dataset folder")
    role: Literal["identification", "validation", "frequency"] = Field(description="identification, validation or "
                                                                                   "frequency (sweeps for J_linear)")
    trim_speed_kt: Finite = Field(ge=0, description="trim speed the record starts from [kt] (display unit)")
    inputs: list[Literal[INPUTS]] = Field(min_length=1, description="the input channels the maneuver excites")
    description: Optional[str] = Field(None, description="free text")


class Manifest(Table):
    """``manifest.json`` of a flight-test folder (docs/data_format.md)."""

    format: Literal[FORMAT_NAME] = Field(description="the format's name")
    format_version: Literal[FORMAT_VERSION] = Field(description="the format's version")
    aircraft: str = Field(min_length=1, description="the aircraft")
    description: Optional[str] = Field(None, description="free text")
    atmosphere: Atmosphere = Field(description="the day's air density and gravity")
    mass_kg: Finite = Field(gt=0, description="helicopter mass [kg]")
    trim_file: str = Field(description="the trim table's CSV file, relative to the dataset folder")
    maneuvers: list[ManeuverEntry] = Field(description="the records (empty: a trim-only flight test)")
    conventions: Optional[Conventions] = Field(None, description="trim-channel conventions (default: the format's)")
    source: Optional[str] = Field(None, description="where the data come from")
    accuracy: Optional[Accuracy] = Field(None, description="the stated accuracy")
    assumptions: Optional[list[str]] = Field(None, description="assumptions made in preparing the data, one each")


def key_table(cls: type[Table]) -> dict[str, bool]:
    """key -> required, in declaration order (the reader's key check)."""
    return {name: f.is_required() for name, f in cls.model_fields.items()}
