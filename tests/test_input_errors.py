"""Errors in variables: the measured inputs' errors estimated with the parameters (NLPOptions.input_errors).

Checked against independent numbers: the generator's declared sensor sigmas (the lead-in estimate), the
truth parameters of the bundled flight test (truth.json, read by the test only), and J_time recomputed with
numpy from the solution's residuals and input errors.
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from pyomo_heli.config import ConfigError, load_identification_config
from pyomo_heli.dataset import load_flight_test
from pyomo_heli.flighttest.sensors import DEFAULT_SIGMA
from pyomo_heli.workflows.identify import build_problem
from pyomo_heli.nlp.identification import NLPOptions, prepare_data, identification_data
from pyomo_heli.nlp.objectives import lead_in_sigma
from pyomo_heli.nlp.parameters import free_parameter_values
from pyomo_heli.pareto.front import ParetoSolver

HERE = Path(__file__).parent
CONFIG = HERE / "configs" / "tiny_case1_input_errors.toml"
DATA = HERE.parent / "data" / "bo105_synthetic"
TRUTH = json.loads((DATA / "truth.json").read_text())["parameters"]


def test_lead_in_sigma_matches_the_declared_sensor_noise():
    """The quiet lead-in of the bundled records gives the generator's declared sigmas (model_spec.md 5)."""
    ft = load_flight_test(DATA)
    data = prepare_data(ft, "identification", 25, None, 1.9)
    est = lead_in_sigma(data.maneuvers, ["q", "theta", "n_x", "n_z", "col", "lon"])
    print("lead-in sigmas (SI):", est)
    for ch, s in est.items():
        assert s == pytest.approx(DEFAULT_SIGMA[ch], rel=0.12), ch


def test_lead_in_needs_a_lead_in():
    ft = load_flight_test(DATA)
    data = prepare_data(ft, ["lon3211_80kt_a"], 25, 6.0, 0.0)
    with pytest.raises(ValueError, match="lon3211_80kt_a.*input_reference_s"):
        lead_in_sigma(data.maneuvers, ["col"])


@pytest.fixture(scope="module")
def fits():
    """Anchor A of the tiny instance with and without input errors (about 3 s each)."""
    out = {}
    for label in ("input_errors", "output_error"):
        cfg = load_identification_config(CONFIG)
        if label == "output_error":
            cfg = dataclasses.replace(cfg, nlp=dataclasses.replace(cfg.nlp, input_errors=()))
        m, data, _ = build_problem(cfg)
        p = ParetoSolver(m, cfg.pareto).point_a()
        assert p.success, p.status
        out[label] = (m, data, free_parameter_values(m))
    return out


def test_input_errors_recover_the_truth_where_output_error_does_not(fits):
    """With 0.02 deg noise on the measured col and lon, the output-error fit of this record puts twist at
    (or next to) its bound (docs/close_loop.md: the input noise, not the output noise, moves twist);
    estimating the input errors brings twist back near the truth and the tail lift slope within 1 %.

    How near is a property of this one noisy record, not a guarantee: the twist's standard error with the
    input errors estimated is about 70 % of the truth here (test_reduced_hessian_standard_errors...), and
    the realised errors are +0.03 % (inputs picked, the default until 2026-11-25) and +5.3 % (inputs
    projected, the default since), against -100 and -95 % for output error. Hence 10 % for twist."""
    eiv, oe = fits["input_errors"][2], fits["output_error"][2]
    print({n: (f"output error {100 * (oe[n] / TRUTH[n] - 1):+.2f} %",
               f"input errors {100 * (eiv[n] / TRUTH[n] - 1):+.2f} %") for n in ("theta_twist", "CL_alpha_HT")})
    assert abs(oe["theta_twist"] / TRUTH["theta_twist"] - 1) > 0.5
    assert eiv["theta_twist"] == pytest.approx(TRUTH["theta_twist"], rel=0.10)
    assert eiv["CL_alpha_HT"] == pytest.approx(TRUTH["CL_alpha_HT"], rel=0.01)


