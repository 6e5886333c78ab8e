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
    weighting = "bins"                       # or "tischler_remple" (below)

``weighting`` (docs/linear.md section 3): "bins" (default) evaluates Eq. 9 at every coherent bin of the
single-window estimates of the identification maneuvers; "tischler_remple" at 20 logarithmically spaced
frequencies of the composite, conditioned responses of the sweep records (role "frequency"), band
coherence >= 0.6, as Tischler and Remple (ch. 11). Both use W_gamma = [1.58 (1 - exp(-gamma^2))]^2,
W_g = 1, W_p = 0.01745.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .dataset.frequency_response import DEFAULT_PAIRS, SpectralSettings
import math

from .units import KT

_OUTPUTS = ("q", "theta", "n_x", "n_z")
_INPUTS = ("col", "lon")
#: most epsilon grid points on J_linear: the front is [pareto] points x this many solves
MAX_POINTS = 50
#: how J_linear weighs frequencies (see the module docstring)
WEIGHTINGS = ("bins", "tischler_remple")


@dataclass
class LinearSettings:
    pairs: tuple = DEFAULT_PAIRS
    speeds: tuple = (0.0, 80.0 * KT)  # [m/s]
    spectral: SpectralSettings = field(default_factory=SpectralSettings)
    points: int = 3
    weighting: str = "bins"  # or "tischler_remple"

    @classmethod
    def from_table(cls, t: dict) -> "LinearSettings":
        known = {"pairs", "speeds_kt", "coherence_min", "input_power_min", "window_s", "overlap",
                 "omega_min_rad_s", "omega_max_rad_s", "points", "weighting"}
        unknown = sorted(set(t) - known)
        if unknown:
            raise ValueError(f"unknown field(s) {unknown}; expected {sorted(known)}")
        pairs = t.get("pairs", [list(p) for p in DEFAULT_PAIRS])
        if not isinstance(pairs, list) or not all(isinstance(p, list) and len(p) == 2 for p in pairs):
            raise ValueError("field 'pairs' must be a list of [output, input] pairs")
        for o, i in pairs:
            if o not in _OUTPUTS:
                raise ValueError(f"field 'pairs': unknown output '{o}'; choose from {', '.join(_OUTPUTS)}")
            if i not in _INPUTS:
                raise ValueError(f"field 'pairs': unknown input '{i}'; choose from {', '.join(_INPUTS)}")
        dup = sorted({tuple(p) for p in pairs if pairs.count(p) > 1})
        if dup:
            raise ValueError(f"field 'pairs' names {[list(p) for p in dup]} more than once")
        speeds = t.get("speeds_kt", [0, 80])
        if not isinstance(speeds, list) or not speeds or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v <= 150 for v in speeds):
            raise ValueError(f"field 'speeds_kt' must be a non-empty list of speeds in 0..150 kt, got {speeds!r}")
        if len(set(speeds)) != len(speeds):
            raise ValueError(f"field 'speeds_kt' names a speed more than once: {speeds}")
        points = t.get("points", 3)
        if not isinstance(points, int) or isinstance(points, bool) or not 2 <= points <= MAX_POINTS:
            raise ValueError(f"field 'points' must be an integer in 2..{MAX_POINTS}, got {points!r}")
        kw = {}
        for key, name in (("coherence_min", "coherence_min"), ("input_power_min", "input_power_min"),
                          ("window_s", "window_s"), ("overlap", "overlap"), ("omega_min_rad_s", "omega_min"),
                          ("omega_max_rad_s", "omega_max")):
            if key in t:
                v = t[key]
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise ValueError(f"field '{key}' must be a finite number, got {v!r}")
                kw[name] = float(v)
        weighting = t.get("weighting", "bins")
        if weighting not in WEIGHTINGS:
            raise ValueError(f"field 'weighting' must be one of {', '.join(WEIGHTINGS)}, got {weighting!r}")
        return cls(pairs=tuple((o, i) for o, i in pairs), speeds=tuple(float(v) * KT for v in speeds),
                   spectral=SpectralSettings(**kw), points=points, weighting=weighting)
