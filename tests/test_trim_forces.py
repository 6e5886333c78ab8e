"""The steady force and moment the trims ask for (diagnosis/trim_forces.py).

Checked against an independent truth: trims of M0 plus a held-out effect with a steady force and moment
(``fuselage_download``, whose dZ and dM the effect itself states), solved by the float trim; the model fitted to
them is M0, so what the trims ask it to add is the effect's own force and moment, under any recording conventions.
The standard errors are checked against a seeded Monte Carlo of the trim noise.
"""
from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pyomo_heli.dataset.schema import TrimConventions
from pyomo_heli.diagnosis.trim_forces import ImpliedForces, implied_forces, neighbour_sigma
from pyomo_heli.flighttest.held_out_effects import HELD_OUT_EFFECTS, HELD_OUT_STRENGTHS
from pyomo_heli.physics.conventions import model_trim, recorded_trim
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.physics.parameters import DEG
from pyomo_heli.simulation.trim import trim_sweep
from pyomo_heli.units import KT

SPEEDS = np.array([0.0, 15.0, 30.0, 60.0, 100.0]) * KT
SIGMA = {"col": 0.05 * DEG, "lon": 0.05 * DEG, "theta": 0.1 * DEG}


def recorded_trims(model, conventions=TrimConventions(), speeds=SPEEDS):
    rows = []
    for tp in trim_sweep(model, speeds):
        rows.append({"V": tp.V, "gamma_fp": 0.0, "source": "level",
                     **recorded_trim(tp.col, tp.lon, tp.theta, model.parameters, conventions)})
    return pd.DataFrame(rows)


@pytest.fixture(scope="module")
def download():
    e = HELD_OUT_EFFECTS["fuselage_download"]()
    truth = HelicopterModel(extensions=(e,)).with_parameters(**HELD_OUT_STRENGTHS["fuselage_download"])
    forces = []
    for tp in trim_sweep(truth, SPEEDS):
        ctx = truth.evaluate(tp.state(), tp.inputs())
        forces.append([float(np.asarray(f)) for f in e.extra_forces(ctx)])
    return truth, np.array(forces)


@pytest.mark.parametrize("conventions", [TrimConventions(),
                                         TrimConventions(collective_station=0.0, lon_sign=-1, theta_datum=2 * DEG)],
                         ids=["format", "root-collective-forward-cyclic-datum"])
def test_the_trims_of_a_missing_steady_force_ask_for_that_force(download, conventions):
    truth, expected = download
    assert np.max(np.abs(expected[:, 1])) > 500.0  # a download of hundreds of N at hover
    got = implied_forces(HelicopterModel(), recorded_trims(truth, conventions), conventions, sigma=SIGMA)
    t = got.table
    assert list(t["V [kt]"]) == pytest.approx(list(SPEEDS / KT))
    assert t["dX [N]"].to_numpy() == pytest.approx(expected[:, 0], abs=1e-6)
    assert t["dZ [N]"].to_numpy() == pytest.approx(expected[:, 1], rel=1e-6, abs=1e-6)
    assert t["dM [N m]"].to_numpy() == pytest.approx(expected[:, 2], rel=1e-6, abs=1e-6)


def test_a_model_that_trims_as_recorded_is_asked_for_nothing():
    m = HelicopterModel().with_parameters(theta_twist=-0.03)
    t = implied_forces(m, recorded_trims(m), sigma=SIGMA).table
    for c in ("dX [N]", "dZ [N]", "dM [N m]"):
        assert np.max(np.abs(t[c])) < 1e-6


def test_standard_errors_match_a_monte_carlo_of_the_trim_noise():
    m = HelicopterModel()
    clean = recorded_trims(m, speeds=np.array([20.0, 80.0]) * KT)
    rng = np.random.default_rng(20261129)
    draws = []
    for _ in range(300):
        noisy = clean.copy()
        for c, s in SIGMA.items():
            noisy[c] = noisy[c] + rng.normal(0.0, s, len(noisy))
        draws.append(implied_forces(m, noisy, sigma=SIGMA).table[["dX [N]", "dZ [N]", "dM [N m]"]].to_numpy())
    spread = np.std(np.array(draws), axis=0, ddof=1)
    se = implied_forces(m, clean, sigma=SIGMA).table[["se dX [N]", "se dZ [N]", "se dM [N m]"]].to_numpy()
    # 300 draws: the sample standard deviation is within ~8 % (two of its standard errors) of the true one
    assert spread == pytest.approx(se, rel=0.12)


def test_the_noise_estimate_from_neighbouring_speeds_ignores_a_smooth_trend():
    rng = np.random.default_rng(7)
    V = np.linspace(0.0, 60.0, 400)
    e = 0.2 * np.exp(-((V - 15.0) / 8.0) ** 2) + rng.normal(0.0, 0.01, V.size)  # a bump 20 noise sigmas high
    assert neighbour_sigma(V, e) == pytest.approx(0.01, rel=0.1)
    assert math.isnan(neighbour_sigma([1.0, 2.0], [0.0, 1.0]))