def test_j_time_equals_the_numpy_likelihood(fits):
    """J_time at the solution = the negative log-likelihood of outputs and inputs, recomputed with numpy."""
    import pyomo.environ as pyo

    m, data, _ = fits["input_errors"]
    outputs, inputs = list(m.time_outputs), ["col", "lon"]
    sigma = lead_in_sigma(data.maneuvers, outputs + inputs)
    total = 0.0
    for mv in data.maneuvers:
        blk = m.man[mv.name]
        for o in outputs:
            r = mv.data[o].to_numpy() - np.array([pyo.value(blk.y[o, t]) for t in blk.samples])
            total += np.sum(r**2) / (2 * sigma[o] ** 2) + len(r) * math.log(sigma[o])
        for c in inputs:
            d = np.array([pyo.value(blk.u_err[c, t]) for t in blk.samples])
            total += np.sum(d**2) / (2 * sigma[c] ** 2) + len(d) * math.log(sigma[c])
    assert pyo.value(m.J_time) == pytest.approx(total, rel=1e-7)
    # the estimated input errors are of the size of the declared sensor noise, not zero and not wild
    d = np.array([pyo.value(v) for v in m.man[data.maneuvers[0].name].u_err.values()])
    assert 0.2 * DEFAULT_SIGMA["col"] < np.std(d) < 1.5 * DEFAULT_SIGMA["col"]


def test_lead_in_ar_recovers_a_known_autoregressive_noise():
    """Yule-Walker on the lead-ins of an AR(2) noise d_k = 1.2 d_(k-1) - 0.5 d_(k-2) + w_k (seeded): the
    coefficients, and the innovation-to-noise sigma ratio of the process, sqrt((1 + a2)((1 - a2)^2 - a1^2) /
    (1 - a2)) = 0.520 (the AR(2) variance formula)."""
    import pandas as pd
    from scipy.signal import lfilter

    from pyomo_heli.dataset.schema import Maneuver
    from pyomo_heli.nlp.objectives import lead_in_ar

    rng = np.random.default_rng(20261201)
    mvs = []
    for i in range(8):
        x = lfilter([1.0], [1.0, -1.2, 0.5], rng.normal(0.0, 1e-3, 3000))[500:]  # 500 samples to settle
        t = np.arange(len(x)) * 0.02
        mvs.append(Maneuver(f"m{i}", "identification", 40.0, ["col"], pd.DataFrame({"t": t, "col": x}),
                            input_reference_s=float(t[-1])))
    a, ratio = lead_in_ar(mvs, "col", 2)
    np.testing.assert_allclose(a, [1.2, -0.5], atol=0.02)
    a1, a2 = 1.2, -0.5
    assert ratio == pytest.approx(math.sqrt((1 + a2) * ((1 - a2) ** 2 - a1**2) / (1 - a2)), rel=0.03)
    a0, r0 = lead_in_ar(mvs, "col", 0)
    assert len(a0) == 0 and r0 == 1.0
    with pytest.raises(ValueError, match="m0: 3 sample"):
        lead_in_ar([dataclasses.replace(mvs[0], input_reference_s=0.05)], "col", 2)


