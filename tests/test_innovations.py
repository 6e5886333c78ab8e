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
