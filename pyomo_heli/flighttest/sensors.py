"""Sensor model of the synthetic flight test (model_spec.md section 5).

The truth is integrated at a high rate; each channel gets 4/rev vibration
and broadband noise at that rate, passes a 2nd-order Butterworth anti-alias
filter and is decimated to the recording rate. The filter is applied
forward and backward (zero phase), as flight-test processing does when the
filter is known, so the sensors add noise but no lag (lag is a separate,
optional effect). The broadband noise is scaled so that the *recorded*
noise has the configured standard deviation.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from ..units import DEG

#: recorded white-noise sigma per channel, SI units (model_spec section 5)
DEFAULT_SIGMA = {"q": 0.2 * DEG, "theta": 0.1 * DEG, "n_x": 0.005, "n_z": 0.01, "TAS": 0.5,
                 "beta_0": 0.05 * DEG, "col": 0.02 * DEG, "lon": 0.02 * DEG}
#: 4/rev vibration amplitude before filtering, SI units
DEFAULT_VIBRATION = {"q": 0.2 * DEG, "n_x": 0.04, "n_z": 0.04}


@dataclass
class SensorConfig:
    """Sampling, filtering and noise of the recorded channels (SI units)."""

    sim_rate: float = 400.0  # Hz, truth integration/output rate
    record_rate: float = 50.0  # Hz
    antialias_hz: float = 10.0
    vibration_hz: float = 4 * 44.4 / (2 * np.pi)  # 4/rev of the Bo-105
    sigma: dict = field(default_factory=lambda: dict(DEFAULT_SIGMA))
    vibration: dict = field(default_factory=lambda: dict(DEFAULT_VIBRATION))
    tas_sigma_low_speed: float = 1.0  # m/s below low_speed
    low_speed: float = 30 * 0.514444  # m/s

    def __post_init__(self):
        ratio = self.sim_rate / self.record_rate
        if abs(ratio - round(ratio)) > 1e-9 or ratio < 1:
            raise ValueError(f"sim_rate {self.sim_rate} Hz must be an integer multiple of record_rate "
                             f"{self.record_rate} Hz")
        if not 0 < self.antialias_hz < self.record_rate / 2:
            raise ValueError(f"antialias_hz {self.antialias_hz} must lie below the Nyquist frequency "
                             f"{self.record_rate / 2} Hz")

    @property
    def decimation(self) -> int:
        return int(round(self.sim_rate / self.record_rate))

    def sos(self):
        return signal.butter(2, self.antialias_hz, fs=self.sim_rate, output="sos")

    def noise_gain(self, n: int = 4096) -> float:
        """Std of filtered-and-decimated unit white noise (so noise can be pre-scaled)."""
        impulse = np.zeros(n)
        impulse[n // 2] = 1.0
        h = signal.sosfiltfilt(self.sos(), impulse)
        return float(np.sqrt(np.sum(h**2)))


def record(t_fast: np.ndarray, channels: dict[str, np.ndarray], cfg: SensorConfig, rng: np.random.Generator,
           speed: float) -> dict[str, np.ndarray]:
    """Turn truth channels at the simulation rate into recorded channels.

    Returns the decimated time vector under key ``t`` and every channel.
    Channels are processed in sorted order so that the random stream does not
    depend on dict order.
    """
    sos, gain, dec = cfg.sos(), cfg.noise_gain(), cfg.decimation
    out = {"t": t_fast[::dec]}
    phase0 = rng.uniform(0, 2 * np.pi)
    for name in sorted(channels):
        x = np.asarray(channels[name], dtype=float)
        sigma = cfg.sigma.get(name, 0.0)
        if name == "TAS" and speed < cfg.low_speed:
            sigma = cfg.tas_sigma_low_speed
        vib = cfg.vibration.get(name, 0.0)
        noisy = x + vib * np.sin(2 * np.pi * cfg.vibration_hz * t_fast + phase0)
        noisy = noisy + rng.standard_normal(x.size) * (sigma / gain)
        filtered = signal.sosfiltfilt(sos, noisy) if (sigma > 0 or vib > 0) else x
        out[name] = filtered[::dec]
    return out


def average_trim(values: dict[str, float], sigma: dict[str, float], offset: dict[str, float],
                 rng: np.random.Generator) -> dict[str, float]:
    """A trim point as delivered: the average of a record plus a not-quite-steady offset."""
    return {k: v + rng.normal(0, sigma.get(k, 0.0)) + rng.normal(0, offset.get(k, 0.0))
            for k, v in sorted(values.items())}