def test_lead_in_ar_low_frequency_power_of_the_generators_noise():
    """The generator's recorded noise (white at 400 Hz, the 10 Hz Butterworth forward and backward, every 8th sample)
    has, at low frequency, 3.0 times the spectral density of white noise of its variance: sum_k rho_k over all lags
    from the filter's impulse response (analytic: 50 Hz / (2 x 8.33 Hz), 8.33 Hz the noise bandwidth of the squared
    filter). Yule-Walker on long seeded lead-ins: AR(8) gives that within 5 %, every order within 10 % of what
    Yule-Walker on the exact autocovariance gives (AR(2) 56 %, AR(4) 83 % of it); a model that understates it lets
    the input noise's slow part pass for a gain. Printed: the same ratio of the AR models fitted to the bundled
    flight test's 1.9 s lead-ins."""
    import pandas as pd
    from scipy import signal

    from pyomo_heli.dataset.schema import Maneuver
    from pyomo_heli.flighttest.sensors import SensorConfig
    from pyomo_heli.nlp.objectives import lead_in_ar

    cfg = SensorConfig()
    impulse = np.zeros(8001)
    impulse[4000] = 1.0
    h = signal.sosfiltfilt(cfg.sos(), impulse)
    dec = cfg.decimation
    gamma = np.array([h[: len(h) - dec * k] @ h[dec * k:] for k in range(40)])
    truth = (gamma[0] + 2 * gamma[1:].sum()) / gamma[0]
    assert truth == pytest.approx(3.0, abs=0.02)
    rng = np.random.default_rng(20261201)
    mvs = []
    for i in range(8):
        x = signal.sosfiltfilt(cfg.sos(), rng.normal(0.0, 1.0, 8 * 4000))[::dec]
        t = np.arange(len(x)) / cfg.record_rate
        mvs.append(Maneuver(f"m{i}", "identification", 40.0, ["col"], pd.DataFrame({"t": t, "col": x}),
                            input_reference_s=float(t[-1])))

    def low_frequency(mans, order, record=False):
        a, ratio = lead_in_ar(mans, "col", order, input_record=record)
        return ratio**2 / (1.0 - a.sum()) ** 2

    def population_share(order):
        """The share AR(order) fitted by Yule-Walker to the exact autocovariance ``gamma`` gives (no sampling)."""
        from scipy.linalg import solve_toeplitz

        a = solve_toeplitz(gamma[:order], gamma[1:order + 1])
        innovation = (gamma[0] - a @ gamma[1:order + 1]) / gamma[0]
        return innovation / (1.0 - a.sum()) ** 2 / truth

    share = {p: low_frequency(mvs, p) / truth for p in (2, 4, 8)}
    print("generator: sum rho", truth, "AR share of it", share, "population", {p: population_share(p) for p in share})
    assert share[8] == pytest.approx(1.0, abs=0.05)
    for p in (2, 4, 8):  # the seeded lead-ins' fits (4000 samples) against the population fits of the same order
        assert share[p] == pytest.approx(population_share(p), rel=0.1), p
    bundled = prepare_data(load_flight_test(DATA), resample_hz=25, input_reference_s=1.9, resample_inputs="record")
    print("bundled lead-ins, AR share:", {p: low_frequency(bundled.maneuvers, p, True) / truth for p in (2, 4, 8)})


@pytest.mark.parametrize("reference", [False, True])
def test_input_error_ar_weighs_the_errors_by_their_innovations(reference):
    """``input_error_ar = 2`` with the inputs at the record rate: J_input is the likelihood of the errors' one-step
    prediction errors under the AR model of the lead-in (recomputed with numpy at random error values), the
    innovation sigma that of the model. With ``input_reference_error`` the AR model applies to ``u_err + u_ref``, and
    the rows ``lead_in_mean`` are the errors' mean over each record's 1.9 s lead-in (t <= t0 + 1.9 s)."""
    import pyomo.environ as pyo

    from pyomo_heli.nlp.objectives import lead_in_ar

    cfg = load_identification_config(CONFIG, {"objectives": {"input_error_ar": 2, "input_reference_error": reference},
                                              "data": {"resample_inputs": "record"}})
    m, data, _ = build_problem(cfg)
    rng = np.random.default_rng(1)
    for v in m.component_data_objects(pyo.Var):
        if v.parent_component().local_name in ("u_err", "u_ref"):
            v.set_value(float(rng.normal(0.0, 3e-4)))
    sigma = lead_in_sigma(data.maneuvers, ["col", "lon"], input_record=True)
    total = 0.0
    for c in ("col", "lon"):
        a, ratio = lead_in_ar(data.maneuvers, c, 2, input_record=True)
        print(c, "AR(2) coefficients", a, "innovation / noise sigma", ratio)
        assert list(a) == m.input_error_ar[c] and 0.3 < ratio < 0.9  # the filtered noise: correlated samples
        s_w = sigma[c] * ratio
        for mv in data.maneuvers:
            blk = m.man[mv.name]
            t = mv.inputs_record["t"].to_numpy()
            assert list(blk.input_samples) == list(t)
            d = np.array([pyo.value(blk.u_err[c, tt]) for tt in t])
            if reference:
                assert pyo.value(blk.lead_in_mean[c].body) == pytest.approx(d[t <= t[0] + 1.9].mean(), rel=1e-12)
                d = d + pyo.value(blk.u_ref[c])
            else:
                assert blk.component("u_ref") is None
            w = d - a[0] * np.r_[0.0, d[:-1]] - a[1] * np.r_[0.0, 0.0, d[:-2]]
            total += np.sum(w**2) / (2 * s_w**2) + len(w) * math.log(s_w)
    # mean_square is a variable defined by an equality: evaluate J_input from its defining sums
    for c in ("col", "lon"):
        m.mean_square[c].set_value(pyo.value(m.sum_square[c]) / pyo.value(m.square_count[c]))
    assert pyo.value(m.J_input) == pytest.approx(total, rel=1e-10)


