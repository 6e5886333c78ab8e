"""Do the measured inputs miss a signal of the flight (diagnosis/input_path.py)?

The stepwise regression is checked on rows built by hand (a known column found, pure noise leaves nothing at the
family-wise level), its corrected least squares on an exact linear Gaussian model (every z standard normal); on the
bundled flight test the exact model at the true parameters passes it, and a cross-feed of collective into the cyclic
that the recorder does not see (written here, on the records) is found with its gain.
"""
from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pyomo_heli.config import load_identification_config
from pyomo_heli.diagnosis.analysis import Diagnosis, diagnose
from pyomo_heli.diagnosis.input_path import SIGNALS, InputPathTest, input_path_test, play, play_signal, zone_signal
from pyomo_heli.diagnosis.residuals import compute_residuals
from pyomo_heli.flighttest.generate import truth_model_of

ROOT = Path(__file__).resolve().parent.parent
EIV = ROOT / "tests" / "configs" / "close_loop_eiv.toml"
MANEUVERS = ["col3211_80kt_a", "col3211_80kt_b", "lon3211_80kt_a", "lon3211_80kt_b", "coldoublet_20kt",
             "londoublet_20kt_a", "coldoublet_hover", "londoublet_hover_a"]
#: the cross-feed the test writes into the records: the rotor saw lon + K_MIX (col - col at t = 0)
K_MIX = 0.05


def _blocks(rng, gain: float, records: int = 6, rows: int = 120, terms: int = 14):
    labels = [(c, s) for c in ("col", "lon") for s in SIGNALS][:terms]
    out = []
    for _ in range(records):
        D = rng.normal(size=(rows, terms))
        e = gain * D[:, 3] + rng.normal(size=rows)
        out.append({"DtD": D.T @ D, "Dte": D.T @ e, "ete": float(e @ e), "B": np.zeros((terms, terms)),
                    "b": np.zeros(terms), "rows": rows, "nuisance": 0, "labels": labels})
    return out


def test_the_stepwise_regression_finds_a_known_column_and_its_gain():
    rng = np.random.default_rng(20261130)
    t = input_path_test(_blocks(rng, 0.3))
    assert [(x["channel"], x["signal"]) for x in t.terms] == [("col", "theta")], t.terms
    est = t.terms[0]
    assert abs(est["estimate"] - 0.3) < 3 * est["se"] and est["se"] == pytest.approx(1 / np.sqrt(720), rel=0.15)
    assert t.level == pytest.approx(0.01 / 14) and t.scale == pytest.approx(1.0, abs=0.1)
    assert not t.consistent and f"col += {est['estimate']:+.3g} +- {est['se']:.2g} x theta" in t.describe()
    assert InputPathTest.from_dict(t.to_dict()) == t


def test_on_noise_the_false_alarm_rate_is_within_the_level():
    """Bonferroni over the dictionary: on pure noise a term is selected in at most alpha of the cases (0.01; 400
    seeded cases, binomial 99.9 % bound 10)."""
    rng = np.random.default_rng(7)
    hits = sum(not input_path_test(_blocks(rng, 0.0, records=2, rows=60)).consistent for _ in range(400))
    assert hits <= 10, hits


def _linear_record(rng, n: int = 40, n_out: int = 2, m: int = 20):
    """One record of an exact linear Gaussian model: ``m`` rows of ``n_out`` outputs respond to 2 x ``n`` input
    samples through ``Su``; the dictionary's signals are the two measured inputs and a "model" signal, each carrying
    the input noise through its own map (the measured inputs: the identity)."""
    from scipy.linalg import cholesky

    t = np.linspace(0.0, 8.0, n)
    Su = rng.normal(size=(m * n_out, 2 * n)) * 0.3
    var_u, R = np.full(2 * n, 0.25), np.full(m * n_out, 1.0)
    L = cholesky((Su * var_u) @ Su.T + np.diag(R), lower=True)
    N = np.zeros((m * n_out, n_out))
    for j in range(n_out):
        N[j::n_out, j] = 1.0
    clean = {"col": np.sin(t), "lon": np.cos(0.7 * t), "q": np.sin(1.3 * t + 0.4)}
    noise = {"col": np.hstack([np.eye(n), np.zeros((n, n))]), "lon": np.hstack([np.zeros((n, n)), np.eye(n)]),
             "q": rng.normal(size=(n, 2 * n)) * 0.2}
    return t, Su, var_u, R, L, N, clean, noise


