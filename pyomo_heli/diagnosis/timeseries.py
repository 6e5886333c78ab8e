"""Time-series residual tests: whiteness, spectra, coherence with the inputs, correlation with regressors.

A model that captures the dynamics leaves residuals that are measurement noise:
white, with a flat spectrum, unrelated to the inputs and to the flight state.
Each departure points at something: low-frequency power and autocorrelation at
a missing slow effect, coherence with an input at a wrong or missing input path
(a lag, a gain), correlation with a state at a missing dependence on it.

**Whiteness at a test rate.** Recorded sensor noise is not white at the record
rate: the anti-alias filter (10 Hz on the 50 Hz synthetic data, and on real
flight-test data alike) correlates neighbouring samples. Testing at the record
rate would reject whiteness for pure noise. The test therefore takes every
k-th sample so that samples are ``1 / test_rate_hz`` apart (default 5 Hz,
200 ms: several times the correlation time of a >= 5 Hz anti-alias filter, and
still above the 0.2-2.5 Hz band of the rigid-body dynamics) and applies the
Ljung-Box test there:

    Q = n (n + 2) sum_{k=1..K} r_k^2 / (n - k)   ~ chi^2(K) if white,

r_k the normalised autocorrelation of the de-meaned residual, K = min(10, n/5)
lags (2 s at 5 Hz). With many maneuvers x outputs the overall verdict uses a
Bonferroni bound (every p > alpha / number of tests).

**Spectra** are Welch estimates (``scipy.signal.welch``, Hann, 50 % overlap) at
the full rate, averaged over the maneuvers of a role. The number reported per
output is the band ratio: mean PSD in the dynamics band 0.1-2 Hz divided by the
mean PSD in 2-5 Hz; about 1 for white noise, large when the residual is
dominated by slow model error.

**Coherence** of each residual with each input the maneuver excites
(``scipy.signal.coherence`` of the input increment and the residual), mean over
0.1-2 Hz and peak; the approximate threshold of zero coherence for n_d Welch
segments is 1 - a^(1/(n_d - 1)), a = alpha Bonferroni-divided by the bins in
the band and the tests of the role (see :func:`coherence_table`).

**Correlation with regressors**: Pearson r of the residual with physically
meaningful regressors of the model (airspeed, advance ratio, wake skew angle,
inflow, q, theta, dq/dt, input increments and their rates), pooled over the
maneuvers of a role at the test rate. It is descriptive: a structured residual
is autocorrelated even at the test rate, so the nominal p-value overstates the
evidence; use it to rank, not to decide.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import signal, stats

#: Hz: the default rate of the whiteness test (samples 200 ms apart)
TEST_RATE_HZ = 5.0
DYN_BAND = (0.1, 2.0)  # Hz
HIGH_BAND = (2.0, 5.0)  # Hz
#: an input whose increment has a smaller std is not excited by the maneuver
INPUT_MIN_STD = 0.02 * math.pi / 180  # rad: an input with a smaller increment std is not excited


def decimation(t: np.ndarray, test_rate_hz: float) -> int:
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    return max(int(round(1.0 / (test_rate_hz * dt))), 1)


def ljung_box(x, lags: int | None = None) -> dict:
    """Ljung-Box portmanteau test of whiteness of ``x``: Q, lags, p, and r_1."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    n = len(x)
    K = lags if lags is not None else max(1, min(10, n // 5))
    if n < 8 or K < 1:
        return {"Q": float("nan"), "lags": int(K), "p": float("nan"), "r1": float("nan"), "n": n}
    r = autocorrelation(x, K)
    Q = n * (n + 2) * np.sum(r[1:] ** 2 / (n - np.arange(1, K + 1)))
    return {"Q": float(Q), "lags": int(K), "p": float(stats.chi2.sf(Q, K)), "r1": float(r[1]), "n": n}


def autocorrelation(x, max_lag: int) -> np.ndarray:
    """Normalised autocorrelation r_0..r_max_lag of the de-meaned ``x`` (biased estimate, r_0 = 1)."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    d = float(np.dot(x, x))
    if d == 0:
        return np.r_[1.0, np.zeros(max_lag)]
    return np.array([np.dot(x[: len(x) - k], x[k:]) / d for k in range(max_lag + 1)])


def noise_scale(e) -> float:
    """Robust noise level of a residual from its sample-to-sample differences (insensitive to slow drift)."""
    d = np.diff(np.asarray(e, dtype=float))
    d = d[np.isfinite(d)]
    if d.size < 2:
        return float("nan")
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2))


def remove_nuisance(m: pd.DataFrame, outputs) -> tuple[dict, dict]:
    """Residuals of one maneuver with its nuisance part removed, and the nuisance estimates.

    Nuisance = a constant bias per output plus the response to a constant offset
    of each input (``dres_<o>_d<input>`` columns), shared by all outputs: the
    replay starts from the first recorded input sample, whose noise acts as a
    constant input error (output-error practice estimates such biases per
    maneuver). Weighted least squares over all outputs, weights from
    :func:`noise_scale`. Returns ({output: cleaned residual}, {"offset_<input>":
    rad, "bias_<output>": SI}).
    """
    outs = [o for o in outputs if np.all(np.isfinite(m[f"res_{o}"].to_numpy(dtype=float)))]
    inputs = [c for c in ("col", "lon") if all(f"dres_{o}_d{c}" in m for o in outs)]
    n = len(m)
    if not outs:
        return {o: m[f"res_{o}"].to_numpy(dtype=float) for o in outputs}, {}
    scale = {o: noise_scale(m[f"res_{o}"]) or 1.0 for o in outs}
    scale = {o: (v if np.isfinite(v) and v > 0 else 1.0) for o, v in scale.items()}
    A = np.zeros((n * len(outs), len(outs) + len(inputs)))
    y = np.zeros(n * len(outs))
    for i, o in enumerate(outs):
        rows = slice(i * n, (i + 1) * n)
        A[rows, i] = 1.0 / scale[o]
        for j, c in enumerate(inputs):
            A[rows, len(outs) + j] = m[f"dres_{o}_d{c}"].to_numpy(dtype=float) / scale[o]
        y[rows] = m[f"res_{o}"].to_numpy(dtype=float) / scale[o]
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    cleaned, est = {}, {}
    for i, o in enumerate(outs):
        fit = coef[i] + sum(coef[len(outs) + j] * m[f"dres_{o}_d{c}"].to_numpy(dtype=float)
                            for j, c in enumerate(inputs))
        cleaned[o] = m[f"res_{o}"].to_numpy(dtype=float) - fit
        est[f"bias_{o}"] = float(coef[i])
    for j, c in enumerate(inputs):
        est[f"offset_{c}"] = float(coef[len(outs) + j])
    for o in outputs:
        cleaned.setdefault(o, m[f"res_{o}"].to_numpy(dtype=float))
    return cleaned, est


def clean_time_residuals(time: pd.DataFrame, outputs) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The time table with every maneuver's nuisance removed from ``res_<o>`` (see :func:`remove_nuisance`),
    and a table of the nuisance estimates per maneuver."""
    out = time.copy()
    rows = []
    for name in dict.fromkeys(time["maneuver"]):
        idx = time.index[time["maneuver"] == name]
        cleaned, est = remove_nuisance(time.loc[idx], outputs)
        for o, v in cleaned.items():
            out.loc[idx, f"res_{o}"] = v
        rows.append({"maneuver": name, "role": time.loc[idx[0], "role"], **est})
    return out, pd.DataFrame(rows)


def _nperseg(n: int, fs: float) -> int:
    target = 2 ** int(round(math.log2(max(4.0 * fs, 16))))  # about 4 s
    return int(min(target, n))


def band_mean(f, p, band) -> float:
    m = (f >= band[0]) & (f <= band[1])
    return float(np.mean(p[m])) if m.any() else float("nan")


def spectra(time: pd.DataFrame, outputs, role: str) -> dict:
    """Welch PSD of each output's residual averaged over the maneuvers of ``role``.

    Returns {"f": [...], "fs": fs, "psd": {o: [...]}, "band_ratio": {o: ratio}}, PSD in SI^2/Hz.
    Maneuvers at another sample rate than the first are interpolated onto its grid.
    """
    df = time[time["role"] == role]
    names = list(dict.fromkeys(df["maneuver"]))
    if not names:
        return {}
    f_ref, acc, fs_ref = None, {o: None for o in outputs}, None
    count = {o: 0 for o in outputs}  # the records each output's average is over (a record without it is left out)
    for name in names:
        m = df[df["maneuver"] == name]
        t = m["t"].to_numpy()
        fs = 1.0 / float(np.median(np.diff(t)))
        nps = _nperseg(len(t), fs)
        for o in outputs:
            e = m[f"res_{o}"].to_numpy(dtype=float)
            if not np.all(np.isfinite(e)):
                continue
            f, p = signal.welch(e, fs=fs, nperseg=nps)
            if f_ref is None:
                f_ref, fs_ref = f, fs
            if len(f) != len(f_ref) or not np.allclose(f, f_ref):
                p = np.interp(f_ref, f, p)
            acc[o] = p if acc[o] is None else acc[o] + p
            count[o] += 1
    psd = {o: (acc[o] / count[o]).tolist() for o in outputs if acc[o] is not None}
    ratio = {o: band_mean(f_ref, np.asarray(v), DYN_BAND) / band_mean(f_ref, np.asarray(v), HIGH_BAND)
             for o, v in psd.items()}
    return {"f": f_ref.tolist(), "fs": fs_ref, "psd": psd, "band_ratio": ratio}


def excited_inputs(m: pd.DataFrame, declared=None) -> list[str]:
    """The inputs a maneuver excites: declared by the dataset, else those whose increment varies."""
    if declared:
        return [c for c in declared if f"in_{c}" in m]
    return [c for c in ("col", "lon") if f"in_{c}" in m and np.nanstd(m[f"in_{c}"]) > INPUT_MIN_STD]


def coherence_table(time: pd.DataFrame, outputs, inputs_of: dict | None = None, alpha: float = 0.01
                    ) -> tuple[pd.DataFrame, dict]:
    """Coherence of every residual with every excited input, per maneuver.

    The statistic is the peak coherence over the dynamics band. Its threshold
    is the zero-coherence quantile 1 - a^(1/(n_d - 1)) for n_d Welch segments
    (50 % overlap counted as independent: approximate), with a = alpha divided
    by the number of frequency bins in the band and by the number of tests of
    the role (Bonferroni: the peak is a maximum over bins, and many maneuvers x
    outputs are tested).

    Returns (table with maneuver, role, output, input, mean_band, peak, f_peak, threshold, significant;
    curves {maneuver: {"f": [...], "<input>:<output>": [...]}}).
    """
    rows, curves = [], {}
    for name in dict.fromkeys(time["maneuver"]):
        m = time[time["maneuver"] == name]
        t = m["t"].to_numpy()
        fs = 1.0 / float(np.median(np.diff(t)))
        nps = _nperseg(len(t), fs) // 2
        nseg = max(1, 1 + (len(t) - nps) // (nps - nps // 2))  # scipy's default overlap is nps // 2
        cur = {}
        for c in excited_inputs(m, (inputs_of or {}).get(name)):
            u = m[f"in_{c}"].to_numpy(dtype=float)
            for o in outputs:
                e = m[f"res_{o}"].to_numpy(dtype=float)
                if not np.all(np.isfinite(e)) or np.std(u) == 0 or np.std(e) == 0:
                    continue
                f, C = signal.coherence(u - u[0], e, fs=fs, nperseg=nps)
                band = (f >= DYN_BAND[0]) & (f <= DYN_BAND[1])
                k = int(np.argmax(np.where(band, C, -1)))
                cur["f"] = f.tolist()
                cur[f"{c}:{o}"] = C.tolist()
                rows.append({"maneuver": name, "role": m["role"].iloc[0], "output": o, "input": c,
                             "mean_band": float(np.mean(C[band])), "peak": float(C[k]), "f_peak": float(f[k]),
                             "segments": int(nseg), "bins": int(band.sum())})
        curves[name] = cur
    cols = ["maneuver", "role", "output", "input", "mean_band", "peak", "f_peak", "threshold", "segments",
            "significant"]
    tab = pd.DataFrame(rows)
    if tab.empty:
        return pd.DataFrame(columns=cols), curves
    ntests = tab.groupby("role")["peak"].transform("size").to_numpy()
    a = alpha / (np.maximum(tab["bins"].to_numpy(), 1) * ntests)
    tab["threshold"] = 1.0 - a ** (1.0 / np.maximum(tab["segments"].to_numpy() - 1, 1))
    tab["significant"] = tab["peak"] > tab["threshold"]
    return tab[cols], curves


def whiteness_table(time: pd.DataFrame, outputs, test_rate_hz: float = 5.0, alpha: float = 0.01) -> pd.DataFrame:
    """Ljung-Box at the test rate for every maneuver and output; ``white`` uses the Bonferroni bound per role."""
    rows = []
    for name in dict.fromkeys(time["maneuver"]):
        m = time[time["maneuver"] == name]
        k = decimation(m["t"].to_numpy(), test_rate_hz)
        for o in outputs:
            e = m[f"res_{o}"].to_numpy(dtype=float)
            lb = ljung_box(e[::k])
            r1_full = autocorrelation(e[np.isfinite(e)], 1)[1] if np.isfinite(e).sum() > 2 else float("nan")
            rows.append({"maneuver": name, "role": m["role"].iloc[0], "output": o, "n": lb["n"], "lags": lb["lags"],
                         "Q": lb["Q"], "p": lb["p"], "r1_test_rate": lb["r1"], "r1_full_rate": float(r1_full),
                         "rms": float(np.sqrt(np.mean(e[np.isfinite(e)] ** 2))) if np.isfinite(e).any() else np.nan,
                         "mean": float(np.mean(e[np.isfinite(e)])) if np.isfinite(e).any() else np.nan})
    return with_bound(pd.DataFrame(rows), alpha)


def with_bound(tab: pd.DataFrame, alpha: float) -> pd.DataFrame:
    """``white`` and ``bound`` columns of a whiteness table: Bonferroni over the tests of each role."""
    if tab.empty:
        return tab
    tab = tab.reset_index(drop=True)
    tab["white"] = True
    for role, g in tab.groupby("role"):
        bound = alpha / max(int(g["p"].notna().sum()), 1)
        tab.loc[g.index, "white"] = ~(g["p"] < bound)
        tab.loc[g.index, "bound"] = bound
    return tab


def _rate(x, t):
    return np.gradient(x, t) if len(t) > 2 else np.zeros_like(x)


def time_regressors(m: pd.DataFrame) -> dict:
    """Physically meaningful regressors of one maneuver (SI): model flight state and measured inputs."""
    t = m["t"].to_numpy(dtype=float)
    out = {}
    if "model_TAS" in m:
        out["V"] = m["model_TAS"].to_numpy(dtype=float)
    for name, col in (("mu", "model_mu"), ("chi", "model_chi"), ("lambda_i", "model_lambda_i"), ("q", "model_q"),
                      ("theta", "model_theta")):
        if col in m:
            out[name] = m[col].to_numpy(dtype=float)
    if "model_q" in m:
        out["dq/dt"] = _rate(m["model_q"].to_numpy(dtype=float), t)
    for c in ("col", "lon"):
        if f"in_{c}" in m:
            u = m[f"in_{c}"].to_numpy(dtype=float)
            out[f"d{c}"] = u - u[0]
            out[f"d{c}/dt"] = _rate(u, t)
    return out


def _pearson(x, y) -> tuple[float, float, int]:
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    n = len(x)
    if n < 4 or np.std(x) == 0 or np.std(y) == 0:
        return float("nan"), float("nan"), n
    r, p = stats.pearsonr(x, y)
    return float(r), float(p), n


def correlation_table(time: pd.DataFrame, trim: pd.DataFrame, outputs, trim_channels,
                      test_rate_hz: float = 5.0) -> pd.DataFrame:
    """Pearson r of residuals with regressors: time (pooled per role, at the test rate) and trim."""
    rows = []
    for role in dict.fromkeys(time["role"]) if len(time) else []:
        pooled: dict = {}
        res: dict = {o: [] for o in outputs}
        for name in dict.fromkeys(time.loc[time["role"] == role, "maneuver"]):
            m = time[time["maneuver"] == name]
            k = decimation(m["t"].to_numpy(), test_rate_hz)
            for reg, x in time_regressors(m).items():
                pooled.setdefault(reg, []).append(x[::k])
            for o in outputs:
                res[o].append(m[f"res_{o}"].to_numpy(dtype=float)[::k])
        for o in outputs:
            y = np.concatenate(res[o])
            for reg, xs in pooled.items():
                x = np.concatenate(xs)
                if len(x) != len(y):
                    continue
                r, p, n = _pearson(x, y)
                rows.append({"kind": "time", "role": role, "channel": o, "regressor": reg, "r": r, "p": p, "n": n})
    if len(trim):
        regs = {"V": trim["V"].to_numpy(dtype=float)}
        for name in ("mu", "chi", "lambda_i", "theta"):
            col = f"model_{name}"
            if col in trim:
                regs[name] = trim[col].to_numpy(dtype=float)
        for c in trim_channels:
            y = trim[f"res_{c}"].to_numpy(dtype=float)
            for reg, x in regs.items():
                r, p, n = _pearson(x, y)
                rows.append({"kind": "trim", "role": "identification", "channel": c, "regressor": reg, "r": r,
                             "p": p, "n": n})
    return pd.DataFrame(rows, columns=["kind", "role", "channel", "regressor", "r", "p", "n"])