def test_output_error_ar_weighs_each_records_residuals_by_their_innovations():
    """``output_error_ar = 2``: J_output is the likelihood of each record's output residuals' one-step prediction
    errors under the AR model of that output's lead-in (recomputed with numpy at the start point), the innovation
    sigma that of the model; the residuals of the 25 Hz outputs are correlated too (ratio below 1)."""
    import pyomo.environ as pyo

    from pyomo_heli.nlp.objectives import lead_in_ar

    cfg = load_identification_config(CONFIG, {"objectives": {"output_error_ar": 2}})
    m, data, _ = build_problem(cfg)
    assert m.ipopt_defaults == {"mumps_pivtol": 1e-4}  # the AR-weighed rows' pivot tolerance (nlp/identification.py)
    outputs = list(cfg.nlp.time_outputs)
    sigma = lead_in_sigma(data.maneuvers, outputs)
    total = 0.0
    for o in outputs:
        a, ratio = lead_in_ar(data.maneuvers, o, 2)
        print(o, "AR(2) coefficients", a, "innovation / noise sigma", ratio)
        assert list(a) == m.output_error_ar[o] and 0.3 < ratio < 1.0
        s_w = sigma[o] * ratio
        for mv in data.maneuvers:
            blk = m.man[mv.name]
            r = mv.data[o].to_numpy() - np.array([pyo.value(blk.y[o, t]) for t in blk.samples])
            w = r - a[0] * np.r_[0.0, r[:-1]] - a[1] * np.r_[0.0, 0.0, r[:-2]]
            total += np.sum(w**2) / (2 * s_w**2) + len(w) * math.log(s_w)
    for o in outputs:
        m.mean_square[o].set_value(pyo.value(m.sum_square[o]) / pyo.value(m.square_count[o]))
    assert pyo.value(m.J_output) == pytest.approx(total, rel=1e-10)


@pytest.mark.slow
def test_output_error_ar_solves_at_full_size_to_a_lower_likelihood_than_the_white_noise_fit():
    """The full-size AR(2) output model (the bundled set's ten identification records, point A of
    studies/held_out_discovery.toml; about 3 min). At MUMPS' pivot tolerance 1e-6 this solve was regularised on every
    iteration once mu was small and still creeping at iteration 60; at the 1e-4 the NLP asks for, Ipopt ends optimal.
    Checked independently: the white-noise fit's optimum is a point of the same NLP (same rows and variables), so the AR
    objective there must not be lower than at the AR optimum."""
    import pyomo.environ as pyo

    from pyomo_heli.solvers import make_solver

    config = HERE.parent / "studies" / "held_out_discovery.toml"
    fits = {}
    for p in (0, 2):
        cfg = load_identification_config(config, {"objectives": {"output_error_ar": p}})
        m, _, _ = build_problem(cfg)
        res = make_solver(m, "casadi-ipopt", {"tol": 1e-8, "max_iter": 100}).solve()
        print(f"output_error_ar = {p}:", res.message, res.iterations, "iterations", f"{res.wall_time:.0f} s")
        assert res.success and res.iterations < 60, res.message
        fits[p] = m
    white, ar = fits[0], fits[2]
    j_ar = pyo.value(ar.J_time)
    values = {v.name: v.value for v in white.component_data_objects(pyo.Var)}
    for v in ar.component_data_objects(pyo.Var):
        v.set_value(values[v.name], skip_validation=True)
    for o in ar.mean_square:  # the mean squares are defined by their rows: evaluate them at the white-noise point
        ar.mean_square[o].set_value(pyo.value(ar.sum_square[o]) / pyo.value(ar.square_count[o]))
    print("AR objective at its optimum", j_ar, "at the white-noise fit's", pyo.value(ar.J_time))
    assert j_ar < pyo.value(ar.J_time)


