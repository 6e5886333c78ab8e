"""Pilot input shapes (increments on trim) and their command-line syntax.

A shape is a piecewise-constant sequence of pulses; edges can be smoothed by a
linear ramp of ``ramp`` seconds (real pilots do not make ideal steps, and
collocation prefers continuous inputs).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: pulse pattern (multiples of the step length, signs) of each named shape
SHAPES = {
    "3211": [(3, +1), (2, -1), (1, +1), (1, -1)],
    "doublet": [(1, +1), (1, -1)],
    "step": [(1e9, +1)],
    "pulse": [(1, +1)],
}
CHANNELS = ("col", "lon")


class InputSpecError(ValueError):
    """A malformed input specification (names the offending part)."""


@dataclass(frozen=True)
class InputSignal:
    """One input channel: a multistep shape applied from ``t_start`` [s].

    amplitude [rad], step [s], ramp [s] (linear edge duration, 0 for steps).
    """

    channel: str
    shape: str
    amplitude: float
    step: float
    t_start: float = 1.0
    ramp: float = 0.0

    def __post_init__(self):
        if self.channel not in CHANNELS:
            raise InputSpecError(f"unknown input channel {self.channel!r}; choose one of {', '.join(CHANNELS)}")
        if self.shape not in SHAPES:
            raise InputSpecError(f"unknown input shape {self.shape!r}; choose one of {', '.join(SHAPES)}")
        if not (self.step > 0 and math.isfinite(self.step)):
            raise InputSpecError(f"input step length must be positive, got {self.step}")
        if not math.isfinite(self.amplitude):
            raise InputSpecError(f"input amplitude must be finite, got {self.amplitude}")

    def breakpoints(self) -> tuple[np.ndarray, np.ndarray]:
        """Edge times and the levels after each edge."""
        t, times, levels = self.t_start, [], []
        for n, sign in SHAPES[self.shape]:
            times.append(t)
            levels.append(sign * self.amplitude)
            t += n * self.step
        times.append(t)
        levels.append(0.0)
        return np.array(times), np.array(levels)

    def __call__(self, t):
        """Increment at time(s) t [rad]."""
        t = np.asarray(t, dtype=float)
        times, levels = self.breakpoints()
        out = np.zeros_like(t)
        prev = 0.0
        for te, lv in zip(times, levels):
            if self.ramp > 0:
                frac = np.clip((t - te) / self.ramp, 0.0, 1.0)
            else:
                frac = (t >= te).astype(float)
            out = out + (lv - prev) * frac
            prev = lv
        return out if out.ndim else float(out)


def parse_input(text: str, t_start: float = 1.0, ramp: float = 0.1) -> InputSignal:
    """Parse ``CHANNEL:SHAPE:AMPLITUDE_DEG:STEP_S``, e.g. ``lon:3211:0.5:0.5``."""
    parts = text.split(":")
    if len(parts) != 4:
        raise InputSpecError(f"input {text!r} must read CHANNEL:SHAPE:AMPLITUDE_DEG:STEP_S, e.g. lon:3211:0.5:0.5")
    channel, shape, amp, step = parts
    try:
        amp_deg, step_s = float(amp), float(step)
    except ValueError:
        raise InputSpecError(f"input {text!r}: amplitude and step must be numbers") from None
    return InputSignal(channel, shape, math.radians(amp_deg), step_s, t_start=t_start, ramp=ramp)