def _first_z(rng, records, corrected: bool, draws: int) -> dict:
    """Every term's first-step z over ``draws`` noise draws of the ``records``; the signals' noise maps given to
    :func:`record_block` (``corrected``) or zero (plain least squares)."""
    from pyomo_heli.diagnosis.input_path import record_block

    out: dict = {}
    for _ in range(draws):
        blocks = []
        for t, Su, var_u, R, L, N, clean, noise in records:
            du = np.sqrt(var_u) * rng.normal(size=len(var_u))
            e = -(Su @ du) + np.sqrt(R) * rng.normal(size=len(R))  # data - model: the replay saw clean + du
            signals = {k: (clean[k] + noise[k] @ du, noise[k] if corrected else 0.0 * noise[k]) for k in clean}
            blocks.append(record_block(e, Su, N, L, signals, ["col", "lon"], var_u, t))
        for f in input_path_test(blocks).first:
            out.setdefault(f"{f['channel']} x {f['signal']}", []).append(f["z"])
    return out


def test_record_block_corrected_least_squares_gives_standard_normal_z_on_an_exact_linear_model():
    """Analytic truth: with the sensitivities exact and every noise Gaussian, each term's z is N(0, 1) when the
    signals' share of the input noise is taken out (mean within 4.3 standard errors of 0 over 300 draws, sd within
    15 %). Without the correction the measured-input terms are biased (the same input noise is in the regressor and
    in the residual), which shows the check has power."""
    rng = np.random.default_rng(3)
    records = [_linear_record(rng) for _ in range(3)]
    z = {k: np.array(v) for k, v in _first_z(rng, records, True, 300).items()}
    assert len(z) == 6
    for k, v in z.items():
        assert abs(v.mean()) < 0.25 and 0.85 < v.std(ddof=1) < 1.15, (k, v.mean(), v.std(ddof=1))
    plain = {k: np.mean(v) for k, v in _first_z(rng, records, False, 100).items()}
    assert plain["col x col"] < -2.0 and plain["lon x lon"] < -2.0, plain


def _residuals(dataset: Path, family: str = "standard"):
    cfg = load_identification_config(EIV, overrides={"data": {"dataset": str(dataset)},
                                                     "diagnosis": {"input_path_family": family}})
    model = truth_model_of(dataset)
    cfg = dataclasses.replace(cfg, maneuvers=list(MANEUVERS), validation=[], model=model)
    return compute_residuals(cfg, model.parameters.to_dict(), label="truth", trim_sensitivities=False)


# CI time: the extended family's play widths are in the default run through the free-play test below
@pytest.mark.parametrize("family, signals", [("standard", 7), pytest.param("extended", 11, marks=pytest.mark.slow)])
def test_the_exact_model_leaves_the_input_errors_white(family, signals):
    """Either dictionary: the standard one (7 signals per input channel) or the extended one (each input's free
    play and dead zone too)."""
    d = diagnose(_residuals(ROOT / "data" / "bo105_synthetic", family))
    assert d.input_path["consistent"] and d.verdict["input_path_consistent"], d.input_path
    assert d.input_path["records"] == len(MANEUVERS) and len(d.input_path["screen"]) == 2 * signals
    assert len(SIGNALS) == 11 and bool(d.input_path["play_widths"]) == (family == "extended")
    assert not any(f.startswith("input path") for f in d.findings)