def test_input_reference_error_takes_up_a_lead_in_offset(tmp_path):
    """A known reference error: M0's noise-free 80 kt 3211 with its recorded lon raised by delta = 0.04 deg (2 sigma)
    over the 1.9 s lead-in only. Referred to the lead-in mean, every later increment is then delta too low: the
    truth is u_ref = -delta (the lead-in's noise mean, in the errors' sign), errors of 0 on the lead-in and +delta
    after it, and M0's parameters. Without the reference error the offset costs an error on each of the 205 later
    samples instead of 96 lead-in ones, so the fit leaves more of it to the parameters: CL_alpha_HT 10.8 % off
    against 5.1 % with it (a 6 s record: the offset and the tail's lift slope move the pitch response alike)."""
    import shutil

    import pandas as pd
    import pyomo.environ as pyo

    ds = tmp_path / "ds"
    shutil.copytree(HERE.parent / "data" / "bo105_clean", ds)
    f = ds / "maneuvers" / "lon3211_80kt_a.csv"
    df = pd.read_csv(f)
    df.loc[df["t_s"] <= 1.9, "lon_deg"] += 0.04
    df.to_csv(f, index=False)
    delta = math.radians(0.04)
    sigma = {"q_deg_s": 0.2, "theta_deg": 0.1, "nx_g": 0.005, "nz_g": 0.01, "tas_m_s": 0.5, "lon_deg": 0.02}
    err = {}
    for ref in (False, True):
        cfg = load_identification_config(HERE / "configs" / "mc_time_small.toml", {
            "data": {"dataset": str(ds), "input_reference_s": 1.9, "resample_inputs": "record"},
            "objectives": {"input_errors": ["lon"], "noise_sigma": sigma, "input_reference_error": ref}})
        m, _, _ = build_problem(cfg)
        assert ParetoSolver(m, cfg.pareto).point_a().success
        est = free_parameter_values(m)
        err[ref] = abs(est["CL_alpha_HT"] / cfg.model.parameters["CL_alpha_HT"] - 1)
        blk = m.man["lon3211_80kt_a"]
        t = np.array(list(blk.input_samples))
        e = np.array([pyo.value(blk.u_err["lon", tt]) for tt in t])
        print(ref, est, e[t <= 1.9].mean() / delta, e[t > 1.9].mean() / delta)
        assert 0.3 < e[t > 1.9].mean() / delta < 1.0  # part of the offset taken up by the errors, both ways
        if ref:
            assert abs(e[t <= 1.9].mean()) < 1e-9 * delta
            assert -1.0 < pyo.value(blk.u_ref["lon"]) / delta < -0.3
    print(err)
    assert err[True] < 0.6 * err[False]


@pytest.mark.parametrize("edit, message", [
    ('input_errors = ["col", "lon"]\ninput_error_ar = 9', "'input_error_ar' must be an integer 0..8"),
    ('input_error_ar = 2', "'input_error_ar' models the input errors: give input_errors too"),
    ('input_reference_error = true', "'input_reference_error' is an error of the input errors' reference: give "
                                     "input_errors too"),
    ('output_error_ar = 2', "'output_error_ar' weighs the known-noise J_time of the errors in variables: give "
                            "input_errors too"),
    ('input_errors = ["col"]\noutput_error_ar = 9', "'output_error_ar' must be an integer 0..8"),
    ('input_errors = ["col"]\ninput_reference_error = 1', "'input_reference_error' must be bool"),
    ('input_errors = ["col", "ped"]', "unknown input channel.*'ped'"),
    ('input_errors = ["col"]\nnoise_sigma = { nz_gee = 0.01 }', "unknown key 'nz_gee'"),
    ('input_errors = ["col"]\nnoise_sigma = { nz_g = -0.01 }', "'nz_g' must be a positive number"),
    ('noise_sigma = { nz_g = 0.01 }', "noise_sigma is only used with input_errors"),
])
def test_bad_input_error_settings_are_named(tmp_path, edit, message):
    text = CONFIG.read_text().replace("../../data", str(HERE.parent / "data"))
    text = text.replace('input_errors = ["col", "lon"]', edit)
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_identification_config(f)


def test_input_errors_without_a_lead_in_are_refused(tmp_path):
    text = CONFIG.read_text().replace("../../data", str(HERE.parent / "data")).replace("input_reference_s = 1.9", "")
    f = tmp_path / "nolead.toml"
    f.write_text(text)
    with pytest.raises(ConfigError, match="input_reference_s > 0 or give \\[objectives.noise_sigma\\]"):
        load_identification_config(f)


def test_nlp_options_refuse_unknown_input_channels():
    with pytest.raises(ValueError, match="unknown input channel"):
        NLPOptions(input_errors=("ped",))


