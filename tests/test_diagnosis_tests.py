"""The statistical tests of the residual diagnosis on constructed residuals with known structure.

Every case is generated here with a seeded random stream and a known truth
(noise only, an offset, a V^2 trend, a Gaussian low-speed bump, a coloured
series, an input response), so each verdict is checked against what was put in.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import signal

from pyomo_heli.diagnosis.timeseries import (coherence_table, ljung_box, remove_nuisance, spectra,
                                             whiteness_table)
from pyomo_heli.diagnosis.trim_shape import V_REF, bump_basis, runs_test, shape_curve, trim_shape_test
from pyomo_heli.units import DEG, KT

#: the trim speeds of the bundled data: 14 level points and 10 maneuver start points [kt]
SPEEDS_KT = [10, 15, 20, 25, 30, 40, 50, 60, 70, 80, 90, 100, 110, 120, 80, 80, 80, 80, 20, 20, 20, 0, 0, 0]
V = np.array(SPEEDS_KT, float) * KT
SIGMA = 0.07 * DEG  # trim noise of the synthetic data (0.05 deg + 0.05 deg offset)


@pytest.mark.parametrize("truth, signal_fn", [
    ("noise", lambda v: 0 * v),
    ("constant", lambda v: 0 * v + 0.3 * DEG),
    ("V^2", lambda v: 0.4 * DEG * (v / V_REF) ** 2),
    ("bump", lambda v: -0.5 * DEG * bump_basis(v, 30 * KT, 10 * KT)),
])
def test_trim_shape_names_the_shape_that_was_put_in(truth, signal_fn):
    hits = 0
    for seed in range(10):
        e = signal_fn(V) + np.random.default_rng(100 + seed).normal(0, SIGMA, len(V))
        t = trim_shape_test(V, e, "lon", n_mc=1000, seed=seed)
        hits += t.shape == truth
        if truth == "noise":
            assert not t.structured
    assert hits >= 8, f"{truth}: named correctly in {hits}/10 noisy draws"


def test_bump_fit_recovers_centre_and_amplitude():
    truth = -0.6 * DEG * bump_basis(V, 35 * KT, 10 * KT)
    e = truth + np.random.default_rng(7).normal(0, SIGMA, len(V))
    t = trim_shape_test(V, e, "theta", n_mc=1000)
    assert t.shape == "bump"
    assert abs(t.fit["centre"] / KT - 35) <= 5
    assert t.fit["amplitude"] == pytest.approx(-0.6 * DEG, rel=0.3)
    # the fitted curve is the bump that was put in, to within the noise, and what it leaves is the noise
    assert np.max(np.abs(shape_curve(t, V) - truth)) < 2 * SIGMA
    assert t.rms_after == pytest.approx(np.sqrt(np.mean((e - shape_curve(t, V)) ** 2)), rel=1e-12)
    assert t.rms_after == pytest.approx(SIGMA, rel=0.3)


def test_runs_test_counts_runs():
    r = runs_test([1, 1, 1, -1, -1, -1, 1, 1, 1, -1, -1, -1])
    assert r["runs"] == 4 and r["expected"] == pytest.approx(7.0)
    assert r["z"] < 0


def test_ljung_box_passes_white_noise_and_rejects_ar1():
    rng = np.random.default_rng(3)
    white = rng.standard_normal(300)
    ar = signal.lfilter([1.0], [1.0, -0.6], rng.standard_normal(300))
    assert ljung_box(white)["p"] > 0.01
    assert ljung_box(ar)["p"] < 1e-6
    assert ljung_box(ar)["r1"] == pytest.approx(0.6, abs=0.1)


def _maneuver(name, res_q, inp, t, dres=None):
    df = pd.DataFrame({"maneuver": name, "role": "identification", "trim_speed": 40.0, "t": t,
                       "in_col": 0.1 + 0 * t, "in_lon": inp, "res_q": res_q})
    if dres is not None:
        df["dres_q_dlon"] = dres
        df["dres_q_dcol"] = np.sin(0.3 * t)  # a second, unused offset response
    return df


def test_coherence_flags_a_residual_driven_by_the_input_and_not_an_unrelated_one():
    fs = 25.0
    t = np.arange(0, 15, 1 / fs)
    rng = np.random.default_rng(11)
    u = signal.lfilter(*signal.butter(2, 3.0, fs=fs), rng.standard_normal(len(t))) * 0.01  # broadband input
    driven = signal.lfilter(*signal.butter(1, 1.5, fs=fs), u) + rng.normal(0, 2e-4, len(t))
    unrelated = rng.normal(0, 1e-3, len(t))
    time = pd.concat([_maneuver("driven", driven, u, t), _maneuver("unrelated", unrelated, u, t)], ignore_index=True)
    tab, curves = coherence_table(time, ["q"], {"driven": ["lon"], "unrelated": ["lon"]})
    sig = dict(zip(tab["maneuver"], tab["significant"]))
    assert sig == {"driven": True, "unrelated": False}
    assert "lon:q" in curves["driven"]


@pytest.mark.parametrize("n", [126, 250, 251, 256, 375])
def test_coherence_counts_the_welch_segments_scipy_averages(n):
    """The threshold's segment count is the number of segments scipy's Welch average uses (the time axis of
    scipy.signal.spectrogram with the same segment and Welch's default overlap, nperseg // 2). An odd segment
    (n = 126: nperseg 63, a record shorter than 128 samples) was counted one segment too many."""
    fs = 25.0
    t = np.arange(n) / fs
    rng = np.random.default_rng(n)
    u = rng.normal(size=n)
    tab, _ = coherence_table(pd.concat([_maneuver("m", rng.normal(size=n), u, t)]), ["q"], {"m": ["lon"]})
    nps = min(2 ** int(round(np.log2(4 * fs))), n) // 2  # the coherence's segment: half the spectra's 4 s
    assert tab["segments"].iloc[0] == len(signal.spectrogram(u, fs=fs, nperseg=nps, noverlap=nps // 2)[1])


def test_nuisance_removal_recovers_a_constant_input_offset_and_whitens():
    fs = 25.0
    t = np.arange(0, 12, 1 / fs)
    rng = np.random.default_rng(5)
    dres = 1.0 - np.exp(-t / 2.0)  # response of q to a unit lon offset (a slow step response)
    noise = rng.normal(0, 1e-3, len(t))
    e = 0.02 * dres + 0.003 + noise
    m = _maneuver("m", e, 0 * t, t, dres)
    cleaned, est = remove_nuisance(m, ["q"])
    assert est["offset_lon"] == pytest.approx(0.02, abs=2e-3)
    assert ljung_box(e[::5])["p"] < 1e-6 and ljung_box(cleaned["q"][::5])["p"] > 0.01


def test_whiteness_table_bonferroni_and_spectra_band_ratio():
    fs = 25.0
    t = np.arange(0, 15, 1 / fs)
    rng = np.random.default_rng(9)
    white = rng.normal(0, 1e-3, len(t))
    slow = white + 5e-3 * np.sin(2 * math.pi * 0.4 * t)
    time = pd.concat([_maneuver("white", white, 0 * t, t), _maneuver("slow", slow, 0 * t, t)], ignore_index=True)
    w = whiteness_table(time, ["q"])
    assert dict(zip(w["maneuver"], w["white"])) == {"white": True, "slow": False}
    assert w["bound"].iloc[0] == pytest.approx(0.01 / 2)
    sp = spectra(time[time["maneuver"] == "white"], ["q"], "identification")
    assert sp["band_ratio"]["q"] == pytest.approx(1.0, abs=0.6)
    sp = spectra(time[time["maneuver"] == "slow"], ["q"], "identification")
    assert sp["band_ratio"]["q"] > 10


def test_trim_nuisance_leaves_out_parameters_that_do_not_act_on_trims():
    from pyomo_heli.diagnosis.analysis import trim_nuisance
    from pyomo_heli.diagnosis.residuals import Residuals

    trim = pd.DataFrame({"V": V, "res_lon": 0 * V, "dres_lon_dtheta_twist": (V / V_REF) ** 2 * 0.1,
                         "dres_lon_dtau_b": 1e-12 + 0 * V})  # a time constant: finite-difference noise only
    r = Residuals(label="x", parameters={"theta_twist": -0.028, "tau_b": 0.05}, time=pd.DataFrame(), trim=trim)
    S, names = trim_nuisance(r, "lon")
    assert names == ["theta_twist"] and S.shape == (len(V), 1)
    assert trim_nuisance(r, "theta") == (None, [])


def test_diagnosis_records_keep_small_p_values(tmp_path):
    """pandas' to_json writes 2.2e-11 as 0.0; the diagnosis' records must keep it (and NaN as None)."""
    import json

    from pyomo_heli.diagnosis.analysis import _records

    df = pd.DataFrame({"p": [2.2359e-11, 1e-300, 0.5, float("nan")], "white": np.array([False, False, True, True]),
                       "n": np.array([76, 76, 76, 3], dtype=np.int64)})
    recs = json.loads(json.dumps(_records(df)))
    assert [r["p"] for r in recs] == [2.2359e-11, 1e-300, 0.5, None]
    assert [r["white"] for r in recs] == [False, False, True, True] and recs[0]["n"] == 76


def test_a_small_alpha_can_still_find_a_trim_shape():
    """A 1 deg lon offset at 20 times the trim noise: structured at alpha 0.01 and at alpha 0.0005 alike. The Monte
    Carlo p cannot fall below 1 / (n_mc + 1), so with 4000 draws and four shapes any alpha below 0.001 put the
    Bonferroni level under the smallest p and called every residual noise (a review); the draws now follow alpha."""
    e = 1.0 * DEG + np.random.default_rng(0).normal(0, 0.05 * DEG, len(V))
    for alpha in (0.01, 0.0005):
        t = trim_shape_test(V, e, "lon", alpha=alpha, n_mc=4000)
        assert t.structured, (alpha, t.p_values)
        assert min(t.p_values.values()) < alpha / len(t.p_values)