# slow (52 s; CI time): the default run has the exact model's input path on the bundled records and the
# corrected sums' N(0, 1) on an exact linear model (both above)
@pytest.mark.slow
def test_the_parameter_shift_leaves_the_corrected_sums_unbiased_on_the_exact_model():
    """Analytic truth: with the model exact and the noise model holding (data = the replay of the clean inputs plus
    white output noise; recorded inputs = clean plus white noise, four times the sensor's to make any bias plain),
    corrected least squares has E[D^T e - b] = 0 for every term, with a parameter shift among the nuisance. The
    parameter columns driven by the measured inputs carried the input noise's response and broke it (here E over sd
    +1.52 for lon x lon); driven by the inputs less their conditional mean error they do not (every term within
    0.24 of zero)."""
    from pyomo_heli.dataset import load_flight_test
    from pyomo_heli.diagnosis.innovations import maneuver_innovations
    from pyomo_heli.nlp.identification import prepare_data
    from pyomo_heli.physics.model import HelicopterModel
    from pyomo_heli.simulation.compiled import simulate_outputs
    from pyomo_heli.simulation.trim import trim_float
    from pyomo_heli.units import DEG

    ft = load_flight_test(ROOT / "data" / "bo105_clean")  # generated by HelicopterModel() itself, no noise
    mv = next(m for m in prepare_data(ft, "identification", resample_hz=25, input_reference_s=1.9,
                                      resample_inputs="sample").maneuvers if m.name == "lon3211_80kt_a")
    model, outs = HelicopterModel(), ["q", "theta", "n_x", "n_z", "TAS"]
    sig = {"q": 0.2 * DEG, "theta": 0.1 * DEG, "n_x": 0.005, "n_z": 0.01, "TAS": 0.5, "col": 0.08 * DEG,
           "lon": 0.08 * DEG}
    t = mv.data["t"].to_numpy(float)
    y = simulate_outputs(model, trim_float(model, mv.trim_speed), t, mv.increments(), outs, 2)
    rng = np.random.default_rng(1)
    H = []
    for _ in range(60):
        df = mv.data.copy()
        for o in outs:
            df[o] = np.asarray(y[o], float) + rng.normal(0, sig[o], len(df))
        for c in ("col", "lon"):
            df[c] = df[c].to_numpy(float) + rng.normal(0, sig[c], len(df))
        path = []
        maneuver_innovations(model, dataclasses.replace(mv, data=df), outs, ["col", "lon"], sig, 5.0, 2, path,
                             ["theta_twist", "CL_alpha_HT", "Iyy"])
        H.append(path[0]["Dte"] - path[0]["b"])
    H = np.array(H)  # every term, 14 columns
    ratio = H.mean(axis=0) / H.std(axis=0, ddof=1)
    assert np.all(np.abs(ratio) < 0.6) and abs(ratio.mean()) < 0.15, ratio


@pytest.fixture(scope="module")
def cross_feed(tmp_path_factory):
    """The bundled flight test whose recorded cyclic misses K_MIX times the collective's change (the rotor flew it,
    the recorder did not see it); nothing else changed."""
    ds = tmp_path_factory.mktemp("data") / "bo105_synthetic"
    shutil.copytree(ROOT / "data" / "bo105_synthetic", ds)
    for name in MANEUVERS:
        f = ds / "maneuvers" / f"{name}.csv"
        df = pd.read_csv(f)
        col = df["col_deg"].rolling(11, center=True, min_periods=1).mean()  # the pilot's input, not the noise
        df["lon_deg"] -= K_MIX * (col - col.iloc[0])
        df.to_csv(f, index=False)
    return _residuals(ds)


def test_a_cross_feed_the_recorder_misses_is_found_with_its_gain(cross_feed, tmp_path):
    d = diagnose(cross_feed)
    assert not d.verdict["input_path_consistent"] and not d.verdict["noise_only"]
    first = d.input_path["terms"][0]
    assert (first["channel"], first["signal"]) == ("lon", "col"), d.input_path["terms"]
    assert abs(first["estimate"] - K_MIX) < 3 * first["se"] and first["se"] < 0.2 * K_MIX, first
    assert any(f.startswith("input path: the input errors follow the flight: lon += +0.05") for f in d.findings)
    # the result is plain data: it saves, loads and prints
    again = Diagnosis.load(d.save(tmp_path / "d.json"))
    assert again.input_path == d.input_path and "Input path" in str(again)
    from pyomo_heli.report.diagnosis import write_diagnosis_report

    text = write_diagnosis_report(tmp_path, cross_feed, d).read_text()
    assert "### Input path" in text and "| selected | lon | col |" in text
    assert "![input errors](diagnosis_input_path.png)" in text and (tmp_path / "diagnosis_input_path.png").is_file()
    # the figure's histories: the records the selected term moves most are the collective ones, and where the
    # cyclic's error is observable (in forward flight; at hover a slow error drifts unconstrained) what the residual
    # asks of the cyclic, with no dictionary, follows the fitted term
    h = {x["maneuver"]: x for x in d.input_path["histories"]}
    assert len(h) == 3 and all(m.startswith("col") for m in h), list(h)
    for m in ("coldoublet_20kt", "col3211_80kt_a"):
        assert np.corrcoef(h[m]["asked_lon"], h[m]["fitted_lon"])[0, 1] > 0.5, m


