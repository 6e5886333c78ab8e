"""Innovations: the whiteness test with the measured inputs' noise taken out (diagnosis/innovations.py).

Checked on the bundled synthetic flight test (data from the truth simulator at 400 Hz with filtered sensor
noise, independent of the float model and of the whitening): the *exact* model at the true parameters
leaves residuals that the plain whiteness test calls coloured (the input noise drives the replay), while
their innovations are white with unit variance; a model that lacks the truth's wake effect still fails.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from pyomo_heli.config import load_identification_config
from pyomo_heli.diagnosis.analysis import diagnose
from pyomo_heli.diagnosis.residuals import Residuals, compute_residuals
from pyomo_heli.flighttest.generate import truth_model_of

ROOT = Path(__file__).resolve().parent.parent
EIV = ROOT / "tests" / "configs" / "close_loop_eiv.toml"
FAST = ["lon3211_80kt_a", "lon3211_80kt_b"]  # where the exact model's raw theta residual is coloured
SLOW = ["londoublet_20kt_a", "londoublet_20kt_b"]  # where the wake acts in the time series


def _cfg(maneuvers, model=None, input_errors=True):
    cfg = load_identification_config(EIV)
    nlp = cfg.nlp if input_errors else dataclasses.replace(cfg.nlp, input_errors=())
    return dataclasses.replace(cfg, maneuvers=list(maneuvers), validation=[], model=model or cfg.model, nlp=nlp)


def _truth(cfg):
    model = truth_model_of(cfg.dataset)
    return model, model.parameters.to_dict()


@pytest.fixture(scope="module")
def exact():
    """Residuals of the truth model at the true parameters on two 80 kt 3-2-1-1s, with the input errors."""
    model, params = _truth(_cfg(FAST))
    return compute_residuals(_cfg(FAST, model), params, label="truth", trim_sensitivities=False)


def test_exact_model_raw_residuals_are_coloured_by_the_input_noise():
    model, params = _truth(_cfg(FAST))
    cfg = dataclasses.replace(_cfg(FAST, model, input_errors=False), diagnosis=None)
    assert cfg.diagnosis_settings.input_noise == ()
    res = compute_residuals(cfg, params, label="truth", trim_sensitivities=False)
    assert res.innovations is None
    d = diagnose(res)
    bad = [w for w in d.whiteness if not w["white"]]
    assert {w["output"] for w in bad} == {"theta"} and len(bad) == 2, bad
    assert all(w["p"] < 1e-10 for w in bad)
    assert not d.verdict["noise_only"]


def test_exact_model_innovations_are_white_with_unit_variance(exact):
    d = diagnose(exact)
    assert all(w["series"] == "innovation" for w in d.whiteness)
    assert len(d.whiteness) == 12 and all(w["white"] for w in d.whiteness), d.whiteness
    assert d.verdict["noise_only"]
    # unit variance where the sigma is the sensor's own (the lead-in pools TAS over 80 kt and the
    # slower maneuvers, whose pitot noise is twice as large, so TAS is left out of this check)
    inn = exact.innovations
    for o in ("q", "theta", "n_x", "n_z", "beta_0"):
        assert 0.85 < float(np.std(inn[f"inn_{o}"])) < 1.15, o
    # test-rate samples: 200 ms apart
    t = inn.loc[inn["maneuver"] == FAST[0], "t"].to_numpy()
    assert np.allclose(np.diff(t), 0.2)


def test_innovations_still_see_a_missing_effect():
    """M0 (no wake) at the true parameters on the 20 kt doublets: the innovations are not white."""
    cfg = _cfg(SLOW)
    _, params = _truth(cfg)
    params = {k: v for k, v in params.items() if k in cfg.model.parameters}
    d = diagnose(compute_residuals(cfg, params, label="M0", trim_sensitivities=False))
    bad = [w for w in d.whiteness if not w["white"]]
    assert bad and all(w["series"] == "innovation" for w in bad)
    assert "theta" in {w["output"] for w in bad}


def test_innovations_save_and_load(exact, tmp_path):
    exact.save(tmp_path / "r")
    back = Residuals.load(tmp_path / "r")
    assert back.info["innovations"]["outputs"] == exact.info["innovations"]["outputs"]
    np.testing.assert_allclose(back.innovations["inn_theta"], exact.innovations["inn_theta"], rtol=1e-8)
    assert diagnose(back).verdict == diagnose(exact).verdict


def test_an_output_without_a_known_sigma_keeps_the_plain_test():
    """A [objectives.noise_sigma] table without beta_0: beta_0 is tested on its residual, and the problems
    say why; the other outputs on their innovations."""
    cfg = _cfg(FAST[:1])
    sig = {"q": 0.0035, "theta": 0.0017, "n_x": 0.049, "n_z": 0.098, "TAS": 0.5, "col": 3.5e-4, "lon": 3.5e-4}
    cfg = dataclasses.replace(cfg, nlp=dataclasses.replace(cfg.nlp, noise_sigma=sig))
    res = compute_residuals(cfg, {}, label="M0", trim_sensitivities=False)
    assert res.info["innovations"]["outputs"] == ["q", "theta", "n_x", "n_z", "TAS"]
    assert any("output beta_0 left out" in p and "noise_sigma has no value" in p for p in res.problems)
    series = {w["output"]: w["series"] for w in diagnose(res).whiteness}
    assert series["beta_0"] == "residual" and series["theta"] == "innovation"


OE = ROOT / "tests" / "configs" / "close_loop.toml"


def test_output_error_config_asks_for_the_innovations_with_diagnosis_input_noise():
    """An output-error identification (inputs taken as exact) with ``[diagnosis] input_noise``: the exact
    model's residuals get their innovations, and these are white (the plain test calls theta coloured,
    test_exact_model_raw_residuals_are_coloured_by_the_input_noise); ``input_noise = []``: none."""
    off = load_identification_config(OE, {"diagnosis": {"input_noise": []}})
    assert off.nlp.input_errors == () and off.diagnosis_settings.input_noise == ()
    cfg = load_identification_config(OE)  # the loop's output-error config declares [diagnosis] input_noise
    assert cfg.nlp.input_errors == () and cfg.diagnosis_settings.input_noise == ("col", "lon")
    cfg = dataclasses.replace(cfg, maneuvers=list(FAST), validation=[])
    model, params = _truth(cfg)
    res = compute_residuals(dataclasses.replace(cfg, model=model), params, label="truth", trim_sensitivities=False)
    assert res.info["innovations"]["input_errors"] == ["col", "lon"]
    d = diagnose(res)
    assert len(d.whiteness) == 12 and all(w["series"] == "innovation" and w["white"] for w in d.whiteness)
    assert d.verdict["noise_only"]


@pytest.mark.parametrize("table, message", [
    ({"input_noise": ["pedal"]}, "[diagnosis]: unknown input channel(s) ['pedal'] in input_noise"),
    ({"input_noise": ["col"], "sigma": 1}, "[diagnosis]: unknown key(s) sigma"),
    ({"input_noise": [], "noise_sigma": {"col_deg": 0.02}}, "[diagnosis]: noise_sigma is only used with input_noise"),
    ({"input_noise": ["col"], "noise_sigma": {"col_deg": -1}}, "[diagnosis.noise_sigma]: 'col_deg' must be a positive"),
])
def test_diagnosis_table_errors_name_the_field(table, message):
    from pyomo_heli.config import ConfigError

    with pytest.raises(ConfigError) as exc:
        load_identification_config(OE, {"diagnosis": table})
    assert message in str(exc.value) and "close_loop.toml" in str(exc.value)


def test_diagnosis_input_noise_needs_a_lead_in_or_sigmas():
    from pyomo_heli.config import ConfigError

    with pytest.raises(ConfigError, match=r"\[diagnosis\]: input_noise takes the noise sigmas from the records' quiet "
                                          r"lead-in; set \[data\] input_reference_s > 0"):
        load_identification_config(OE, {"data": {"input_reference_s": 0.0}, "diagnosis": {"input_noise": ["col"]}})
    cfg = load_identification_config(OE, {"data": {"input_reference_s": 0.0},
                                          "diagnosis": {"input_noise": ["col"], "noise_sigma": {"col_deg": 0.02}}})
    assert cfg.diagnosis_settings.noise_sigma["col"] == pytest.approx(np.radians(0.02))


def test_the_ar_precision_is_the_nlps_input_likelihood_and_its_inverse_the_processs_covariance():
    """``ar_precision``: e^T P e equals the sum of squared innovations the NLP's J_input takes (pre-record errors
    zero); its inverse (``input_error_covariance``) is the covariance of the AR process started from zero,
    against 20 000 simulated records (every entry within 0.04 of the unit-variance scale)."""
    from pyomo_heli.nlp.objectives import ar_precision, input_error_covariance

    rng = np.random.default_rng(11)
    a, sw, n = np.array([1.2, -0.5]), 0.3, 12
    e = rng.normal(size=n)
    w = e - a[0] * np.r_[0.0, e[:-1]] - a[1] * np.r_[0.0, 0.0, e[:-2]]
    assert e @ ar_precision(n, a, sw) @ e == pytest.approx(np.sum(w**2) / sw**2, rel=1e-12)
    sims = np.zeros((20000, n))
    innov = rng.normal(0.0, sw, (20000, n))
    for k in range(n):
        sims[:, k] = innov[:, k] + sum(a[j] * sims[:, k - 1 - j] for j in range(len(a)) if k - 1 - j >= 0)
    cov = input_error_covariance(n, ["lon"], {"lon": 1.0}, {"lon": (a, sw)})
    assert np.abs(np.cov(sims.T) - cov).max() < 0.04 * cov.max(), np.abs(np.cov(sims.T) - cov).max()
    assert input_error_covariance(n, ["col"], {"col": 0.5}).tolist() == [0.25] * n  # independent: the variances


def test_innovations_take_the_input_errors_ar_model():
    """Known truth: M0's noise-free 80 kt 3211 replayed, white output noise added and the recorded inputs' noise
    an AR(1) process (a = 0.8, 0.08 deg). The innovations whitened with that model have unit variance (mean
    square within 0.1 of 1 over 30 draws: 1.004); taken as independent errors of the same sigma they do not (1.32)."""
    from pyomo_heli.dataset import load_flight_test
    from pyomo_heli.diagnosis.innovations import maneuver_innovations
    from pyomo_heli.nlp.identification import prepare_data
    from pyomo_heli.physics.model import HelicopterModel
    from pyomo_heli.simulation.compiled import simulate_outputs
    from pyomo_heli.simulation.trim import trim_float
    from pyomo_heli.units import DEG

    ft = load_flight_test(ROOT / "data" / "bo105_clean")
    mv = next(m for m in prepare_data(ft, "identification", resample_hz=25, input_reference_s=1.9,
                                      resample_inputs="sample").maneuvers if m.name == "lon3211_80kt_a")
    model, outs = HelicopterModel(), ["q", "theta", "n_x", "n_z", "TAS"]
    a, s_u = 0.8, 0.08 * DEG
    sig = {"q": 0.2 * DEG, "theta": 0.1 * DEG, "n_x": 0.005, "n_z": 0.01, "TAS": 0.5, "lon": s_u}
    t = mv.data["t"].to_numpy(float)
    y = simulate_outputs(model, trim_float(model, mv.trim_speed), t, mv.increments(), outs, 2)
    rng = np.random.default_rng(4)
    ms = {"ar": [], "white": []}
    for _ in range(30):
        df = mv.data.copy()
        for o in outs:
            df[o] = np.asarray(y[o], float) + rng.normal(0, sig[o], len(df))
        d, w = np.zeros(len(df)), rng.normal(0, s_u * np.sqrt(1 - a**2), len(df))
        for k in range(len(df)):
            d[k] = w[k] + (a * d[k - 1] if k else 0.0)
        df["lon"] = df["lon"].to_numpy(float) + d
        noisy = dataclasses.replace(mv, data=df)
        for key, models in (("ar", {"lon": (np.array([a]), np.sqrt(1 - a**2))}), ("white", None)):
            inn, _ = maneuver_innovations(model, noisy, outs, ["lon"], sig, 5.0, 2, models=models)
            ms[key].append(float(np.mean(inn[[f"inn_{o}" for o in outs]].to_numpy() ** 2)))
    assert abs(np.mean(ms["ar"]) - 1) < 0.1 and np.mean(ms["white"]) > 1.2, {k: np.mean(v) for k, v in ms.items()}


def test_the_diagnosis_score_test_and_bounds_take_the_nlps_input_error_ar():
    """``[objectives] input_error_ar = 2``: the residual analysis takes the identification's AR model of the input
    errors (its settings name the coefficients, fitted to the lead-ins at the analysis's samples), and the exact
    model's innovations on the bundled 3211s stay white; the score test and the Cramer-Rao bounds are given the
    order and weigh the data by it. The bundled input noise is filtered (neighbouring samples share it): its AR model
    has more low-frequency power than independent errors of its sigma, so the bounds widen (by 22-30 %)."""
    from pyomo_heli.diagnosis.attribution import attribute
    from pyomo_heli.nlp.identification import identification_data
    from pyomo_heli.nlp.objectives import input_error_models
    from pyomo_heli.dataset import load_flight_test
    from pyomo_heli.uncertainty.cramer_rao import cramer_rao, point_information

    cfg = _cfg(FAST)
    ar = dataclasses.replace(cfg, nlp=dataclasses.replace(cfg.nlp, input_error_ar=2), diagnosis=None)
    assert ar.diagnosis_settings.input_error_ar == 2 and cfg.diagnosis_settings.input_error_ar == 0
    model, params = _truth(cfg)
    res = compute_residuals(dataclasses.replace(ar, model=model), params, label="truth", trim_sensitivities=False)
    data = identification_data(ar, load_flight_test(ar.dataset))
    models = input_error_models(data.maneuvers, ["col", "lon"], 2)
    info = res.info["innovations"]
    assert info["input_error_ar"] == {c: [float(x) for x in a] for c, (a, _) in models.items()}
    d = diagnose(res)
    assert all(w["white"] for w in d.whiteness), d.whiteness
    for o in ("q", "theta", "n_x", "n_z"):
        assert 0.85 < float(np.std(res.innovations[f"inn_{o}"])) < 1.15, o
    names = [f.name for f in cfg.free]
    lm = {k: attribute(model, names, data, cfg.nlp.time_outputs, (), candidates=["nx_bias"],
                       input_errors=("col", "lon"), input_error_ar=k).scores.set_index("name").loc["nx_bias", "LM"]
          for k in (0, 2)}
    se = {k: cramer_rao(point_information(model, cfg.free, params, data.maneuvers, None, cfg.nlp.time_outputs, (),
                                          input_errors=("col", "lon"), input_error_ar=k), cfg.free, kind="A").se
          for k in (0, 2)}
    assert lm[0] != pytest.approx(lm[2], rel=1e-3), lm
    assert all(1.1 * se[0][n] < se[2][n] < 1.5 * se[0][n] for n in names), se


def test_with_record_rate_inputs_the_analysis_takes_the_nlps_input_samples():
    """``resample_inputs = "record"`` with AR(4) errors: the input errors sit on the 50 Hz recorded samples, as the
    NLP's (every other one is an output sample: ``Maneuver.input_grid``), with the record-rate lead-in's sigma and AR
    model; the exact model's innovations on the bundled 3211s are white with about unit variance, the input path
    selects nothing, the Cramer-Rao bounds eliminate the 50 Hz errors and the score test finds nothing missing."""
    from pyomo_heli.dataset import load_flight_test
    from pyomo_heli.nlp.identification import identification_data
    from pyomo_heli.nlp.objectives import lead_in_sigma
    from pyomo_heli.uncertainty.cramer_rao import cramer_rao, point_information

    cfg = load_identification_config(EIV, overrides={"data": {"resample_inputs": "record"},
                                                     "objectives": {"input_error_ar": 4}})
    model = truth_model_of(cfg.dataset)
    cfg = dataclasses.replace(cfg, maneuvers=list(FAST), validation=[], diagnosis=None, model=model)
    data = identification_data(cfg, load_flight_test(cfg.dataset))
    mv = data.maneuvers[0]
    t_in, inc, idx = mv.input_grid()
    assert len(t_in) == 2 * len(mv.data) - 1 and np.array_equal(t_in[idx], mv.t) and np.array_equal(idx[:3], [0, 2, 4])
    res = compute_residuals(cfg, model.parameters.to_dict(), label="truth", trim_sensitivities=False)
    info = res.info["innovations"]
    rec = lead_in_sigma(data.maneuvers, ["col", "lon"], input_record=True)
    assert info["sigma"]["col"] == pytest.approx(rec["col"]) and rec["col"] != pytest.approx(
        lead_in_sigma(data.maneuvers, ["col"])["col"], rel=1e-3)
    assert len(info["input_error_ar"]["lon"]) == 4
    d = diagnose(res)
    assert all(w["white"] for w in d.whiteness) and d.input_path["consistent"], (d.whiteness, d.input_path)
    for o in ("q", "theta", "n_x", "n_z"):
        assert 0.85 < float(np.std(res.innovations[f"inn_{o}"])) < 1.15, o
    pi = point_information(model, cfg.free, model.parameters.to_dict(), data.maneuvers, None, cfg.nlp.time_outputs,
                           (), input_errors=("col", "lon"), input_error_ar=4)
    assert next(iter(pi.S_input[0][1].values())).shape == (len(mv.data), 2 * len(t_in))
    assert all(np.isfinite(v) and v > 0 for v in cramer_rao(pi, cfg.free, kind="A").se.values())
    from pyomo_heli.diagnosis.attribution import attribute

    sc = attribute(model, [f.name for f in cfg.free], data, cfg.nlp.time_outputs, (), candidates=["nx_bias"],
                   input_errors=("col", "lon"), input_error_ar=4).scores.set_index("name")
    assert np.isfinite(sc.loc["nx_bias", "LM"]) and sc.loc["nx_bias", "p_value"] > 0.01  # the exact model
