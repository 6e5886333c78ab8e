"""The [linear] table of an identification config: which frequency responses J_linear uses.

Example (studies/case1_tri.toml):

    [objectives]
    use = ["time", "trim", "linear"]

    [linear]
    pairs = [["q", "lon"], ["n_z", "col"]]   # (output, input)
    speeds_kt = [0, 80]                      # flight conditions (maneuver trim speeds)
    coherence_min = 0.9                      # coherent band: coherence at least this ...
    input_power_min = 0.2                    # ... and input autospectrum at least this of its peak
    window_s = 5.12                          # Welch segment length
    omega_min_rad_s = 0.9
    omega_max_rad_s = 20.0
    points = 3                               # epsilon grid points on J_linear (the front is points x this)
    weighting = "bins"                       # or "tischler_remple": composite responses of the sweep records
    # with "tischler_remple", the composite estimator's sweep_* keys (unset: SWEEP_SETTINGS, TR_POINTS) in place of
    # the Welch keys above (a key the weighting does not read is an error), e.g. studies/case1_tri.toml:
    #   sweep_windows_s = [5, 10, 20, 30, 45, 60]
    #   sweep_min_periods = 4
    #   sweep_points = 20                    # cost frequencies per response

The table is declared (fields, defaults, domains) in :class:`pyomo_heli.settings.identification.LinearTable`.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from .dataset.frequency_response import DEFAULT_PAIRS, SWEEP_SETTINGS, TR_POINTS, CompositeSettings, SpectralSettings
from .settings import Problems, validate
from .settings.identification import MAX_LINEAR_POINTS as MAX_POINTS  # noqa: F401 - re-exported
from .settings.identification import LinearTable
from .units import KT

#: [linear] key -> SpectralSettings field
_SPECTRAL = (("coherence_min", "coherence_min"), ("input_power_min", "input_power_min"), ("window_s", "window_s"),
             ("overlap", "overlap"), ("omega_min_rad_s", "omega_min"), ("omega_max_rad_s", "omega_max"))
#: [linear] key -> CompositeSettings field (the sweep records' estimator)
_COMPOSITE = (("sweep_min_periods", "min_periods"), ("sweep_record_periods", "record_periods"),
              ("sweep_overlap", "overlap"), ("sweep_coherence_min", "coherence_min"),
              ("sweep_omega_min_rad_s", "omega_min"), ("sweep_omega_max_rad_s", "omega_max"),
              ("sweep_max_window_fraction", "max_window_fraction"), ("sweep_coherence_span", "coherence_span"))


@dataclass
class LinearSettings:
    pairs: tuple = DEFAULT_PAIRS
    speeds: tuple = (0.0, 80.0 * KT)  # [m/s]
    spectral: SpectralSettings = field(default_factory=SpectralSettings)
    points: int = 3
    weighting: str = "bins"  # or "tischler_remple" (docs/linear.md section 3)
    composite: CompositeSettings = field(default_factory=lambda: SWEEP_SETTINGS)  # "tischler_remple": the estimator
    sweep_points: int = TR_POINTS  # "tischler_remple": cost frequencies per response

    @classmethod
    def from_table(cls, t: "dict | LinearTable") -> "LinearSettings":
        """From the [linear] table (a dict, checked here: ValueError with the errors, or its checked model)."""
        if not isinstance(t, LinearTable):
            problems = Problems("[linear]", ValueError)
            t = validate(LinearTable, t, problems)
            if problems:
                raise ValueError("; ".join(line.removeprefix("[linear]: ") for line in problems.lines))
        kw = {name: float(getattr(t, key)) for key, name in _SPECTRAL if getattr(t, key) is not None}
        ckw = {name: float(getattr(t, key)) for key, name in _COMPOSITE if getattr(t, key) is not None}
        if t.sweep_windows_s is not None:
            ckw["windows_s"] = tuple(float(w) for w in t.sweep_windows_s)
        if t.sweep_n_omega is not None:
            ckw["n_omega"] = int(t.sweep_n_omega)
        try:
            composite = dataclasses.replace(SWEEP_SETTINGS, **ckw)
        except ValueError as exc:
            raise ValueError(f"sweep_*: {exc}") from None
        return cls(pairs=tuple((o, i) for o, i in t.pairs), speeds=tuple(float(v) * KT for v in t.speeds_kt),
                   spectral=SpectralSettings(**kw), points=t.points, weighting=t.weighting, composite=composite,
                   sweep_points=int(t.sweep_points) if t.sweep_points is not None else TR_POINTS)