def test_level_study_counts_a_seed_below_a_level_by_its_adjusted_smallest_p():
    """pyomo_heli.studies.input_path_level: a seed is below a level when its first step's smallest p times the
    dictionary size is; per term, the first step's z (mean, sd) and p shares over the seeds."""
    from pyomo_heli.studies.input_path_level import below, summary

    def doc(p_col, z_col, p_lon=0.5):
        return {"alpha": 0.01, "terms": 14, "selected": [], "first step smallest p": min(p_col, p_lon),
                "first step": {"col x col_rate": {"estimate": 0.0, "se": 1.0, "z": z_col, "p": p_col},
                               "lon x col": {"estimate": 0.0, "se": 1.0, "z": 0.0, "p": p_lon}}}
    quiet = doc(0.003, 3.0)  # adjusted 0.042
    assert [below(quiet, a) for a in (0.01, 0.05, 0.1)] == [False, True, True]
    assert [below(doc(1e-5, 4.4), a) for a in (0.01, 0.05, 0.1)] == [True, True, True]
    tab = summary([quiet, doc(1e-5, 4.4), doc(0.5, -0.7), doc(0.005, 2.8)]).set_index("term")
    assert tab.loc["col x col_rate", "mean z"] == pytest.approx((3.0 + 4.4 - 0.7 + 2.8) / 4)
    assert tab.loc["col x col_rate", "p < 0.01 [%]"] == 75.0 and tab.loc["lon x col", "p < 0.05 [%]"] == 0.0
    assert list(tab.loc["any (smallest p x terms)", ["p < 0.01 [%]", "p < 0.05 [%]", "p < 0.1 [%]"]]) == \
        [25.0, 50.0, 75.0]


def test_level_study_writes_each_seed_and_resumes(tmp_path):
    """The level study (pyomo_heli.studies.input_path_level) on one seed of the small held-out flight test (three
    records), M0 + noise at the true parameters: the 14-term dictionary at alpha 0.01, the seed's data removed once it
    is done, a rerun reads the seed back, and a rerun with another input resampling makes it again."""
    import json

    from pyomo_heli.studies.input_path_level import main

    argv = ["--seeds", "7", "--config", str(ROOT / "studies" / "held_out_small.toml"),
            "--data-config", str(ROOT / "studies" / "held_out_small_gen.toml"), "--out", str(tmp_path)]
    assert main(argv) == 0
    doc = json.loads((tmp_path / "seed_7.json").read_text())
    assert doc["records"] == 3 and doc["terms"] == 14 and doc["alpha"] == 0.01 and not doc["problems"]
    assert len(doc["first step"]) == 13 and 0.0 < doc["first step smallest p"] <= 1.0  # one term not fittable here
    assert doc["first step smallest p"] == min(r["p"] for r in doc["first step"].values())
    assert not (tmp_path / "data").exists()
    assert list(pd.read_csv(tmp_path / "summary.csv")["term"])[-1] == "any (smallest p x terms)"
    (tmp_path / "seed_7.json").write_text(json.dumps({**doc, "records": 99}))
    assert main(argv) == 0 and "(99 records each" in (tmp_path / "summary.md").read_text()
    # --resample-inputs replaces the config's [data] resample_inputs (projected here): the seed is made again with
    # the inputs picked, its replay differs, and the summary says how the inputs were resampled
    assert main([*argv, "--resample-inputs", "sample"]) == 0
    picked = json.loads((tmp_path / "seed_7.json").read_text())
    assert picked["overrides"] == {"data": {"resample_inputs": "sample"}} and picked["records"] == 3
    terms = sorted(set(doc["first step"]) & set(picked["first step"]))
    assert len(terms) >= 10
    assert [picked["first step"][t]["z"] for t in terms] != pytest.approx([doc["first step"][t]["z"] for t in terms])
    assert "inputs resampled by 'sample'" in (tmp_path / "summary.md").read_text()


