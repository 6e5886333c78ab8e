"""Tables more than one config kind uses: a free parameter, the noise sigmas, the solver, a list of names."""
from __future__ import annotations

from typing import Annotated, Any, Literal, Optional

from pydantic import AfterValidator, Field, ValidationInfo, create_model

from ..units import SENSOR_SIGMA_KEYS
from .base import Table, names_check

#: the solvers a config can name (pyomo_heli.solvers.SOLVER_NAMES; tests/test_settings.py keeps them equal)
SOLVER_NAMES = ("casadi-ipopt", "pounce", "ipopt")
#: largest noise sigma [SI: rad, rad/s, g, m/s] a config may give: no sensor is that poor; larger is a unit slip
SIGMA_MAX_SI = 10.0

Finite = Annotated[float, Field(allow_inf_nan=False)]


def Names(choices=None, *, allow_empty: bool = False, unknown: str | None = None, what: str = "name",
          empty: str | None = None):
    """The type of a list of distinct names (each of ``choices`` if given; empty only with ``allow_empty``)."""
    schema: dict[str, Any] = {"uniqueItems": True}
    if choices is not None:
        schema["items"] = {"type": "string", "enum": list(choices)}
    if not allow_empty:
        schema["minItems"] = 1

    def check(v: list, info: ValidationInfo) -> list:
        return names_check(v, info, choices=choices, what=what, allow_empty=allow_empty, unknown=unknown,
                           empty=empty)

    return Annotated[list[str], AfterValidator(check), Field(json_schema_extra=schema)]


class ParameterTable(Table):
    """``[parameters.<name>]``: one free parameter of the fit. Values in ``unit``; a field left out takes the
    parameter's own value, bounds or scale (docs/model_parameters.md)."""

    messages = {"": "must be a table with initial, lower, upper, scale, unit",
                "scale": (None, "field 'scale' must be a number > 0, got {v!r}")}
    number_words = "a finite number"

    initial: Optional[Finite] = Field(None, description="start value, in `unit` (default: the nominal value)")
    lower: Optional[Finite] = Field(None, description="lower bound, in `unit` (default: the parameter's range)")
    upper: Optional[Finite] = Field(None, description="upper bound, in `unit` (default: the parameter's range)")
    scale: Optional[Finite] = Field(None, gt=0, description="typical magnitude, in `unit`, > 0: the NLP variable "
                                                            "is value / scale (default: the parameter's scale)")
    unit: Optional[str] = Field(None, description="the unit of the numbers above: the parameter's SI unit (or "
                                                  "\"SI\") or its display unit, e.g. deg/m for theta_twist")


def _sigma_desc(key: str) -> str:
    channel, factor = SENSOR_SIGMA_KEYS[key]
    unit = {"q_deg_s": "deg/s", "theta_deg": "deg", "nx_g": "g", "nz_g": "g", "tas_m_s": "m/s",
            "beta0_deg": "deg", "col_deg": "deg", "lon_deg": "deg"}.get(key, "SI")
    return f"noise sigma of {channel} [{unit}] (display unit in the key; read as SI x {factor:.6g})"


def sigma_table(name: str, *, positive: bool, doc: str, unknown_style: str = "key-use", messages=None,
                validators=None):
    """A table of one optional noise number per sensor key (display units in the key names)."""
    fields = {k: (Optional[Finite], Field(None, **({"gt": 0} if positive else {"ge": 0}), description=_sigma_desc(k)))
              for k in SENSOR_SIGMA_KEYS}
    model = create_model(name, __base__=Table, __doc__=doc, __validators__=validators, __module__=__name__,
                         **fields)
    model.unknown_style = unknown_style
    if messages is not None:
        model.messages = messages
    return model


class SolverTable(Table):
    """``[solver]``: the NLP solver and its options."""

    messages = {"name": (None, "field 'name': unknown solver {v!r}; choose from " + ", ".join(SOLVER_NAMES))}

    name: Literal[SOLVER_NAMES] = Field("casadi-ipopt", description="the NLP solver")
    options: dict[str, Any] = Field(default_factory=dict, description="solver options (Ipopt's), checked against "
                                                                      "the solver's own list when the file is read")


#: the terms a model parameter table [model.parameters] takes: a parameter name -> its value in SI
ParameterValues = Annotated[dict[str, Any], Field(json_schema_extra={"additionalProperties": {"type": "number"}})]
