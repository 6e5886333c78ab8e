"""The parameter table of the identification model M0 (Bo-105, sea level).

Every constant the physics uses lives here, with its SI unit, nominal value,
source and a default identification range/scale. Sources are abbreviated:

- ``Padfield``: G. D. Padfield, *Helicopter Flight Dynamics*, 2nd ed. 2007,
  Appendix 4B (Bo-105 data set).
- ``paper``: the multi-objective PID paper, Tables 2-3 ("actual Bo-105").
- ``TUD``: TU Delft teaching/6-DoF Bo-105 model lineage (lecture code).
- ``ISA``: International Standard Atmosphere, sea level.
- ``choice``: a modelling choice of this project, see docs/model_parameters.md.

Values tagged ``[L]`` in model_spec.md are engineering guesses; they are fixed,
never identified by default.

Units are SI and radians inside the package. ``theta_twist`` is the paper's
parameter in rad/m (the paper prints deg/m; convert at the edges only).
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, replace
from typing import Iterable, Mapping

from ..units import DEG


@dataclass(frozen=True)
class ParameterSpec:
    """One named model parameter.

    ``bounds`` and ``scale`` are the defaults used when the parameter is
    declared free in an identification; ``display`` gives (unit, factor) used
    to print the value at the edges (value * factor). ``domain`` is what the
    physics needs of any value: "positive" (> 0), "nonnegative" (>= 0),
    "fraction" (0 <= x <= 1), "time_constant" (>= 1 ms) or None (any finite number).
    """

    name: str
    value: float
    unit: str
    description: str
    source: str
    bounds: tuple[float, float] | None = None
    scale: float | None = None
    display: tuple[str, float] | None = None
    domain: str | None = None

    def check(self, value) -> float:
        """``value`` as a float, or a ValueError naming the parameter when the physics cannot take it."""
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise ValueError(f"parameter {self.name}: value must be a number [{self.unit}], got {value!r}")
        v = float(value)
        need = DOMAINS[self.domain]
        if not math.isfinite(v) or not need[0](v):
            raise ValueError(f"parameter {self.name}: value must be {need[1]} [{self.unit}], got {value!r}")
        return v

    def shown(self) -> tuple[float, str]:
        """Value and unit as printed at the edges (e.g. deg/m for twist)."""
        if self.display is None:
            return self.value, self.unit
        unit, factor = self.display
        return self.value * factor, unit



#: domain name -> (test, wording) for ParameterSpec.domain
DOMAINS = {
    None: (lambda v: True, "a finite number"),
    "positive": (lambda v: v > 0, "a finite number > 0"),
    "nonnegative": (lambda v: v >= 0, "a finite number >= 0"),
    "fraction": (lambda v: 0 <= v <= 1, "a number in [0, 1]"),
    # a time constant of a state the explicit simulator integrates: below 1 ms (a hundredth of a rotor
    # revolution) the equation is so stiff that a record takes hours (1e-6 s did not finish in 30 s)
    "time_constant": (lambda v: v >= 1e-3, "a finite number >= 0.001 (1 ms)"),
}

_BO105: tuple[ParameterSpec, ...] = (
    # --- mass and inertia
    ParameterSpec("m", 2200.0, "kg", "helicopter mass", "Padfield; TUD", (1500.0, 2600.0), 2200.0,
                  domain="positive"),
    ParameterSpec("Iyy", 4973.0, "kg m^2", "pitch moment of inertia", "Padfield; paper Table 3",
                  (2000.0, 8000.0), 5000.0, domain="positive"),
    # --- atmosphere
    ParameterSpec("g", 9.81, "m/s^2", "gravity", "ISA", domain="positive"),
    ParameterSpec("rho", 1.225, "kg/m^3", "air density", "ISA sea level", domain="positive"),
    # --- main rotor
    ParameterSpec("R", 4.912, "m", "rotor radius", "TUD (Padfield 4.91)", domain="positive"),
    ParameterSpec("Omega", 44.4, "rad/s", "rotor speed (424 rpm)", "Padfield; TUD", domain="positive"),
    ParameterSpec("Nb", 4.0, "-", "number of blades", "Padfield", domain="positive"),
    ParameterSpec("c", 0.27, "m", "blade chord", "Padfield; TUD", domain="positive"),
    ParameterSpec("a", 6.113, "1/rad", "blade lift-curve slope", "Padfield (NACA 23012)", (4.0, 7.0), 6.0,
                  domain="positive"),
    ParameterSpec("I_beta", 231.7, "kg m^2", "blade flap inertia", "Padfield; TUD", domain="positive"),
    ParameterSpec("K_beta", 113330.0, "N m/rad", "centre-spring equivalent hub stiffness",
                  "Padfield; TUD", (0.0, 2.0e5), 1.0e5, domain="nonnegative"),
    ParameterSpec("beta_p", 2.5 * DEG, "rad", "precone", "Bo-105 descriptions [L]",
                  display=("deg", 1 / DEG)),
    ParameterSpec("theta_twist", -1.6329 * DEG, "rad/m", "linear blade twist per metre of span",
                  "paper Table 2 (-0.14 rad over R, Padfield)", (-10.0 * DEG, 0.0), 1.0 * DEG,
                  display=("deg/m", 1 / DEG)),
    ParameterSpec("r_ref", 0.7, "-", "radial station where collective is measured",
                  "GARTEUR AG-06 control ranges via TUD [M]", domain="fraction"),
    ParameterSpec("gamma_s", 3.0 * DEG, "rad", "forward shaft tilt", "Padfield; TUD",
                  display=("deg", 1 / DEG)),
    ParameterSpec("x_h", 0.08, "m", "hub position forward of the CG", "Padfield; TUD", (-0.3, 0.3), 0.1),
    ParameterSpec("h", 1.48, "m", "hub height above the CG", "Padfield; TUD"),
    ParameterSpec("tau_lambda", 0.1, "s", "inflow time constant", "TUD lecture code", (0.005, 0.5), 0.1,
                  domain="time_constant"),
    # --- fuselage
    ParameterSpec("f_e", 0.95, "m^2", "equivalent flat-plate drag area", "TUD code (1.3*0.73) [L]",
                  (0.3, 3.0), 1.0, domain="nonnegative"),
    ParameterSpec("KfVf", 5.08, "m^3", "Munk moment factor times fuselage volume",
                  "TUD code (0.83*pi/4*6*1.3) [L]", (0.0, 15.0), 5.0),
    ParameterSpec("eps_v", 0.1, "m/s", "airspeed regulariser keeping derivatives finite in hover",
                  "choice", domain="positive"),
    # --- horizontal tail
    ParameterSpec("S_t", 0.803, "m^2", "horizontal tail area", "Padfield; TUD", domain="nonnegative"),
    ParameterSpec("l_t", 4.64, "m", "tail aerodynamic centre aft of the CG", "TUD (Padfield ~4.56)"),
    ParameterSpec("alpha_t0", 4.0 * DEG, "rad", "tail incidence (leading edge up)", "TUD code [L]",
                  (-5 * DEG, 10 * DEG), 1 * DEG, display=("deg", 1 / DEG)),
    ParameterSpec("CL_alpha_HT", 6.2166, "1/rad", "horizontal tail lift-curve slope",
                  "paper Table 2 'actual Bo-105'", (0.1, 10.0), 5.0),
    ParameterSpec("eta_t", 1.0, "-", "tail dynamic-pressure ratio", "choice (not separable from CL_alpha_HT)",
                  domain="nonnegative"),
)


class ParameterSet(Mapping[str, float]):
    """An ordered, immutable-by-convention table of parameter values.

    Behaves as a read-only mapping name -> value. ``with_values`` returns a
    copy with some values changed and rejects unknown names, so that a typo in
    a config is an error, not a silently ignored setting.
    """

    def __init__(self, specs: Iterable[ParameterSpec]):
        self._specs: dict[str, ParameterSpec] = {}
        for s in specs:
            if s.name in self._specs:
                raise ValueError(f"duplicate parameter name {s.name!r}")
            self._specs[s.name] = s

    # Mapping protocol -------------------------------------------------
    def __getitem__(self, name: str) -> float:
        try:
            return self._specs[name].value
        except KeyError:
            raise KeyError(self._unknown(name)) from None

    def __iter__(self):
        return iter(self._specs)

    def __len__(self) -> int:
        return len(self._specs)

    # ------------------------------------------------------------------
    def _unknown(self, name: str) -> str:
        import difflib

        close = difflib.get_close_matches(name, list(self._specs), n=3)
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        return f"unknown parameter name {name!r}{hint}"

    def spec(self, name: str) -> ParameterSpec:
        if name not in self._specs:
            raise KeyError(self._unknown(name))
        return self._specs[name]

    def specs(self) -> list[ParameterSpec]:
        return list(self._specs.values())

    def check_names(self, names: Iterable[str]) -> None:
        for n in names:
            if n not in self._specs:
                raise KeyError(self._unknown(n))

    def with_values(self, **values: float) -> "ParameterSet":
        """A copy with some values changed; unknown names and values outside a parameter's domain
        (a negative mass, a NaN, ...) raise KeyError and ValueError naming the parameter."""
        self.check_names(values)
        return ParameterSet(
            replace(s, value=s.check(values[s.name])) if s.name in values else s for s in self.specs()
        )

    def extended(self, specs: Iterable[ParameterSpec]) -> "ParameterSet":
        """A copy with more parameters (e.g. those of model extensions) appended."""
        new = [s for s in specs if s.name not in self._specs]
        return ParameterSet(self.specs() + new)

    def without(self, names: Iterable[str]) -> "ParameterSet":
        """A copy without the parameters ``names`` (those of a model extension taken out); unknown names raise
        KeyError."""
        names = set(names)
        self.check_names(names)
        return ParameterSet(s for s in self.specs() if s.name not in names)

    def to_dict(self) -> dict[str, float]:
        return {k: s.value for k, s in self._specs.items()}

    def table(self) -> str:
        rows = [f"{'name':<12} {'value':>12} {'unit':<8} {'shown':>14}  source"]
        for s in self._specs.values():
            v, u = s.shown()
            rows.append(f"{s.name:<12} {s.value:>12.6g} {s.unit:<8} {v:>9.5g} {u:<4}  {s.source}")
        return "\n".join(rows)

    def __repr__(self) -> str:
        return f"ParameterSet({len(self)} parameters)"


def bo105() -> ParameterSet:
    """Nominal Bo-105 parameter set of M0 (model_spec.md section 2)."""
    return ParameterSet(_BO105)


def teaching_model() -> ParameterSet:
    """The degenerate TU Delft teaching helicopter (model_spec.md section 1.11).

    The teaching model is specified by V_tip, R, solidity sigma and Lock number
    gamma; chord and flap inertia are back-computed so that M0's formulas
    reproduce them. Hub spring, shaft tilt, hub offset, precone, twist, tail
    and fuselage moment are switched off, and collective is referred to the
    root (r_ref = 0) as in the teaching equations.
    """
    R, v_tip, sigma, a, lock, rho, nb = 7.32, 200.0, 0.075, 5.7, 6.0, 1.225, 4.0
    c = sigma * math.pi * R / nb
    i_beta = rho * a * c * R**4 / lock
    return bo105().with_values(
        m=2200.0, Iyy=10615.0, R=R, Omega=v_tip / R, Nb=nb, c=c, a=a, I_beta=i_beta,
        K_beta=0.0, beta_p=0.0, theta_twist=0.0, r_ref=0.0, gamma_s=0.0, x_h=0.0, h=1.0,
        tau_lambda=0.1, f_e=1.5, KfVf=0.0, S_t=0.0, rho=rho, g=9.81,
    )
