"""Frequency responses from flight-test maneuvers (the data side of J_linear).

What a user of frequency-domain tools would extract: for an input/output
pair at one flight condition, the auto- and cross-spectra of the measured
input and output increments (Welch: Hann window, 75 % overlap, spectra summed
over every maneuver at that speed that moves only this input), the H1
estimate T = G_uy / G_uu and the coherence |G_uy|^2 / (G_uu G_yy).

The bundled maneuvers are short transients (doublets and 3-2-1-1s of 12-15 s),
so not every frequency carries information. A bin is kept ("coherent band")
only where the coherence is at least ``coherence_min`` AND the input
autospectrum is at least ``input_power_min`` of its peak in the band (near the spectral
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
    #: normalised random error of |T| (Bendat-Piersol, from coherence); phase error ~ degrees(random_error) [deg]
    random_error: np.ndarray | None = None
    #: the other inputs this response is conditioned on (composite/conditioned estimates; empty for SISO)
    conditioned_on: tuple = ()

    @property
    def gain_db(self) -> np.ndarray:
        return 20 * np.log10(np.abs(self.T))

    @property
    def phase_deg(self) -> np.ndarray:
        return np.degrees(np.angle(self.T))

    def band(self) -> "FrequencyResponse":
        """Only the coherent bins."""
        k = self.coherent
        err = None if self.random_error is None else self.random_error[k]
        return FrequencyResponse(self.speed, self.output, self.input, self.omega[k], self.T[k], self.coherence[k],
                                 self.input_power[k], self.coherent[k], list(self.maneuvers), err,
                                 tuple(self.conditioned_on))

    @property
    def label(self) -> str:
        return f"{self.output}/{self.input} at {self.speed / (1852 / 3600):.0f} kt"

    def to_frame(self) -> pd.DataFrame:
        cols = {"speed": self.speed, "output": self.output, "input": self.input, "omega": self.omega,
                "T_re": self.T.real, "T_im": self.T.imag, "coherence": self.coherence,
                "input_power": self.input_power, "coherent": self.coherent, "maneuvers": " ".join(self.maneuvers)}
        if self.random_error is not None:  # composite estimates only: the SISO files keep their columns
            cols["random_error"] = self.random_error
            cols["conditioned_on"] = " ".join(self.conditioned_on)
        return pd.DataFrame(cols)


def estimate(maneuvers, output: str, input: str, settings: SpectralSettings | None = None) -> FrequencyResponse:
    """H1 frequency response and coherence of ``output``/``input`` from maneuvers at one speed."""
    s = settings or SpectralSettings()
    if not maneuvers:
        raise ValueError(f"no maneuver to estimate {output}/{input} from")
    speeds = {round(mv.trim_speed, 6) for mv in maneuvers}
    if len(speeds) != 1:
        raise ValueError(f"maneuvers at different speeds {sorted(speeds)}: spectra of one flight condition only")
    g_uu = g_uy = g_yy = 0.0
    segments = 0
    rate = maneuvers[0].sample_rate  # spectra are summed bin by bin: one frequency grid, one sample rate
    for mv in maneuvers:
        fs = mv.sample_rate
        if abs(fs - rate) > 1e-9:
            raise ValueError(f"maneuver {mv.name}: sample rate {fs:g} Hz differs from {rate:g} Hz of "
                             f"{maneuvers[0].name}: spectra of one sample rate only")
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
        segments += 1 + (mv.n_samples - n) // max(n - kw["noverlap"], 1)
        f, puu = signal.welch(u, **kw)
        _, puy = signal.csd(u, y, **kw)
        _, pyy = signal.welch(y, **kw)
        g_uu, g_uy, g_yy = g_uu + puu, g_uy + puy, g_yy + pyy
    if segments < 2:  # one averaged segment has coherence 1 at every frequency, whatever the data
        raise ValueError(f"{output}/{input} at {maneuvers[0].trim_speed:.6g} m/s: linear.window_s = {s.window_s:g} s "
                         f"leaves one spectral segment in all ({', '.join(mv.name for mv in maneuvers)}); the "
                         f"coherence needs at least two: a shorter window or more records")
    omega = 2 * np.pi * f
    with np.errstate(divide="ignore", invalid="ignore"):
        T = g_uy / g_uu
        coh = np.abs(g_uy) ** 2 / (g_uu * g_yy)
    # relative to the input's peak inside the band: a held offset or a step puts the peak of the whole spectrum
    # below omega_min, which would leave every bin of the band under input_power_min
    in_band = (omega >= s.omega_min) & (omega <= s.omega_max)
    power = g_uu / (np.max(g_uu[in_band]) if in_band.any() else np.max(g_uu))
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
        err = g["random_error"].to_numpy() if "random_error" in g else None
        cond = tuple(str(g["conditioned_on"].iloc[0]).split()) if "conditioned_on" in g and \
            isinstance(g["conditioned_on"].iloc[0], str) else ()
        out.append(FrequencyResponse(float(V), o, i, g["omega"].to_numpy(),
                                     g["T_re"].to_numpy() + 1j * g["T_im"].to_numpy(),
                                     g["coherence"].to_numpy(), g["input_power"].to_numpy(),
                                     g["coherent"].astype(bool).to_numpy(), mans, err, cond))
    return out


# ---------------------------------------------------------------------------------------------------------------
# Composite-window, multi-input conditioned frequency responses (CIFER practice, for frequency sweeps)
# ---------------------------------------------------------------------------------------------------------------

#: largest coherence used in a weight: noise-free data has gamma^2 -> 1 and would give infinite weights
WEIGHT_COHERENCE_CAP = 0.999


@dataclass
class CompositeSettings:
    """Composite windowing (Tischler and Remple, ch. 7; CIFER's COMPOSITE) and the coherent band.

    Each window length in ``windows_s`` gives a Welch estimate (Hann, ``overlap``); a window of length
    T_w counts only at omega >= ``min_periods`` * 2 pi / T_w (it must hold that many periods) and uses
    only the records that hold two segments and are at least T_w / ``max_window_fraction`` long (with
    0.5, Tischler and Remple's guideline, ch. 7: the longest window at most half the record, so that every
    record gives 6 segments at 80 % overlap and the window's coherence and random error are averages, not
    nearly one segment's, which has coherence 1 whatever the data); no frequency below
    ``record_periods`` periods in the longest record counts (Tischler and Remple: record length >= 4-5
    times the longest period). The estimates
    are averaged at each frequency of a
    logarithmic grid of ``n_omega`` points in [omega_min, omega_max] with the weights 1 / eps_r^2
    (random error from coherence, below). A bin is coherent where the composite (partial) coherence
    gamma^2 >= ``coherence_min`` (the usual 0.6 guideline).

    Coherence over the resolution bandwidth (``coherence_span``): a window's estimate at omega is not a
    measurement at omega alone but the Guu-weighted average of the data over its spectral kernel, and it
    is only as good as the data it averages. So a window's (multiple and partial) coherence at omega is
    the SMALLEST of its Welch bins within +-``coherence_span`` / T_w [Hz] of omega (2: the main lobe of
    the Hann kernel, whose first zeros are 2 / T_w either side; the same main lobe that sets
    SWEEP_SETTINGS' 4 periods), and that coherence sets both its random error (its weight in the
    composite) and the composite coherence, hence the band. Where the input autospectrum has a notch (a
    stabilising pilot puts one at each unstable bare-airframe pole, where the response also varies
    fastest) the bins in the notch lose coherence, and the bins on its flanks, whose H1 ratio is set by
    leakage from the notch's other side, leave the band with them. 0: the coherence at omega itself
    (interpolated between bins), as before this rule.
    """

    windows_s: tuple = (5.0, 10.0, 15.0, 20.0, 30.0)  # [s]
    overlap: float = 0.8  # CIFER's default
    nfft_factor: int = 2
    coherence_min: float = 0.6
    omega_min: float = 0.3  # [rad/s]
    omega_max: float = 20.0  # [rad/s]
    n_omega: int = 100
    min_periods: float = 2.0
    record_periods: float = 5.0
    max_window_fraction: float = 1.0  # longest window / record length (SWEEP_SETTINGS: 0.5, CIFER's T_rec / 2)
    coherence_span: float = 2.0  # [1/T_w Hz]: a window's coherence at omega is its smallest this near omega

    def __post_init__(self):
        self.windows_s = tuple(float(w) for w in self.windows_s)
        if not self.windows_s or min(self.windows_s) <= 0:
            raise ValueError(f"composite windows_s must be positive window lengths [s], got {self.windows_s}")
        if not 0 <= self.overlap < 1:
            raise ValueError(f"composite overlap must be in [0, 1), got {self.overlap}")
        if not 0 < self.coherence_min < 1:
            raise ValueError(f"composite coherence_min must be in (0, 1), got {self.coherence_min}")
        if not 0 < self.omega_min < self.omega_max:
            raise ValueError(f"composite omega_min must be in (0, omega_max), got {self.omega_min}, {self.omega_max}")
        if self.n_omega < 2 or self.min_periods <= 0 or self.record_periods < 0:
            raise ValueError(f"composite n_omega must be >= 2 and min_periods > 0, got {self.n_omega}, "
                             f"{self.min_periods}")
        if not 0 < self.max_window_fraction <= 1:
            raise ValueError(f"composite max_window_fraction must be in (0, 1], got {self.max_window_fraction}")
        if not 0 <= self.coherence_span <= 10:
            raise ValueError(f"composite coherence_span must be in [0, 10] (units of 1/T_w), got {self.coherence_span}")


@dataclass
class WindowSpectra:
    """Segment-averaged spectra of one window length over several records.

    f [Hz]; Gxx [nf, q, q] with Gxx[:, i, j] = csd(x_i, x_j) (one-sided, conj(X_i) X_j); Gxy [nf, q];
    Gyy [nf]; n_d = number of averaged segments (Welch, all records).
    """

    window_s: float
    f: np.ndarray
    Gxx: np.ndarray
    Gxy: np.ndarray
    Gyy: np.ndarray
    n_d: int


def _record_arrays(mv, names):
    """Increments on the first sample of the named columns of a maneuver (or a DataFrame with ``sample_rate``)."""
    data = mv.data
    return [data[c].to_numpy(dtype=float) - float(data[c].iloc[0]) for c in names]


def window_spectra(records, inputs, output: str, window_s: float, overlap: float = 0.8,
                   nfft_factor: int = 2, max_fraction: float = 1.0) -> WindowSpectra | None:
    """Welch spectral matrices of (inputs, output) for one window length; None if no record holds 2 segments
    and is at least ``window_s / max_fraction`` long.

    Records of different lengths are combined by their segment counts (each record's Welch average
    weighted by its number of segments), so the result is the average over every segment.
    """
    q = len(inputs)
    acc = None
    n_total = 0
    f = rate = None  # rate: the sample rate of the records seen so far
    for mv in records:
        fs = mv.sample_rate
        n = int(round(window_s * fs))
        step = n - int(round(overlap * n))
        if n < MIN_WINDOW_SAMPLES or step < 1 or mv.n_samples < n + step or mv.n_samples < n / max_fraction - 1e-9:
            continue  # fewer than two segments, or the window is too long for this record: no average
        segs = 1 + (mv.n_samples - n) // step
        sig = _record_arrays(mv, list(inputs) + [output])
        kw = dict(fs=fs, window="hann", nperseg=n, noverlap=n - step, detrend=False, nfft=nfft_factor * n)
        if f is not None and abs(fs - rate) > 1e-9:
            raise ValueError(f"maneuver {mv.name}: sample rate {fs:g} Hz differs from {rate:g} Hz of the others")
        rate = fs
        G = np.empty((q + 1, q + 1), dtype=object)
        for i in range(q + 1):
            for j in range(i, q + 1):
                f, G[i, j] = signal.csd(sig[i], sig[j], **kw)
                if i != j:
                    G[j, i] = np.conj(G[i, j])
        M = np.stack([np.stack(list(row), axis=-1) for row in G], axis=-2)  # [nf, q+1, q+1]
        acc = segs * M if acc is None else acc + segs * M
        n_total += segs
    if acc is None:
        return None
    M = acc / n_total
    return WindowSpectra(window_s, f, M[:, :q, :q], M[:, :q, q], M[:, q, q].real, n_total)


def conditioned(Gxx, Gxy, Gyy):
    """MIMO H1 responses and coherences from spectral matrices (Bendat and Piersol, ch. 7).

    For y = sum_i H_i x_i + n:   H = Gxx^-1 Gxy
    multiple coherence           gamma^2_y:x = Gxy^H Gxx^-1 Gxy / Gyy
    partial coherence of x_i     gamma^2_iy.o = |G_iy.o|^2 / (G_ii.o G_yy.o)
    with the spectra conditioned on the other inputs o:  G_ab.o = G_ab - G_ao G_oo^-1 G_ob.
    With one input this is the ordinary H1 and coherence. Returns H [nf, q], multiple [nf], partial [nf, q].
    """
    nf, q = Gxy.shape
    H = np.full((nf, q), np.nan + 0j)
    mult = np.zeros(nf)
    part = np.zeros((nf, q))
    for k in range(nf):
        A, b, gyy = Gxx[k], Gxy[k], Gyy[k]
        if not (np.all(np.isfinite(A)) and gyy > 0) or np.linalg.cond(A) > 1e12:
            continue  # an input without power here, or inputs moving together: not separable
        h = np.linalg.solve(A, b)
        H[k] = h
        mult[k] = float(np.real(np.conj(b) @ h) / gyy)
        for i in range(q):
            o = [j for j in range(q) if j != i]
            if not o:
                part[k, i] = abs(b[i]) ** 2 / (A[i, i].real * gyy)
                continue
            Aoo = A[np.ix_(o, o)]
            gii = A[i, i] - A[i, o] @ np.linalg.solve(Aoo, A[o, i])
            giy = b[i] - A[i, o] @ np.linalg.solve(Aoo, b[o])
            gyo = gyy - np.real(np.conj(b[o]) @ np.linalg.solve(Aoo, b[o]))
            part[k, i] = abs(giy) ** 2 / (gii.real * gyo) if gii.real > 0 and gyo > 0 else 0.0
    return H, np.clip(mult, 0.0, 1.0), np.clip(part, 0.0, 1.0)


def random_error(multiple, partial, n_d, q: int = 1):
    """Normalised random error of |H| (Bendat and Piersol, eq. 9.90; ch. 9 for one input):

        eps_r = sqrt(1 - gamma^2_y:x) / (|gamma_iy.o| sqrt(2 (n_d - q + 1)))

    with one input (q = 1) eps_r = sqrt(1 - gamma^2) / (|gamma| sqrt(2 n_d)). The phase error is about
    eps_r [rad]. n_d is the number of averaged segments; with overlapping segments they are not
    independent, so eps_r is somewhat optimistic.
    """
    dof = max(n_d - q + 1, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.sqrt(np.clip(1 - np.asarray(multiple), 0, None)) / (np.sqrt(np.asarray(partial)) * np.sqrt(2 * dof))
    return np.where(np.asarray(partial) > 0, e, np.inf)


def _interp_complex(x, xp, fp):
    return np.interp(x, xp, fp.real) + 1j * np.interp(x, xp, fp.imag)


def span_minimum(x, xp, fp, half: float, interpolated):
    """At each x, the smallest of ``interpolated`` (fp interpolated at x) and fp at the points xp within
    +-``half`` of x (xp ascending); with ``half`` 0, ``interpolated`` itself."""
    out = np.array(interpolated, dtype=float)
    if half > 0:
        lo = np.searchsorted(xp, x - half, side="left")
        hi = np.searchsorted(xp, x + half, side="right")
        for k in np.flatnonzero(hi > lo):
            out[k] = min(out[k], fp[lo[k]:hi[k]].min())
    return out


def composite_responses(records, output: str, inputs, settings: CompositeSettings | None = None,
                        speed: float | None = None) -> list[FrequencyResponse]:
    """Composite-window frequency responses of ``output`` to each of ``inputs`` (conditioned on the others).

    ``records`` are maneuvers (``data``, ``sample_rate``, ``n_samples``, ``name``, ``trim_speed``) at one
    flight condition, all recording every input in ``inputs``. Returns one FrequencyResponse per input on
    the logarithmic grid, with ``coherence`` the composite partial coherence (ordinary coherence for one
    input), ``random_error`` eps_r, and ``coherent`` the bins with gamma^2 >= coherence_min.
    """
    s = settings or CompositeSettings()
    inputs = tuple(inputs)
    if not records:
        raise ValueError(f"no record to estimate {output}/{', '.join(inputs)} from")
    if not inputs or len(set(inputs)) != len(inputs):
        raise ValueError(f"inputs must be distinct input names, got {inputs}")
    for mv in records:
        for c in inputs + (output,):
            if c not in mv.data:
                raise ValueError(f"maneuver {mv.name}: no column '{c}'")
    if speed is None:
        speeds = {round(float(mv.trim_speed), 6) for mv in records}
        if len(speeds) != 1:
            raise ValueError(f"records at different speeds {sorted(speeds)}: spectra of one flight condition only")
        speed = float(records[0].trim_speed)
    q = len(inputs)
    omega = np.geomspace(s.omega_min, s.omega_max, s.n_omega)
    wsum = np.zeros((s.n_omega, q))
    Tsum = np.zeros((s.n_omega, q), dtype=complex)
    psum = np.zeros((s.n_omega, q))
    esum = np.zeros((s.n_omega, q))
    guu = np.zeros((s.n_omega, q))
    used = []
    longest = max((mv.n_samples - 1) / mv.sample_rate for mv in records)  # [s]
    omega_record = s.record_periods * 2 * np.pi / longest
    for w in s.windows_s:
        sp = window_spectra(records, inputs, output, w, s.overlap, s.nfft_factor, s.max_window_fraction)
        if sp is None:
            continue
        used.append(w)
        wo = 2 * np.pi * sp.f
        H, mult, part = conditioned(sp.Gxx, sp.Gxy, sp.Gyy)
        ok_native = np.isfinite(H).all(axis=1)
        valid = (omega >= s.min_periods * 2 * np.pi / w) & (omega <= wo[-1]) & (omega >= omega_record)
        if not ok_native.any():
            continue
        # onto the composite grid: T interpolated; coherences the smallest over the resolution bandwidth
        # (bins where the inputs are not separable count with coherence 0)
        half = s.coherence_span * 2 * np.pi / w  # [rad/s]
        m_i = span_minimum(omega, wo, mult, half, np.interp(omega, wo[ok_native], mult[ok_native]))
        for i in range(q):
            T_i = _interp_complex(omega, wo[ok_native], H[ok_native, i])
            p_i = span_minimum(omega, wo, part[:, i], half, np.interp(omega, wo[ok_native], part[ok_native, i]))
            e_i = random_error(np.minimum(m_i, WEIGHT_COHERENCE_CAP), np.minimum(p_i, WEIGHT_COHERENCE_CAP),
                               sp.n_d, q)
            wt = np.where(valid & np.isfinite(e_i), 1.0 / e_i ** 2, 0.0)
            wsum[:, i] += wt
            Tsum[:, i] += wt * T_i
            psum[:, i] += wt * p_i
            esum[:, i] += wt * np.where(np.isfinite(e_i), e_i, 0.0)
            guu[:, i] += wt * np.interp(omega, wo, sp.Gxx[:, i, i].real)
    if not used:
        raise ValueError(f"records of {output}/{', '.join(inputs)} are shorter than two segments of every window "
                         f"length {s.windows_s} s")
    out = []
    names = [mv.name for mv in records]
    with np.errstate(divide="ignore", invalid="ignore"):
        for i, inp in enumerate(inputs):
            have = wsum[:, i] > 0
            T = np.where(have, Tsum[:, i] / wsum[:, i], np.nan + 0j)
            coh = np.where(have, psum[:, i] / wsum[:, i], 0.0)
            # composite error: the weighted mean of the windows' errors (the windows share their data,
            # so combining them as independent estimates would overstate the accuracy)
            err = np.where(have, esum[:, i] / wsum[:, i], np.inf)
            gi = np.where(have, guu[:, i] / wsum[:, i], 0.0)
            power = gi / gi.max() if gi.max() > 0 else gi
            ok = have & (coh >= s.coherence_min) & np.isfinite(T)
            out.append(FrequencyResponse(float(speed), output, inp, omega, T, coh, power, ok, list(names), err,
                                         tuple(x for x in inputs if x != inp)))
    return out


#: composite settings for the long sweeps of the bundled flight test: the default ladder extended to 90 s, each
#: window used only on records at least twice its length (45 s on the 95 s records) and counted where it holds
#: 4 periods (with 2, the main lobe of the Hann window, +-2 bins, reaches 0 rad/s, where the records' trim drift
#: is; docs/linear.md section 6)
SWEEP_SETTINGS = CompositeSettings(windows_s=(5.0, 10.0, 15.0, 20.0, 30.0, 45.0, 60.0, 90.0), min_periods=4.0,
                                   max_window_fraction=0.5)


def sweep_responses(records, pairs=DEFAULT_PAIRS, speeds=None,
                    settings: CompositeSettings | None = None) -> list[FrequencyResponse]:
    """Composite responses of each (output, input) pair at each speed of the sweep ``records``.

    At each trim speed every record is used together, conditioned on every input any of them moves (manifest
    ``inputs``): a pilot's corrections on lon during a col sweep are removed from the col response.
    ``speeds`` [m/s] restricts the flight conditions.
    """
    s = settings or SWEEP_SETTINGS
    by_speed: dict[float, list] = {}
    for mv in records:
        by_speed.setdefault(round(float(mv.trim_speed), 6), []).append(mv)
    out = []
    for output, input in pairs:
        for V, recs in sorted(by_speed.items()):
            if speeds is not None and not any(abs(V - v) < 1e-3 for v in speeds):
                continue
            moved = sorted({i for mv in recs for i in mv.inputs})
            if input not in moved:
                continue
            frs = composite_responses(recs, output, tuple(moved), s, speed=V)
            out.append(next(f for f in frs if f.input == input))
    return out


#: frequencies per response of the Tischler-Remple cost: n_omega = 20, spaced logarithmically over the band
TR_POINTS = 20


def tischler_remple_points(fr: FrequencyResponse, n: int = TR_POINTS) -> FrequencyResponse:
    """``fr`` with its coherent band cut to (at most) ``n`` frequencies spaced logarithmically across it.

    Tischler and Remple (ch. 11) evaluate the cost at n_omega = 20 logarithmically spaced frequencies of
    each response's coherent band, so that every decade counts alike; here each target frequency takes the
    nearest coherent grid point (a target in a gap of the band takes the point nearest to it, once).
    """
    k = np.flatnonzero(fr.coherent)
    keep = np.zeros(len(fr.omega), dtype=bool)
    if len(k):
        w = fr.omega[k]
        targets = np.geomspace(w.min(), w.max(), n) if len(k) > 1 else w
        idx = {int(k[np.argmin(np.abs(np.log(w) - np.log(t)))]) for t in targets}
        keep[sorted(idx)] = True
    return FrequencyResponse(fr.speed, fr.output, fr.input, fr.omega, fr.T, fr.coherence, fr.input_power, keep,
                             list(fr.maneuvers), fr.random_error, tuple(fr.conditioned_on))