#: the bundled sensor sigmas, given to the noise-free records' residual analysis (their lead-ins hold no noise)
BUNDLED_SIGMA = {"q_deg_s": 0.2, "theta_deg": 0.1, "nx_g": 0.005, "nz_g": 0.01, "tas_m_s": 0.5, "beta0_deg": 0.05,
                 "col_deg": 0.02, "lon_deg": 0.02}


def _filtered_innovations(data: Path, replay: str, resample_hz: float | None = 25):
    cfg = load_identification_config(EIV, overrides={
        "data": {"dataset": str(data), "maneuvers": ["lon3211_80kt_a", "col3211_80kt_a"], "validation": [],
                 "resample_inputs": "project",
                 **({"resample_hz": resample_hz} if resample_hz else {})},
        "objectives": {"noise_sigma": BUNDLED_SIGMA}, "diagnosis": {"replay": replay}})
    if not resample_hz:
        cfg = dataclasses.replace(cfg, resample_hz=None)
    model = truth_model_of(data)
    return compute_residuals(dataclasses.replace(cfg, model=model), model.parameters.to_dict(), label="truth",
                             input_offsets=False, trim_sensitivities=False)


def test_the_replay_of_the_recorded_inputs_leaves_no_resampling_residual(tmp_path):
    """The exact model on noise-free records that went through the anti-alias filter (the generator's 10 Hz filter,
    two 80 kt 3211s at 50 Hz), fitted at 25 Hz with the inputs projected: the replay of the projected inputs leaves
    a residual that is the resampling's, not the model's (in n_z, the collective's direct thrust, 0.12 of its
    sigma); the replay driven by the recorded inputs (``[diagnosis] replay = "record"``) leaves at most a fifth of
    it in n_z, n_x, theta, TAS and beta_0. At the record's rate (no resampling) the two replays are the same."""
    from pyomo_heli.flighttest.config import load_config
    from pyomo_heli.flighttest.generate import generate

    data = generate(load_config(ROOT / "tests" / "configs" / "m0_filtered_noise_free_gen.toml"), tmp_path / "d",
                    force=True)
    rms = {}
    for replay in ("fit", "record"):
        res = _filtered_innovations(data, replay)
        assert res.info["innovations"]["replay"] == replay and not res.problems
        inn = res.innovations
        rms[replay] = {c[4:]: float(np.sqrt(np.mean(inn[c] ** 2))) for c in inn.columns if c.startswith("inn_")}
    print(rms)
    assert rms["fit"]["n_z"] > 0.05
    for o in ("n_z", "n_x", "theta", "TAS", "beta_0"):
        assert rms["record"][o] < 0.2 * rms["fit"][o], o
    same = [_filtered_innovations(data, r, resample_hz=None).innovations for r in ("fit", "record")]
    pd.testing.assert_frame_equal(same[0], same[1])


def test_diagnosis_replay_is_checked_and_keeps_the_input_noise_model():
    """``[diagnosis] replay`` takes "fit" or "record" (one line naming the field otherwise; "record" by default); a
    [diagnosis] table that gives only the replay keeps the identification's input-noise model."""
    from pyomo_heli.config import ConfigError

    with pytest.raises(ConfigError, match=r"\[diagnosis\]: field 'replay' must be \"fit\" or \"record\""):
        load_identification_config(EIV, overrides={"diagnosis": {"replay": "fine"}})
    cfg = load_identification_config(EIV, overrides={"diagnosis": {"replay": "fit"}})
    plain = load_identification_config(EIV)
    assert cfg.diagnosis_settings.replay == "fit" and plain.diagnosis_settings.replay == "record"
    assert cfg.diagnosis_settings.input_noise == plain.diagnosis_settings.input_noise != ()


def test_the_play_operator_follows_a_known_sequence():
    """Analytic: width 1, the follower starts on the input, moves only when pushed half the width away and keeps
    its side when the input reverses within the play."""
    p, j = play(np.array([0.0, 1.0, 2.0, 1.9, 1.5, 0.0, 0.5]), 1.0)
    assert p.tolist() == [0.0, 0.5, 1.5, 1.5, 1.5, 0.5, 0.5] and j.tolist() == [0, 1, 2, 2, 2, 5, 5]