def test_default_noise_comes_from_the_residual_and_results_round_trip(tmp_path, download):
    truth, _ = download
    trims = recorded_trims(truth, speeds=np.arange(0.0, 121.0, 10.0) * KT)
    rng = np.random.default_rng(3)
    for c, s in SIGMA.items():
        trims[c] = trims[c] + rng.normal(0.0, s, len(trims))
    got = implied_forces(HelicopterModel(), trims)
    assert got.sigma_source.startswith("the model's trim residual")
    for c, s in SIGMA.items():  # 13 points: a rough estimate, within a factor of two
        assert 0.5 * s < got.sigma[c] < 2.0 * s
    back = ImpliedForces.load(got.save(tmp_path / "f"))
    pd.testing.assert_frame_equal(back.table, got.table)
    assert back.sigma == got.sigma and back.label == got.label
    assert "dM [N m]" in str(back)


def test_a_trim_table_without_a_channel_is_a_one_line_error():
    with pytest.raises(ValueError, match="trims: no column lon"):
        implied_forces(HelicopterModel(), pd.DataFrame({"V": [10.0], "gamma_fp": [0.0], "col": [0.1],
                                                        "theta": [0.05]}))


def test_findings_name_the_force_beyond_the_noise(download):
    truth, expected = download
    got = implied_forces(HelicopterModel(), recorded_trims(truth, speeds=np.arange(0.0, 121.0, 10.0) * KT),
                         sigma=SIGMA, label="M0")
    rows = {r["force"]: r for r in got.summary().to_dict("records")}
    # the download's dZ (667 N at hover, SE 179 N) is beyond the noise at 0.01, its dM (534 N m, SE 197) is not
    assert rows["dZ [N]"]["p"] < 0.01 < rows["dM [N m]"]["p"]
    assert rows["dZ [N]"]["largest"] == pytest.approx(expected[0, 1], rel=1e-6)
    assert got.findings() == [f"the trims ask M0 for a steady dZ of up to {expected[0, 1]:+.3g} N at 0 kt (chi2 "
                              f"{rows['dZ [N]']['chi2']:.3g} on 13 trim points, p = {rows['dZ [N]']['p']:.2g}; "
                              "equation error at the trims, no library)"]


def test_a_shift_of_the_identified_parameters_is_taken_out():
    # trims of M0, a model with twist and tail lift slope far off (a time-domain anchor can sit there): what the
    # trims ask it for is far beyond the noise, and all of it is a shift of those two parameters
    m0 = HelicopterModel()
    trims = recorded_trims(m0, speeds=np.arange(0.0, 121.0, 10.0) * KT)
    off = m0.with_parameters(theta_twist=m0.parameters["theta_twist"] * 2.0,
                             CL_alpha_HT=m0.parameters["CL_alpha_HT"] * 1.5)
    got = implied_forces(off, trims, sigma=SIGMA, free=("theta_twist", "CL_alpha_HT", "Iyy"))
    s = got.summary().set_index("force")
    assert s.loc["dZ [N]", "chi2"] > 300.0 and s.loc["dM [N m]", "chi2"] > 300.0
    assert (s["chi2 beyond parameters"] < 0.01 * s["chi2"]).all()
    # Iyy does not act on a trim and is not counted; both others move dZ and dM
    assert s.loc["dZ [N]", "df beyond"] == s.loc["dM [N m]", "df beyond"] == 13 - 2
    assert got.findings() == []
    raw = implied_forces(off, trims, sigma=SIGMA).findings()  # without the parameters: both named
    assert [f.split(" of up to")[0] for f in raw] == ["the trims ask model for a steady dZ",
                                                      "the trims ask model for a steady dM"]
    back = ImpliedForces.load(got.save(Path(tempfile.mkdtemp())))
    pd.testing.assert_frame_equal(back.summary(), got.summary())


def test_a_climbing_trim_point_is_balanced_along_its_flight_path(download):
    truth, _ = download
    e = truth.extensions[0]
    gam = math.radians(4.0)
    tp = trim_sweep(truth, [40.0 * KT], gamma_fp=gam)[0]
    expected = [float(np.asarray(f)) for f in e.extra_forces(truth.evaluate(tp.state(), tp.inputs()))]
    trims = pd.DataFrame([{"V": tp.V, "gamma_fp": gam, "source": "climb",
                           **recorded_trim(tp.col, tp.lon, tp.theta, truth.parameters, TrimConventions())}])
    t = implied_forces(HelicopterModel(), trims, sigma=SIGMA).table
    assert t["gamma_fp [deg]"].iloc[0] == pytest.approx(4.0)
    assert [t["dX [N]"].iloc[0], t["dZ [N]"].iloc[0], t["dM [N m]"].iloc[0]] == pytest.approx(expected, abs=1e-6)


def test_trims_that_never_record_all_three_channels_give_an_empty_table_not_an_error():
    # the Padfield flight trims record each channel at its own speeds: no point has all three
    trims = pd.DataFrame({"V": [10.0, 20.0, 30.0], "gamma_fp": 0.0, "col": [0.2, np.nan, np.nan],
                          "lon": [np.nan, 0.01, np.nan], "theta": [np.nan, np.nan, 0.05]})
    got = implied_forces(HelicopterModel(), trims, sigma=SIGMA, free=("theta_twist",))
    assert got.table.empty and got.findings() == []
    assert (got.summary()["points"] == 0).all()


def test_model_trim_inverts_recorded_trim():
    p = HelicopterModel().parameters
    c = TrimConventions(collective_station=0.0, lon_sign=-1, theta_datum=2 * DEG)
    rec = recorded_trim(0.15, 0.02, 0.05, p, c)
    back = model_trim(rec["col"], rec["lon"], rec["theta"], p, c)
    assert [back["col"], back["lon"], back["theta"]] == pytest.approx([0.15, 0.02, 0.05], abs=1e-15)
