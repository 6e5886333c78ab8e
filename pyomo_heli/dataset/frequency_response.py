"""Frequency responses from flight-test maneuvers (the data side of J_linear).

What a user of frequency-domain tools would extract: for an input/output
pair at one flight condition, the auto- and cross-spectra of the measured
input and output increments (Welch: Hann window, 75 % overlap, spectra summed
over every maneuver at that speed that moves only this input), the H1
estimate T = G_uy / G_uu and the coherence |G_uy|^2 / (G_uu G_yy).

The bundled maneuvers are short transients (doublets and 3-2-1-1s of 12-15 s),
so not every frequency carries information. A bin is kept ("coherent band")
only where the coherence is at least ``coherence_min`` AND the input
autospectrum is at least ``input_power_min`` of its peak (near the spectral
nulls of a doublet the coherence can stay high while the H1 ratio is
dominated by leakage of the window), inside [omega_min, omega_max].
The defaults were chosen once on bo105_clean (docs/linear.md lists the
measured errors against the model's own linearisation).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import signal

#: the pairs the bundled maneuvers excite: (output, input)
DEFAULT_PAIRS = (("q", "lon"), ("n_z", "col"))


#: fewest samples of a Welch segment: below this a spectrum has no frequency resolution to speak of
MIN_WINDOW_SAMPLES = 16


@dataclass
class SpectralSettings:
    """How spectra are estimated and which bins count as coherent."""

    window_s: float = 5.12  # Welch segment length [s]
    overlap: float = 0.75  # fraction of a segment
    nfft_factor: int = 2  # zero padding: nfft = factor * segment samples
    coherence_min: float = 0.9
    input_power_min: float = 0.2  # fraction of the peak input autospectrum
    omega_min: float = 0.9  # [rad/s]
    omega_max: float = 20.0  # [rad/s]

    def __post_init__(self):
        if not self.window_s > 0:
            raise ValueError(f"linear.window_s must be positive, got {self.window_s}")
        if not 0 <= self.overlap < 1:
            raise ValueError(f"linear.overlap must be in [0, 1), got {self.overlap}")
        if not 0 < self.coherence_min < 1:
            raise ValueError(f"linear.coherence_min must be in (0, 1), got {self.coherence_min}")
        if not 0 <= self.input_power_min < 1:
            raise ValueError(f"linear.input_power_min must be in [0, 1), got {self.input_power_min}")
        if not 0 <= self.omega_min < self.omega_max:
            raise ValueError(f"linear.omega_min must be below omega_max, got {self.omega_min}, {self.omega_max}")


@dataclass
class FrequencyResponse:
    """One estimated frequency response T(j omega) = output/input (SI per SI)."""

    speed: float  # trim speed [m/s]
    output: str
    input: str
    omega: np.ndarray  # [rad/s]
    T: np.ndarray  # complex
    coherence: np.ndarray
    input_power: np.ndarray  # input autospectrum / its peak
    coherent: np.ndarray  # bool: inside the coherent band
    maneuvers: list = field(default_factory=list)

    @property
    def gain_db(self) -> np.ndarray:
        return 20 * np.log10(np.abs(self.T))

    @property
    def phase_deg(self) -> np.ndarray:
        return np.degrees(np.angle(self.T))

    def band(self) -> "FrequencyResponse":
        """Only the coherent bins."""
        k = self.coherent
        return FrequencyResponse(self.speed, self.output, self.input, self.omega[k], self.T[k], self.coherence[k],
                                 self.input_power[k], self.coherent[k], list(self.maneuvers))

    @property
    def label(self) -> str:
        return f"{self.output}/{self.input} at {self.speed / (1852 / 3600):.0f} kt"

    def to_frame(self) -> pd.DataFrame:
        return pd.DataFrame({"speed": self.speed, "output": self.output, "input": self.input, "omega": self.omega,
                             "T_re": self.T.real, "T_im": self.T.imag, "coherence": self.coherence,
                             "input_power": self.input_power, "coherent": self.coherent,
                             "maneuvers": " ".join(self.maneuvers)})


def estimate(maneuvers, output: str, input: str, settings: SpectralSettings | None = None) -> FrequencyResponse:
    """H1 frequency response and coherence of ``output``/``input`` from maneuvers at one speed."""
    s = settings or SpectralSettings()
    if not maneuvers:
        raise ValueError(f"no maneuver to estimate {output}/{input} from")
    speeds = {round(mv.trim_speed, 6) for mv in maneuvers}
    if len(speeds) != 1:
        raise ValueError(f"maneuvers at different speeds {sorted(speeds)}: spectra of one flight condition only")
    g_uu = g_uy = g_yy = 0.0
    for mv in maneuvers:
        fs = mv.sample_rate
        n = int(round(s.window_s * fs))
        if n < MIN_WINDOW_SAMPLES:
            raise ValueError(f"maneuver {mv.name}: linear.window_s = {s.window_s:g} s is {n} samples at {fs:g} Hz; "
                             f"a spectral window needs at least {MIN_WINDOW_SAMPLES}")
        if n > mv.n_samples:
            raise ValueError(f"maneuver {mv.name}: {mv.n_samples} samples, shorter than the spectral window "
                             f"linear.window_s = {s.window_s} s")
        u = mv.data[input].to_numpy() - mv.data[input].iloc[0]
        y = mv.data[output].to_numpy() - mv.data[output].iloc[0]
        kw = dict(fs=fs, window="hann", nperseg=n, noverlap=int(round(s.overlap * n)), detrend=False,
                  nfft=s.nfft_factor * n)
        f, puu = signal.welch(u, **kw)
        _, puy = signal.csd(u, y, **kw)
        _, pyy = signal.welch(y, **kw)
        g_uu, g_uy, g_yy = g_uu + puu, g_uy + puy, g_yy + pyy
    omega = 2 * np.pi * f
    with np.errstate(divide="ignore", invalid="ignore"):
        T = g_uy / g_uu
        coh = np.abs(g_uy) ** 2 / (g_uu * g_yy)
    power = g_uu / np.max(g_uu)
    ok = ((omega >= s.omega_min) & (omega <= s.omega_max) & (coh >= s.coherence_min) & (power >= s.input_power_min)
          & np.isfinite(T))
    return FrequencyResponse(float(maneuvers[0].trim_speed), output, input, omega, T, np.nan_to_num(coh), power, ok,
                             [mv.name for mv in maneuvers])


def single_input_maneuvers(maneuvers, input: str) -> dict[float, list]:
    """Maneuvers whose excited inputs (manifest ``inputs``) are ``input`` alone, grouped by trim speed [m/s].

    The manifest is used rather than the records because recorded inputs carry sensor noise.
    """
    out: dict[float, list] = {}
    for mv in maneuvers:
        if list(mv.inputs) == [input]:
            out.setdefault(round(float(mv.trim_speed), 6), []).append(mv)
    return out


def frequency_responses(maneuvers, pairs=DEFAULT_PAIRS, speeds=None,
                        settings: SpectralSettings | None = None) -> list[FrequencyResponse]:
    """Every (speed, pair) the maneuvers excite; ``speeds`` [m/s] restricts the flight conditions."""
    out = []
    for output, input in pairs:
        for V, mans in sorted(single_input_maneuvers(maneuvers, input).items()):
            if speeds is not None and not any(abs(V - s) < 1e-3 for s in speeds):
                continue
            out.append(estimate(mans, output, input, settings))
    return out


def save_responses(responses: list[FrequencyResponse], path: str | Path) -> None:
    pd.concat([r.to_frame() for r in responses], ignore_index=True).to_csv(path, index=False, float_format="%.12g")


def load_responses(path: str | Path) -> list[FrequencyResponse]:
    df = pd.read_csv(path)
    out = []
    for (V, o, i), g in df.groupby(["speed", "output", "input"], sort=False):
        mans = str(g["maneuvers"].iloc[0]).split() if "maneuvers" in g else []
        out.append(FrequencyResponse(float(V), o, i, g["omega"].to_numpy(), g["T_re"].to_numpy() + 1j * g["T_im"].to_numpy(),
                                     g["coherence"].to_numpy(), g["input_power"].to_numpy(),
                                     g["coherent"].astype(bool).to_numpy(), mans))
    return out