def test_inspect_and_multistart_know_the_input_errors():
    """`pyomo-heli inspect` names the input errors, their sigmas and their model; a multi-start restart zeroes the
    errors (the reference errors too) and re-initialises the mean squares consistently
    (nlp.identification.initialise_at)."""
    import pyomo.environ as pyo

    from pyomo_heli.nlp.identification import initialise_at
    from pyomo_heli.nlp.inspect import inspect_problem

    cfg = load_identification_config(CONFIG)
    text = inspect_problem(cfg, diagnostics=False)
    assert "input errors col, lon (noise sigmas from the lead-in)" in text and "noise sigmas (lead-in" in text
    cfg = load_identification_config(CONFIG, {"objectives": {"input_error_ar": 2, "input_reference_error": True}})
    assert ("input errors col, lon (noise sigmas from the lead-in; AR(2) errors; each record's reference error)"
            in " ".join(inspect_problem(cfg, diagnostics=False).split()))  # the header is wrapped
    m, data, _ = build_problem(cfg)
    blk = m.man["lon3211_80kt_a"]
    for v in [*blk.u_err.values(), *blk.u_ref.values()]:
        v.set_value(1e-4)
    initialise_at(m, data, cfg.model, cfg.free, {f.name: f.initial for f in cfg.free})
    assert all(v.value == 0.0 for v in [*blk.u_err.values(), *blk.u_ref.values()])
    for c in m.mean_square:
        assert pyo.value(m.mean_square_def[c].body) == pytest.approx(0.0, abs=1e-9 * pyo.value(m.sum_square[c]))


def test_lead_in_without_noise_is_refused():
    """Noise-free records (bo105_clean) give no lead-in sigma to work with: a clear error, not a bad solve."""
    ft = load_flight_test(HERE.parent / "data" / "bo105_clean")
    data = prepare_data(ft, ["lon3211_80kt_a"], 25, 6.0, 1.9)
    with pytest.raises(ValueError, match="'col' shows no noise in the lead-in.*noise_sigma"):
        lead_in_sigma(data.maneuvers, ["col"])


def test_reduced_hessian_standard_errors_agree_with_cramer_rao_and_cover_the_truth():
    """Second method for the standard errors at anchor A: the inverse reduced Hessian of the NLP
    (uncertainty/reduced_hessian.py, exact second derivatives, observed information) against the Cramer-Rao
    bounds from simulated sensitivities (uncertainty/cramer_rao.py), within 5 %: on output-error data, and
    with input errors against the bounds with the input errors eliminated (their Schur complement, exact
    input sensitivities). There the estimate lies within 2 standard errors of the truth, and the standard
    errors exceed the output-error bounds (the input errors take information)."""
    from pyomo_heli.uncertainty.cramer_rao import cramer_rao, point_information
    from pyomo_heli.uncertainty.reduced_hessian import reduced_hessian_covariance

    cfg = load_identification_config(HERE / "configs" / "mc_time_small.toml", {"data": {"dataset": str(DATA)}})
    m, data, _ = build_problem(cfg)
    solver = ParetoSolver(m, cfg.pareto)
    assert solver.point_a().success
    rh = reduced_hessian_covariance(m, solver.solver, 1.0 / solver.s_time)
    info = point_information(cfg.model, cfg.free, free_parameter_values(m), data.maneuvers, data.trims,
                             cfg.nlp.time_outputs, cfg.nlp.trim_outputs)
    cr = cramer_rao(info, cfg.free, "A")
    print("output error, reduced Hessian vs Cramer-Rao SE:", {n: (rh["se"][n], cr.se[n]) for n in rh["se"]})
    for name in ("CL_alpha_HT", "Iyy"):
        assert rh["se"][name] == pytest.approx(cr.se[name], rel=0.05), name

    cfg = load_identification_config(CONFIG)
    m, data, _ = build_problem(cfg)
    solver = ParetoSolver(m, cfg.pareto)
    assert solver.point_a().success
    rh = reduced_hessian_covariance(m, solver.solver, 1.0 / solver.s_time)
    est = free_parameter_values(m)
    info = point_information(cfg.model, cfg.free, est, data.maneuvers, data.trims, cfg.nlp.time_outputs,
                             cfg.nlp.trim_outputs)
    cr = cramer_rao(info, cfg.free, "A")
    info_eiv = point_information(cfg.model, cfg.free, est, data.maneuvers, data.trims, cfg.nlp.time_outputs,
                                 cfg.nlp.trim_outputs, input_errors=cfg.nlp.input_errors)
    cr_eiv = cramer_rao(info_eiv, cfg.free, "A")
    print("input errors, reduced Hessian vs Cramer-Rao with input errors vs output-error Cramer-Rao SE:",
          {n: (rh["se"][n], cr_eiv.se[n], cr.se[n]) for n in rh["se"]})
    for name in ("theta_twist", "CL_alpha_HT"):
        assert abs(est[name] - TRUTH[name]) < 2 * rh["se"][name], name
        assert rh["se"][name] > cr.se[name], name
        assert cr_eiv.se[name] == pytest.approx(rh["se"][name], rel=0.05), name


