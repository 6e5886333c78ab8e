"""Shared parameter variables of an NLP, scaled at optimizer level only.

Free parameters become one indexed Var ``theta_s`` of *scaled* values; the
physics sees ``scale * theta_s[name]`` through the mapping returned by
:func:`add_parameters`, so the model equations keep physical units (paper,
Fig. 4). Fixed parameters enter the expressions as plain numbers.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import pyomo.environ as pyo

from ..physics.parameters import ParameterSet


@dataclass(frozen=True)
class FreeParameter:
    """A parameter to identify: initial value, bounds and scale (SI units)."""

    name: str
    initial: float
    lower: float
    upper: float
    scale: float

    def __post_init__(self):
        if not self.lower < self.upper:
            raise ValueError(f"parameter {self.name}: lower bound {self.lower} must be below upper {self.upper}")
        if not self.lower <= self.initial <= self.upper:
            raise ValueError(f"parameter {self.name}: initial value {self.initial} is outside its bounds "
                             f"[{self.lower}, {self.upper}]")
        if not self.scale > 0:
            raise ValueError(f"parameter {self.name}: scale must be positive, got {self.scale}")

    @classmethod
    def from_spec(cls, parameters: ParameterSet, name: str, initial: float | None = None,
                  bounds: tuple[float, float] | None = None, scale: float | None = None) -> "FreeParameter":
        spec = parameters.spec(name)
        lo, hi = bounds if bounds is not None else (spec.bounds or (-1e20, 1e20))
        sc = scale if scale is not None else (spec.scale or max(abs(spec.value), 1.0))
        return cls(name, spec.value if initial is None else initial, lo, hi, sc)


class ParameterMap(Mapping):
    """name -> number (fixed) or Pyomo expression (free); what the physics reads."""

    def __init__(self, values: dict, free: dict | None = None):
        self._values = values
        #: free parameter name -> (its scaled Var, scale): the value is ``scale * var``
        self.free = dict(free or {})

    def __getitem__(self, k):
        return self._values[k]

    def __iter__(self):
        return iter(self._values)

    def __len__(self):
        return len(self._values)


def add_parameters(m: pyo.Block, parameters: ParameterSet, free: list[FreeParameter] = ()) -> ParameterMap:
    """Declare the shared parameter Vars on ``m`` and return the physics mapping."""
    free = list(free)
    parameters.check_names(f.name for f in free)
    names = [f.name for f in free]
    by_name = {f.name: f for f in free}
    m.free_parameters = pyo.Set(initialize=names, ordered=True)
    m.theta_s = pyo.Var(m.free_parameters, initialize=lambda _, n: by_name[n].initial / by_name[n].scale,
                        bounds=lambda _, n: (by_name[n].lower / by_name[n].scale, by_name[n].upper / by_name[n].scale))
    m.theta_scale = pyo.Param(m.free_parameters, initialize=lambda _, n: by_name[n].scale)
    #: the parameters' nominal values (the model's ParameterSpec) [SI]: the scaling's nominals (nlp/scaling.py)
    m.theta_nominal = pyo.Param(m.free_parameters, initialize=lambda _, n: float(parameters[n]))
    values: dict = {k: float(v) for k, v in parameters.items()}
    for n in names:
        values[n] = by_name[n].scale * m.theta_s[n]
    return ParameterMap(values, {n: (m.theta_s[n], by_name[n].scale) for n in names})


def free_parameter_values(m: pyo.Block) -> dict[str, float]:
    """Current physical values of the free parameters."""
    return {n: pyo.value(m.theta_scale[n] * m.theta_s[n]) for n in m.free_parameters}