@pytest.mark.parametrize("signal", [play_signal, zone_signal])
def test_the_play_and_dead_zone_noise_maps_are_their_exact_linearisation(signal):
    """The map of the input's sample errors into the signal (what corrected least squares takes out) against
    central differences of the signal itself, on ramps and holds whose switching a small change does not move."""
    t = np.arange(0.0, 8.0, 0.04)
    u = np.radians(np.interp(t, [0, 2, 2.3, 4, 4.6, 6, 6.2, 8], [0, 0, 1, 1, -1, -1, -0.05, -0.05]))
    w = np.radians(0.12)
    x, A = signal(t, u, w)
    rng = np.random.default_rng(5)
    du = rng.normal(0, 1e-7, len(t))
    fd = (signal(t, u + du, w)[0] - signal(t, u - du, w)[0]) / 2
    assert np.abs(x).max() == pytest.approx(w / 2) and np.allclose(fd, A @ du, atol=1e-12), np.abs(fd - A @ du).max()


def _records_with(tmp_path_factory, stick_minus_rotor):
    """The bundled flight test whose recorded cyclic is the pilot's stick where the rotor flew the recorded one:
    ``stick_minus_rotor(r)`` of the rotor's cyclic increment r (the recorded one smoothed: the pilot's input, not
    the noise) [deg], added to the record; nothing else changed."""
    ds = tmp_path_factory.mktemp("data") / "bo105_synthetic"
    shutil.copytree(ROOT / "data" / "bo105_synthetic", ds)
    for name in MANEUVERS:
        f = ds / "maneuvers" / f"{name}.csv"
        df = pd.read_csv(f)
        r = df["lon_deg"].rolling(11, center=True, min_periods=1).mean().to_numpy()
        df["lon_deg"] += stick_minus_rotor(r - r[:50].mean())
        df.to_csv(f, index=False)
    return _residuals(ds, "extended")


#: half the play or dead band the tests write into the control path [deg]: the stick moves this much before the
#: rotor follows
H_DEG = 0.05


#: how far the rotor's input must move before the tests' pilot is taken to move the stick [deg] (the smoothed
#: recorded noise is 0.006 deg)
MOVE_DEG = 0.05


def _dead_zone_stick(r):
    """The stick of a dead band of half-width H_DEG about the trim: beyond MOVE_DEG from it the stick leads the
    rotor by H_DEG away from the trim; closer, the pilot holds the trim and the rotor's input is its noise."""
    return H_DEG * np.sign(r) * (np.abs(r) > MOVE_DEG)


def _free_play_stick(r):
    """The stick of a free play of H_DEG either side: it leads the rotor by H_DEG in the direction the rotor's input
    last moved (by MOVE_DEG from its extreme since the last turn), and crosses the play at once on a turn."""
    d, ext, out = 0.0, r[0], np.zeros_like(r)
    for k in range(len(r)):
        if d >= 0 and r[k] < ext - MOVE_DEG or d <= 0 and r[k] > ext + MOVE_DEG:
            d, ext = (-1.0 if r[k] < ext else 1.0), r[k]
        ext = max(ext, r[k]) if d > 0 else min(ext, r[k]) if d < 0 else ext
        out[k] = H_DEG * d
    return out


# CI time: the free play in the default run, the dead zone (same search, another shape) with --runslow
@pytest.mark.parametrize("stick, signal", [pytest.param(_dead_zone_stick, "lon_zone", marks=pytest.mark.slow),
                                           (_free_play_stick, "lon_play")])
def test_a_control_path_nonlinearity_the_recorder_misses_is_found(tmp_path_factory, stick, signal):
    """Known truth: a dead band or a free play in the cyclic's path, written into the records (the rotor flew the
    bundled inputs, the recorder saw the stick). The input path selects its own signal first, with the play's
    size: the error is -H_DEG in the direction of the stick's lead, the signal -(w / 2) there (w: its operator's
    width), so the estimate is about 2 H_DEG / w."""
    d = diagnose(_records_with(tmp_path_factory, stick))
    first = d.input_path["terms"][0]
    assert (first["channel"], first["signal"]) == ("lon", signal), d.input_path["terms"]
    expected = 2 * np.radians(H_DEG) / d.input_path["play_widths"]["lon"]
    print(signal, first, "expected about", expected)
    assert first["z"] > 5 and abs(first["estimate"] / expected - 1) < 0.1, (first, expected)