def test_input_sensitivities_match_finite_differences():
    """simulation.compiled.input_sensitivities (Jacobians of one RK4 interval chained along the record)
    against central differences of the simulation itself, one input sample at a time."""
    from pyomo_heli.simulation.compiled import input_sensitivities, simulate_outputs
    from pyomo_heli.simulation.trim import trim_float

    cfg = load_identification_config(CONFIG)
    mv = identification_data(cfg).maneuvers[0]
    t, inc, outs = mv.data["t"].to_numpy(), mv.increments(), ["q", "theta", "n_x", "n_z", "TAS"]
    tp = trim_float(cfg.model, mv.trim_speed)
    y, S = input_sensitivities(cfg.model, tp, t, inc, outs, ["col", "lon"])
    n, h = len(t), 1e-6
    for o in outs:
        assert np.array_equal(y[o], simulate_outputs(cfg.model, tp, t, inc, [o])[o])
    for c, chan in enumerate(["col", "lon"]):
        for k in (0, 7, n // 2, n - 1):
            up, dn = ({kk: v.copy() for kk, v in inc.items()} for _ in range(2))
            up[chan][k] += h
            dn[chan][k] -= h
            yp, ym = simulate_outputs(cfg.model, tp, t, up, outs), simulate_outputs(cfg.model, tp, t, dn, outs)
            for o in outs:
                fd = (yp[o] - ym[o]) / (2 * h)
                col = S[o][:, c * n + k]
                np.testing.assert_allclose(col, fd, atol=1e-6 * np.max(np.abs(fd)) + 1e-12, err_msg=f"{o} {chan} {k}")
                assert not col[:k].any(), "an input sample moves no earlier output"
    # keep: only the wanted rows, identical to the full matrix's
    keep = np.arange(0, n, 5)
    _, S_keep = input_sensitivities(cfg.model, tp, t, inc, outs, ["col", "lon"], keep=keep)
    for o in outs:
        np.testing.assert_array_equal(S_keep[o], S[o][keep])


def test_cramer_rao_with_vanishing_input_noise_is_the_output_error_bound():
    """Analytic limit: with input sigmas -> 0 the input errors carry no freedom and the eliminated
    information equals the output-error information with the same known output sigmas."""
    from pyomo_heli.uncertainty.cramer_rao import point_information

    cfg = load_identification_config(CONFIG)
    data = identification_data(cfg)
    values = {f.name: TRUTH[f.name] for f in cfg.free}
    args = (cfg.model, cfg.free, values, data.maneuvers, data.trims, cfg.nlp.time_outputs, cfg.nlp.trim_outputs)
    sigma = lead_in_sigma(data.maneuvers, list(cfg.nlp.time_outputs))
    tiny = point_information(*args, input_errors=("col", "lon"), noise_sigma={**sigma, "col": 1e-9, "lon": 1e-9})
    oe = point_information(*args)
    oe.R_time = {o: sigma[o] ** 2 for o in oe.R_time}
    np.testing.assert_allclose(tiny.fisher_time(), oe.fisher_time(), rtol=1e-6)
    np.testing.assert_allclose(tiny.grad_time(), oe.grad_time(), rtol=1e-5, atol=1e-9 * np.abs(oe.grad_time()).max())
    real = point_information(*args, input_errors=("col", "lon"))
    # with the real input noise the information can only fall (positive semi-definite difference)
    assert np.linalg.eigvalsh(oe.fisher_time() - real.fisher_time()).min() > -1e-9 * np.abs(oe.fisher_time()).max()
