"""Pilot input shapes (increments on trim) and their command-line syntax.

A multistep shape is a piecewise-constant sequence of pulses; edges can be
smoothed by a linear ramp of ``ramp`` seconds (real pilots do not make ideal
steps, and collocation prefers continuous inputs).

``sweep`` is a logarithmic frequency sweep (Tischler and Remple, *Aircraft
and Rotorcraft System Identification*, 2nd ed., sec. 5.9, automated sweep):
a dwell of ``dwell`` whole cycles at omega_min, then

    delta(t) = A sin(theta(t)),  dtheta/dt = omega(t)  [rad/s]
    omega(t) = omega_min + K(t) (omega_max - omega_min)
    K(t) = C2 (exp(C1 t / T_s) - 1),  C1 = 4.0, C2 = 0.0187  (K(T_s) = 1.002)

over the sweep time T_s = T - dwell * 2 pi / omega_min, with T the whole
length (``step`` for this shape). The record is cut at the last zero of the
sine before T, so the input starts and ends at zero with no jump.
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
    "sweep": None,  # logarithmic frequency sweep (InputSignal.sweep_phase), not a pulse pattern
}
#: Tischler-Remple constants of the exponential frequency law
SWEEP_C1, SWEEP_C2 = 4.0, 0.0187
CHANNELS = ("col", "lon")


class InputSpecError(ValueError):
    """A malformed input specification (names the offending part)."""


@dataclass(frozen=True)
class InputSignal:
    """One input channel: a shape applied from ``t_start`` [s].

    amplitude [rad], step [s], ramp [s] (linear edge duration, 0 for steps).
    For ``shape="sweep"``: ``step`` is the whole sweep length T [s] (dwell
    included), omega_min/omega_max [rad/s] its frequency range and ``dwell``
    the whole cycles at omega_min before the sweep; ``ramp`` is unused.
    """

    channel: str
    shape: str
    amplitude: float
    step: float
    t_start: float = 1.0
    ramp: float = 0.0
    omega_min: float = 0.3
    omega_max: float = 20.0
    dwell: int = 2

    def __post_init__(self):
        if self.channel not in CHANNELS:
            raise InputSpecError(f"unknown input channel {self.channel!r}; choose one of {', '.join(CHANNELS)}")
        if self.shape not in SHAPES:
            raise InputSpecError(f"unknown input shape {self.shape!r}; choose one of {', '.join(SHAPES)}")
        if not (self.step > 0 and math.isfinite(self.step)):
            raise InputSpecError(f"input step length must be positive, got {self.step}")
        if not math.isfinite(self.amplitude):
            raise InputSpecError(f"input amplitude must be finite, got {self.amplitude}")
        if self.shape == "sweep":
            if not (0 < self.omega_min < self.omega_max and math.isfinite(self.omega_max)):
                raise InputSpecError(f"sweep frequencies must satisfy 0 < omega_min < omega_max, got "
                                     f"{self.omega_min:g}, {self.omega_max:g} rad/s")
            if isinstance(self.dwell, bool) or not isinstance(self.dwell, int) or self.dwell < 0:
                raise InputSpecError(f"sweep dwell must be a whole number of cycles >= 0, got {self.dwell!r}")
            need = self.dwell_time + 2 * math.pi / self.omega_min
            if self.step < need:
                raise InputSpecError(f"sweep length {self.step:g} s is too short: the {self.dwell}-cycle dwell at "
                                     f"{self.omega_min:g} rad/s and one more period take {need:.3g} s")

    @property
    def dwell_time(self) -> float:
        """Length of the low-frequency dwell of a sweep [s]."""
        return self.dwell * 2 * math.pi / self.omega_min

    def sweep_phase(self, tau):
        """Phase theta [rad] of the sweep at time ``tau`` [s] after its start (dwell, then exponential law)."""
        tau = np.asarray(tau, dtype=float)
        td, ts = self.dwell_time, self.step - self.dwell_time
        s = np.clip(tau - td, 0.0, None)
        # integral of omega_min + C2 (exp(C1 s / T_s) - 1)(omega_max - omega_min) ds
        sweep = self.omega_min * s + (self.omega_max - self.omega_min) * SWEEP_C2 * (
            ts / SWEEP_C1 * np.expm1(SWEEP_C1 * s / ts) - s)
        return np.where(tau < td, self.omega_min * tau, self.omega_min * td + sweep)

    def sweep_frequency(self, tau):
        """Instantaneous frequency omega [rad/s] of the sweep at ``tau`` [s] after its start."""
        tau = np.asarray(tau, dtype=float)
        td, ts = self.dwell_time, self.step - self.dwell_time
        k = SWEEP_C2 * np.expm1(SWEEP_C1 * np.clip(tau - td, 0.0, None) / ts)
        return self.omega_min + k * (self.omega_max - self.omega_min)

    @property
    def sweep_end(self) -> float:
        """Length of the applied sweep [s]: the last zero of sin(theta) at or before ``step``."""
        theta_end = float(self.sweep_phase(self.step))
        target = math.floor(theta_end / math.pi + 1e-12) * math.pi
        lo, hi = 0.0, self.step  # theta is increasing: bisect theta(tau) = target
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            if self.sweep_phase(mid) < target:
                lo = mid
            else:
                hi = mid
        return hi

    def breakpoints(self) -> tuple[np.ndarray, np.ndarray]:
        """Edge times and the levels after each edge (multistep shapes)."""
        if self.shape == "sweep":
            raise InputSpecError("a sweep has no edges; evaluate the signal instead")
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
        if self.shape == "sweep":
            tau = t - self.t_start
            on = (tau >= 0) & (tau <= self.sweep_end)
            out = np.where(on, self.amplitude * np.sin(self.sweep_phase(np.clip(tau, 0.0, None))), 0.0)
            return out if out.ndim else float(out)
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


SWEEP_SYNTAX = "CHANNEL:sweep:AMPLITUDE_DEG:LENGTH_S[:OMEGA_MIN_RAD_S:OMEGA_MAX_RAD_S[:DWELL_CYCLES]]"


def parse_input(text: str, t_start: float = 1.0, ramp: float = 0.1) -> InputSignal:
    """Parse ``CHANNEL:SHAPE:AMPLITUDE_DEG:STEP_S``, e.g. ``lon:3211:0.5:0.5``.

    A sweep reads ``CHANNEL:sweep:AMPLITUDE_DEG:LENGTH_S[:OMEGA_MIN:OMEGA_MAX[:DWELL_CYCLES]]``
    (frequencies in rad/s, defaults 0.3, 20 and 2 cycles), e.g. ``lon:sweep:0.5:90:0.3:20``.
    """
    parts = text.split(":")
    is_sweep = len(parts) >= 2 and parts[1] == "sweep"
    if is_sweep and len(parts) not in (4, 6, 7):
        raise InputSpecError(f"input {text!r} must read {SWEEP_SYNTAX}, e.g. lon:sweep:0.5:90:0.3:20")
    if not is_sweep and len(parts) != 4:
        raise InputSpecError(f"input {text!r} must read CHANNEL:SHAPE:AMPLITUDE_DEG:STEP_S, e.g. lon:3211:0.5:0.5")
    channel, shape, amp, step = parts[:4]
    try:
        amp_deg, step_s = float(amp), float(step)
        extra = [float(x) for x in parts[4:6]]
    except ValueError:
        raise InputSpecError(f"input {text!r}: amplitude, step (length) and frequencies must be numbers") from None
    kw = {}
    if is_sweep:
        if extra:
            kw["omega_min"], kw["omega_max"] = extra
        if len(parts) == 7:
            try:
                kw["dwell"] = int(parts[6])
            except ValueError:
                raise InputSpecError(f"input {text!r}: DWELL_CYCLES must be a whole number") from None
    return InputSignal(channel, shape, math.radians(amp_deg), step_s, t_start=t_start, ramp=ramp, **kw)
