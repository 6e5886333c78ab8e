"""Cramer-Rao standard errors, identifiability and Monte Carlo (issue: trust in the answer).

References: the spread of estimates over seeded noise realizations (an
independent route to the standard errors), the known true parameters of the
clean data, and closed-form linear-Gaussian results.
"""
from __future__ import annotations

import concurrent.futures as cf
import math
from pathlib import Path

import numpy as np
import pyomo.environ as pyo
import pytest

from pyomo_heli.config import load_identification_config
from pyomo_heli.dataset import load_flight_test
from pyomo_heli.flighttest.sensors import DEFAULT_SIGMA
from pyomo_heli.nlp.identification import (NLPOptions, build_identification_nlp, identification_data, prepare_data,
                                           set_measurements)
from pyomo_heli.nlp.parameters import FreeParameter
from pyomo_heli.physics.parameters import bo105
from pyomo_heli.provenance import ResultsMismatchError
from pyomo_heli.uncertainty.cramer_rao import PointInformation, cramer_rao, point_information
from pyomo_heli.uncertainty.identifiability import identifiability
from pyomo_heli.uncertainty.monte_carlo import ProblemSpec, run_monte_carlo
from pyomo_heli.uncertainty.realizations import noisy_copy
from pyomo_heli.units import DEG

HERE = Path(__file__).parent
CONFIGS = HERE / "configs"
TRUTH = bo105()
SIGMA = {o: DEFAULT_SIGMA[o] for o in ("q", "theta", "n_x", "n_z", "TAS")}


def test_cramer_rao_agrees_with_monte_carlo_spread(tmp_path):
    """Acceptance: bo105_clean + known white noise, 20 realizations of the time-domain fit (point A):
    the spread of the estimates and the Cramer-Rao standard error (at each estimate, R as estimated)
    agree within a factor 1.5 for every parameter, and the estimates scatter around the noise-free
    estimate (the estimator adds no bias of its own)."""
    n = 20
    spec = ProblemSpec.make(CONFIGS / "mc_time_small.toml")
    quiet = dict(truth=dict(TRUTH), multi_objective=False, workers=0, progress=lambda *_: None)
    res = run_monte_carlo(spec, n, seed=11, sigma=SIGMA, trim_sigma={}, out=tmp_path / "mc", **quiet)
    # the noise-free reference goes through the Executor interface (what a Dask client's executor offers)
    with cf.ThreadPoolExecutor(max_workers=1) as ex:
        clean = run_monte_carlo(spec, 1, seed=11, sigma={}, trim_sigma={}, out=None, crb=False, executor=ex,
                                **quiet).estimates
    s = res.summary().set_index("parameter")
    print(s[["mean", "std", "crb", "std/crb"]].to_string(), "\nnoise-free:",
          clean[["CL_alpha_HT", "Iyy"]].to_dict("records"))
    assert (s["n"] == n).all() and res.estimates["success"].all()
    for p in ("CL_alpha_HT", "Iyy"):
        ratio = s.loc[p, "std/crb"]
        assert 1 / 1.5 <= ratio <= 1.5, (p, ratio)
        # the noise must not move the mean further than its sampling error from the noise-free fit (which
        # is not the truth exactly: the fit's own discretisation, docs/uncertainty.md)
        assert abs(s.loc[p, "mean"] - clean[p].iloc[0]) < 3 * s.loc[p, "std"] / math.sqrt(n), p
    # each finished realization is on disk; a rerun into the same folder has nothing left to do
    again = run_monte_carlo(spec, n, seed=11, sigma=SIGMA, trim_sigma={}, out=tmp_path / "mc", **quiet)
    cols = ["realization", "CL_alpha_HT", "Iyy"]
    np.testing.assert_allclose(again.estimates[cols].to_numpy(float), res.estimates[cols].to_numpy(float), rtol=1e-11)
    # a rerun asking for fewer summarises those; another run's settings are refused, naming what differs
    fewer = run_monte_carlo(spec, 5, seed=11, sigma=SIGMA, trim_sigma={}, out=tmp_path / "mc", **quiet)
    assert (fewer.summary()["n"] == 5).all()
    with pytest.raises(ResultsMismatchError, match="differs in: seed"):
        run_monte_carlo(spec, n, seed=12, sigma=SIGMA, trim_sigma={}, out=tmp_path / "mc", **quiet)
    with pytest.raises(ResultsMismatchError, match="differs in: sigma"):
        run_monte_carlo(spec, n, seed=11, sigma={**SIGMA, "q": 2 * SIGMA["q"]}, trim_sigma={}, out=tmp_path / "mc",
                        **quiet)


def test_monte_carlo_counts_a_parameter_at_its_bound_by_name():
    """``at bound`` counts a parameter by its name in the cell, not by a substring: "a" is not at its bound when
    "theta_twist" is."""
    import pandas as pd

    from pyomo_heli.uncertainty.monte_carlo import MonteCarloResult

    est = pd.DataFrame({"realization": [0, 1, 2], "estimator": "time", "success": True, "a": [6.0, 6.1, 5.9],
                        "theta_twist": [-0.03, 0.0, -0.03],
                        "at_bound": [float("nan"), "theta_twist:upper", "theta_twist:upper;a:lower"]})
    s = MonteCarloResult(est, ["a", "theta_twist"], {"a": 6.0, "theta_twist": -0.03}).summary().set_index("parameter")
    assert s.loc["theta_twist", "at bound"] == 2 and s.loc["a", "at bound"] == 1


def test_a_realization_without_a_chosen_point_keeps_its_point_a(monkeypatch):
    """No front point converged, so Eq. 11 chooses nothing (ParetoSolver.choose returns None): the multi-objective
    row fails saying so, and the converged point A stays a successful time-domain row (a review: the exception
    marked both rows failed, leaving a realization out of the time-domain summary)."""
    from pyomo_heli.pareto.front import ParetoSolver
    from pyomo_heli.uncertainty.monte_carlo import RealizationTask, run_realization

    monkeypatch.setattr(ParetoSolver, "choose", lambda self, rule=None: (None, np.zeros(0)))
    spec = ProblemSpec.make(CONFIGS / "tiny_case1_noisy.toml")
    rows = run_realization(RealizationTask(spec, 0, 11, tuple(SIGMA.items()), (), multi_objective=True, crb=False))
    assert [r["estimator"] for r in rows] == ["time", "multi"]
    assert rows[0]["success"] and rows[0]["kind"] == "A"
    assert not rows[1]["success"] and "no front point converged" in rows[1]["status"]


def _linear_info(rng, n=3, N=200, M=12):
    S_t = {"y1": rng.normal(size=(N, n)), "y2": rng.normal(size=(N, n))}
    S_r = {"col": rng.normal(size=(M, n))}
    return PointInformation(names=[f"p{i}" for i in range(n)], values={f"p{i}": 1.0 for i in range(n)},
                            scale=np.ones(n), S_time=S_t, e_time={o: np.zeros(N) for o in S_t},
                            R_time={"y1": 0.3, "y2": 2.0}, S_trim=S_r, e_trim={"col": np.zeros(M)},
                            R_trim={"col": 0.01})


def _free(n, lower=-10.0, upper=10.0):
    return [FreeParameter(f"p{i}", 1.0, lower, upper, 1.0) for i in range(n)]


def test_sandwich_covariance_in_closed_form():
    """Linear-Gaussian checks: A gives F_time^-1; a weighted sum with the ML-optimal trim weight
    gives (F_time + F_trim)^-1; a pure trim fit gives F_trim^-1."""
    info = _linear_info(np.random.default_rng(3))
    Ft, Fr = info.fisher_time(), info.fisher_trim()
    a = cramer_rao(info, _free(3), kind="A")
    assert a.combination == "time"
    np.testing.assert_allclose([a.se[n] for n in info.names], np.sqrt(np.diag(np.linalg.inv(Ft))), rtol=1e-10)
    # b * H_trim = F_trim when b * 2 / (M DEG^2) = 1 / R_trim
    b = 1 / info.R_trim["col"] * info.n_trims * DEG**2 / 2
    c = cramer_rao(info, _free(3), weights=(1.0, b))
    np.testing.assert_allclose([c.se[n] for n in info.names], np.sqrt(np.diag(np.linalg.inv(Ft + Fr))), rtol=1e-10)
    cov = np.linalg.inv(Ft + Fr)
    np.testing.assert_allclose(c.correlation, cov / np.outer(np.sqrt(np.diag(cov)), np.sqrt(np.diag(cov))),
                               atol=1e-12)
    r = cramer_rao(info, _free(3), weights=(0.0, 1.0))
    np.testing.assert_allclose([r.se[n] for n in info.names], np.sqrt(np.diag(np.linalg.inv(Fr))), rtol=1e-10)


def test_a_front_points_covariance_is_the_weights_held_estimators_not_the_epsilon_held_ones():
    """Linear-Gaussian front with model error (the trims made by another parameter), b/a = 200: over 1000 seeded
    noise draws the sandwich at the point's multiplier matches the spread of argmin J_time + (b/a) J_trim (the
    weights held) within 10 %, while the point held at its own eps (argmin J_time s.t. J_trim <= eps) scatters
    a third less in the direction the bound fixes (docs/uncertainty.md, "Which combination")."""
    from scipy.optimize import brentq

    rng = np.random.default_rng(0)
    n_t, n_r = 400, 12
    Xt, Xr = rng.normal(size=(n_t, 2)), rng.normal(size=(n_r, 2)) * DEG
    st, sr = 1.0, 0.05 * DEG
    yt0, yr0 = Xt @ np.array([1.0, 0.0]), Xr @ np.array([1.0, 1.0])
    c = 2 / (n_r * DEG**2)  # J_trim = sum (r / DEG)^2 / M, J_time = sum e^2 / (2 st^2)

    def weights_held(yt, yr, mu):
        return np.linalg.solve(Xt.T @ Xt / st**2 + mu * c * Xr.T @ Xr, Xt.T @ yt / st**2 + mu * c * Xr.T @ yr)

    def j_trim(th, yr):
        return np.sum(((yr - Xr @ th) / DEG) ** 2) / n_r

    def eps_held(yt, yr, eps):
        lm = brentq(lambda lm: j_trim(weights_held(yt, yr, np.exp(lm)), yr) - eps, -30, 30, xtol=1e-13)
        return weights_held(yt, yr, np.exp(lm))

    mu = 200.0
    th0 = weights_held(yt0, yr0, mu)
    eps = j_trim(th0, yr0)
    draws = [(yt0 + st * rng.normal(size=n_t), yr0 + sr * rng.normal(size=n_r)) for _ in range(1000)]
    spread_w = np.std([weights_held(yt, yr, mu) for yt, yr in draws], axis=0, ddof=1)
    spread_e = np.std([eps_held(yt, yr, eps) for yt, yr in draws], axis=0, ddof=1)
    info = PointInformation(names=["p0", "p1"], values={"p0": th0[0], "p1": th0[1]}, scale=np.ones(2),
                            S_time={"y": Xt}, e_time={"y": yt0 - Xt @ th0}, R_time={"y": st**2},
                            S_trim={"c": Xr}, e_trim={"c": yr0 - Xr @ th0}, R_trim={"c": sr**2})
    u = cramer_rao(info, [FreeParameter(f"p{i}", th0[i], -100, 100, 1.0) for i in range(2)], kind="eps",
                   multiplier=mu)
    se = np.array([u.se["p0"], u.se["p1"]])
    np.testing.assert_allclose(se, spread_w, rtol=0.1)
    assert spread_e[1] < 0.75 * se[1]


def test_parameter_at_a_bound_is_projected_out():
    info = _linear_info(np.random.default_rng(4))
    info.values["p1"] = 10.0  # at the upper bound of _free
    u = cramer_rao(info, _free(3), kind="A")
    assert u.at_bound == {"p0": "", "p1": "upper", "p2": ""}
    assert math.isnan(u.se["p1"]) and "p1:upper" in u.row()["at_bound"]
    keep = [0, 2]
    Ft = info.fisher_time()[np.ix_(keep, keep)]  # p1 treated as known
    np.testing.assert_allclose([u.se["p0"], u.se["p2"]], np.sqrt(np.diag(np.linalg.inv(Ft))), rtol=1e-10)
    assert "projected out" in str(u)
    again = type(u).from_dict(u.to_dict())
    assert math.isnan(again.se["p1"]) and again.se["p0"] == u.se["p0"]


def test_a_parameter_the_solver_left_just_inside_an_active_bound_is_projected_out():
    """An interior-point solver stops about mu / z inside an active bound: 5e-4 scales from it here, beyond
    BOUND_TOL. The residual wants p1 one unit higher (e = S delta, the Gauss-Newton step delta = +1 on p1), past the
    upper bound at 10: p1 is held by the bound and projected out, the others' SEs are F^-1 without it (a review
    found the twist of a short record counted free, its SE 318 deg/m and the others' 26 % too large). The same
    distance with the step pointing inwards is an interior estimate."""
    for sign, held in ((1.0, "upper"), (-1.0, "")):
        info = _linear_info(np.random.default_rng(4))
        info.values["p1"] = 10.0 - 5e-4
        delta = np.array([0.0, sign, 0.0])
        info.e_time = {o: S @ delta for o, S in info.S_time.items()}
        u = cramer_rao(info, _free(3), kind="A")
        assert u.at_bound == {"p0": "", "p1": held, "p2": ""}
        keep = [0, 2] if held else [0, 1, 2]
        cov = np.linalg.inv(info.fisher_time()[np.ix_(keep, keep)])
        np.testing.assert_allclose([u.se[f"p{i}"] for i in keep], np.sqrt(np.diag(cov)), rtol=1e-10)


def test_an_undetermined_parameter_keeps_its_infinite_se_through_save_and_load():
    """Two parameters the time data see only through their sum: their SEs are infinite (not determined), a third's
    finite. Saved (JSON has no infinity: null, and named under "undetermined") and loaded, they are infinite again,
    told apart from a missing SE (NaN), and the table says so (a review: they came back NaN)."""
    import json

    info = _linear_info(np.random.default_rng(6))
    for o, S in info.S_time.items():
        S[:, 1] = S[:, 0]
    info.S_trim = {"col": np.zeros_like(info.S_trim["col"])}
    u = cramer_rao(info, _free(3), kind="A")
    assert u.se["p0"] == math.inf and u.se["p1"] == math.inf and math.isfinite(u.se["p2"])
    d = json.loads(json.dumps(u.to_dict()))
    assert d["se"]["p0"] is None and d["undetermined"] == ["p0", "p1"]
    again = type(u).from_dict(d)
    assert again.se["p0"] == math.inf and again.se["p2"] == u.se["p2"]
    assert "not determined" in again.table().set_index("parameter").loc["p0", "note"]
    d.pop("undetermined")
    assert math.isnan(type(u).from_dict(d).se["p0"])  # a file without the list: unknown, as before


def test_weights_of_an_interior_front_point_make_it_stationary():
    """For an epsilon point the weights found from the gradients satisfy a g_time + b g_trim = 0."""
    rng = np.random.default_rng(5)
    info = _linear_info(rng)
    g = rng.normal(size=3)
    # residuals whose gradients are anti-parallel: g_time = -S^T R^-1 e = g, g_trim = -4 g
    info.e_time = {"y1": -np.linalg.pinv(info.S_time["y1"].T) @ g * info.R_time["y1"], "y2": np.zeros(200)}
    info.e_trim = {"col": np.linalg.pinv(info.S_trim["col"].T) @ (4 * g) * info.n_trims * DEG**2 / 2}
    np.testing.assert_allclose(info.grad_time(), g, rtol=1e-8)
    np.testing.assert_allclose(info.grad_trim(), -4 * g, rtol=1e-8)
    u = cramer_rao(info, _free(3), kind="eps")
    a, b = u.weights
    assert u.combination == "weighted" and b / a == pytest.approx(0.25, rel=1e-8)


def test_weights_do_not_depend_on_the_parameters_nominal_scales():
    """A front point's standard errors must not depend on the unit a parameter is scaled in. The case a
    closed loop met (fuselage_wake_incidence 22, iteration 2's direct point): the trade between the objectives
    runs along p0 (g_trim = -4 g_time there), the trims cannot see p2, and the float model's J_time gradient
    keeps about one standard error's worth along p2 (the collocation NLP's optimum is not the float model's to
    the last digit). With p2's nominal scale 200 times its standard error, a balance in scaled units saw two
    orthogonal gradients and took weights (1, 0) or (0, 1) by the rounding of a sign: time-only or trim-only
    standard errors, 5-10 times apart."""
    rng = np.random.default_rng(8)
    info = _linear_info(rng)
    info.S_trim = {"col": info.S_trim["col"] * np.array([1.0, 1.0, 0.0])}  # the trims do not see p2
    se_time = np.sqrt(np.diag(np.linalg.inv(info.fisher_time())))
    g_t = np.array([7.0 / se_time[0], 0.0, 1.0 / se_time[2]])  # 7 standard errors' worth along p0, 1 along p2
    g_r = np.array([-4 * g_t[0], 0.0, 0.0])
    info.e_time = {"y1": -np.linalg.pinv(info.S_time["y1"].T) @ g_t * info.R_time["y1"], "y2": np.zeros(200)}
    info.e_trim = {"col": np.linalg.pinv(info.S_trim["col"].T) @ (-g_r) * info.n_trims * DEG**2 / 2}
    np.testing.assert_allclose(info.grad_time(), g_t, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(info.grad_trim(), g_r, rtol=1e-6, atol=1e-9)
    ref = cramer_rao(info, _free(3), kind="eps")
    assert ref.combination == "weighted"
    a, b = ref.weights
    assert b / a == pytest.approx(0.25, rel=0.05)  # the trade along p0; p2's stray gradient moves it little
    for s2 in (1e-3, 200 * se_time[2], 1e4):
        info.scale = np.array([1.0, 1.0, s2])
        u = cramer_rao(info, _free(3), kind="eps")
        assert u.weights == pytest.approx(ref.weights, rel=1e-9), s2
        assert u.se == pytest.approx(ref.se, rel=1e-9), s2


def test_weights_from_the_gradients_are_eq11s_at_its_direct_solve():
    """An independent check of the multiplier estimate on a real front: the direct Eq. 11 solve of the committed
    Case 1 run (a copy in tests/results/case1) minimises sum_k ((J_k - U_k) / (N_k - U_k))^2, so it is stationary
    for a J_time + b J_trim with a, b proportional to (J_k - U_k) / (N_k - U_k)^2: known in closed form. The
    weights found from the float model's gradients alone agree with them, and so the standard errors."""
    from pyomo_heli.pareto.result import IdentificationResult
    from pyomo_heli.uncertainty.front import config_information, eq11_weights

    cfg = load_identification_config(CONFIGS / "case1.toml")
    res = IdentificationResult.load(HERE / "results" / "case1")
    exact = eq11_weights(res.direct, res.utopia, res.nadir)
    info = config_information(cfg, identification_data(cfg), res.direct["parameters"])
    found = cramer_rao(info, cfg.free, kind="direct")
    assert found.combination == "weighted"
    assert found.weights[1] / found.weights[0] == pytest.approx(exact[1] / exact[0], rel=0.01)
    assert found.se == pytest.approx(cramer_rao(info, cfg.free, weights=exact).se, rel=1e-3)


def test_weights_of_the_front_points_lie_between_the_fronts_slopes():
    """A second independent check, on every interior point of the committed Case 1 front: an epsilon point's
    multiplier b/a is -dJ_time/dJ_trim along the front (envelope theorem), so it lies between the slopes of the
    chords to its two neighbours (the front is convex there). The multiplier found from the gradients does."""
    from pyomo_heli.pareto.result import IdentificationResult
    from pyomo_heli.uncertainty.front import config_information

    cfg = load_identification_config(CONFIGS / "case1.toml")
    res = IdentificationResult.load(HERE / "results" / "case1")
    data = identification_data(cfg)
    f = res.front[res.front["success"].astype(bool)].sort_values("J_trim").reset_index(drop=True)
    checked = 0
    for r in range(1, len(f) - 1):
        if f.loc[r, "kind"] != "eps":
            continue
        info = config_information(cfg, data, {n: float(f.loc[r, n]) for n in res.parameters})
        a, b = cramer_rao(info, cfg.free, kind="eps").weights
        steeper = -(f.J_time[r] - f.J_time[r - 1]) / (f.J_trim[r] - f.J_trim[r - 1])
        flatter = -(f.J_time[r + 1] - f.J_time[r]) / (f.J_trim[r + 1] - f.J_trim[r])
        assert flatter <= b / a <= steeper, (int(f.loc[r, "index"]), b / a, flatter, steeper)
        checked += 1
    assert checked == 9


def test_weights_of_a_point_that_is_both_optima_are_the_time_domain_ones():
    """A degenerate front (noise-free data: A = B = every point): gradients of rounding size in
    arbitrary directions must not pick the weights; the point is J_time's optimum, so (1, 0), the same
    standard errors as point A, whatever the rounding noise."""
    info = _linear_info(np.random.default_rng(6))
    ref = cramer_rao(info, _free(3), kind="A")
    for seed in range(5):
        rng = np.random.default_rng(100 + seed)
        info.e_time = {o: 1e-13 * rng.normal(size=200) for o in info.S_time}
        info.e_trim = {"col": 1e-13 * rng.normal(size=info.n_trims)}
        u = cramer_rao(info, _free(3), kind="eps")
        assert u.weights == (1.0, 0.0) and u.combination == "time"
        assert u.se == ref.se
    # a real interior point (anti-parallel gradients of statistical size) keeps its own weights
    g = np.random.default_rng(7).normal(size=3)
    info.e_time = {"y1": -np.linalg.pinv(info.S_time["y1"].T) @ g * info.R_time["y1"], "y2": np.zeros(200)}
    info.e_trim = {"col": np.linalg.pinv(info.S_trim["col"].T) @ (4 * g) * info.n_trims * DEG**2 / 2}
    assert cramer_rao(info, _free(3), kind="eps").combination == "weighted"


def test_trim_data_separate_what_the_time_series_cannot_see():
    """Case 2 parameters at the truth on clean data (R set to the sensor noise): the time series'
    weakest direction is the twist; trim information lifts the weakest singular value, and the
    combined singular values are those of F_time + F_trim."""
    cfg = load_identification_config(CONFIGS / "small_case2.toml")
    ft = load_flight_test(cfg.dataset)
    data = prepare_data(ft, ["lon3211_80kt_a"], resample_hz=25, max_duration=6.0)
    trims = data.trims.iloc[::4].reset_index(drop=True)  # 6 of the 24 trim points keep it quick
    info = point_information(cfg.model, cfg.free, {f.name: TRUTH[f.name] for f in cfg.free}, data.maneuvers, trims,
                             cfg.nlp.time_outputs, cfg.nlp.trim_outputs)
    info.R_time = {o: SIGMA[o] ** 2 for o in info.R_time}  # clean data: use the known noise level
    info.R_trim = {o: (0.05 * DEG) ** 2 for o in info.R_trim}
    ident = identifiability(info)
    weak_time = ident.weakest("time")
    assert weak_time.direction.startswith("+") and abs(weak_time["v_theta_twist"]) > 0.9, weak_time.direction
    assert ident.weakest("combined").singular_value > 3 * weak_time.singular_value  # measured 4.7x
    D = np.diag(info.scale)
    F = D @ (info.fisher_time() + info.fisher_trim()) @ D
    sv = np.sort(ident.table.loc[ident.table.objective == "combined", "singular_value"].to_numpy())
    np.testing.assert_allclose(sv, np.sqrt(np.sort(np.linalg.eigvalsh(F))), rtol=1e-8)
    # the trim points alone cannot see the pitch inertia (a trim is an equilibrium)
    assert abs(ident.weakest("trim")["v_Iyy"]) > 0.99
    # ... at all: its singular value is round-off of the differences, reported as 0 with an infinite bound
    assert ident.weakest("trim").singular_value == 0.0 and ident.weakest("trim").se_scaled == np.inf
    assert ident.condition("trim") == np.inf
    assert "weakest direction" in ident.summary()


def test_a_numerically_zero_singular_value_is_reported_as_zero():
    """Trim sensitivities with known singular values 3 and 2 and a column only round-off reaches (1e-12):
    the table reports 3, 2 and 0, with an infinite Cramer-Rao bound along e_c; a weak direction the data
    do see (1e-5) keeps its value."""
    A = np.zeros((6, 3))
    A[0, 0], A[1, 1], A[2, 2] = 3.0, 2.0, 1e-12
    info = PointInformation(names=["a", "b", "c"], values={"a": 1.0, "b": 1.0, "c": 1.0}, scale=np.ones(3),
                            S_trim={"col": A}, e_trim={"col": np.zeros(6)}, R_trim={"col": 1.0})
    t = identifiability(info).table
    assert t.singular_value.tolist() == [3.0, 2.0, 0.0]
    assert t.se_scaled.tolist() == [pytest.approx(1 / 3), pytest.approx(0.5), np.inf]
    assert t.direction.iloc[2] == "+1.00 c" and identifiability(info).condition("trim") == np.inf
    A[2, 2] = 1e-5
    assert identifiability(info).table.singular_value.iloc[2] == pytest.approx(1e-5, rel=1e-12)


def test_realizations_carry_the_generators_low_speed_airspeed_noise():
    """The bundled generator records TAS with 1.0 m/s noise below 30 kt and 0.5 m/s above (flighttest.sensors);
    flight_test_noise returns both, and noisy_copy gives a maneuver trimmed below 30 kt the low-speed sigma and
    every other output and maneuver the same draws as without it (before, the Monte Carlo study gave its hover
    and 20 kt maneuvers half the airspeed noise the flight test has)."""
    import dataclasses

    from pyomo_heli.flighttest.config import flight_test_noise
    from pyomo_heli.units import KT

    sigma, _, (v_low, low) = flight_test_noise(HERE.parent / "data" / "bo105_synthetic.toml")
    assert sigma["TAS"] == pytest.approx(0.5) and low == {"TAS": pytest.approx(1.0)}
    assert v_low == pytest.approx(30 * KT)
    data = identification_data(load_identification_config(CONFIGS / "mc_time_small.toml"))
    mv = data.maneuvers[0]
    slow = dataclasses.replace(mv, name="slow", trim_speed=10 * KT)
    data = dataclasses.replace(data, maneuvers=[mv, slow] * 20)
    plain = noisy_copy(data, SIGMA, {}, seed=4, k=0)
    noisy = noisy_copy(data, SIGMA, {}, seed=4, k=0, low_speed=(v_low, low))
    for i, m in enumerate(noisy.maneuvers):
        for o in SIGMA:
            d, d0 = m.data[o] - data.maneuvers[i].data[o], plain.maneuvers[i].data[o] - data.maneuvers[i].data[o]
            scale = low["TAS"] / SIGMA["TAS"] if (o == "TAS" and m.name == "slow") else 1.0
            np.testing.assert_allclose(d, scale * d0, rtol=1e-12, atol=1e-12)  # (x + n) - x: rounding of x
    pooled = np.concatenate([(m.data["TAS"] - mv.data["TAS"]).to_numpy() for m in noisy.maneuvers if m.name == "slow"])
    assert np.std(pooled) == pytest.approx(1.0, rel=0.05)


def test_swapping_measured_data_equals_building_from_it():
    """An NLP with mutable data, re-pinned to a noise realization, has the objectives of an NLP
    built from that realization directly."""
    cfg = load_identification_config(CONFIGS / "mc_time_small.toml")
    data = identification_data(cfg)
    data.trims = data.trims.iloc[:5].reset_index(drop=True)
    noisy = noisy_copy(data, SIGMA, {"col": 0.1 * DEG}, seed=1, k=2)
    fixed = build_identification_nlp(noisy, cfg.model, cfg.free, cfg.nlp)
    opts = NLPOptions(**{**cfg.nlp.__dict__, "mutable_data": True})
    m = build_identification_nlp(data, cfg.model, cfg.free, opts)
    assert pyo.value(m.J_trim) != pytest.approx(pyo.value(fixed.J_trim), rel=1e-6)
    set_measurements(m, noisy)
    assert pyo.value(m.J_trim) == pytest.approx(pyo.value(fixed.J_trim), rel=1e-12)
    for o in cfg.nlp.time_outputs:
        assert pyo.value(m.R_hat[o, o]) == pytest.approx(pyo.value(fixed.R_hat[o, o]), rel=1e-12)
    with pytest.raises(ValueError, match="mutable_data"):
        set_measurements(fixed, noisy)


def test_standard_errors_are_written_to_front_chosen_and_report(tmp_path):
    """add_uncertainty on a hand-made result (no solve): se_ columns and at_bound in front.csv, the
    uncertainty entries in chosen.json / time_domain.json, identifiability.csv and the report section;
    the time-domain point's twist sits at its upper bound and is projected out."""
    import pandas as pd

    from pyomo_heli.pareto.result import IdentificationResult
    from pyomo_heli.report.uncertainty import uncertainty_section
    from pyomo_heli.uncertainty.front import add_uncertainty

    cfg = load_identification_config(CONFIGS / "small_case1.toml")
    data = prepare_data(load_flight_test(cfg.dataset), ["lon3211_80kt_a"], resample_hz=25, max_duration=4.0)
    data.trims = data.trims.iloc[::6].reset_index(drop=True)
    noisy = noisy_copy(data, SIGMA, {"col": 0.07 * DEG, "lon": 0.07 * DEG, "theta": 0.14 * DEG}, seed=3, k=0)
    base = {"epsilon": None, "J_time": -1.0, "J_trim": 0.2, "success": True, "status": "Solve_Succeeded",
            "iterations": 1, "wall_time": 0.0}
    pts = [dict(base, index=0, kind="A", parameters={"theta_twist": 0.0, "CL_alpha_HT": 6.2}),
           dict(base, index=1, kind="eps", parameters={"theta_twist": TRUTH["theta_twist"], "CL_alpha_HT": 6.2})]
    front = pd.DataFrame([{**{k: v for k, v in p.items() if k != "parameters"}, **p["parameters"]} for p in pts])
    res = IdentificationResult(front=front, parameters=["theta_twist", "CL_alpha_HT"],
                               units={"theta_twist": "rad/m", "CL_alpha_HT": "1/rad"}, utopia=(0, 0), nadir=(1, 1),
                               chosen=pts[1], direct=None, time_domain=pts[0])
    add_uncertainty(res, cfg, noisy, tmp_path, progress=lambda *_: None)
    f = pd.read_csv(tmp_path / "front.csv")
    assert f.loc[0, "at_bound"] == "theta_twist:upper" and math.isnan(f.loc[0, "se_theta_twist"])
    assert (f["se_CL_alpha_HT"] > 0).all() and f.loc[1, "se_theta_twist"] > 0
    again = IdentificationResult.load(tmp_path)
    u = again.chosen["uncertainty"]
    assert u["combination"] in ("weighted", "time", "trim") and u["correlation"][0][0] == pytest.approx(1.0)
    assert again.time_domain["uncertainty"]["se"]["theta_twist"] is None
    assert (tmp_path / "identifiability.csv").is_file()
    text = "\n".join(uncertainty_section(again, tmp_path, cfg.model))
    assert "at upper bound, projected out" in text and "weakest direction" in text


def test_uncertainty_command_names_a_missing_results_folder(tmp_path):
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "pyomo_heli", "uncertainty", str(CONFIGS / "small_case1.toml"),
                           "--results", str(tmp_path / "nowhere")], capture_output=True, text=True)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "nowhere" in proc.stderr and "front.csv" in proc.stderr


def test_a_direction_no_objective_sees_gets_an_infinite_error():
    """A pure trim fit cannot see a parameter the trims do not depend on (like Iyy): infinite, not zero."""
    info = _linear_info(np.random.default_rng(6))
    info.S_trim["col"][:, 2] = 0.0
    r = cramer_rao(info, _free(3), weights=(0.0, 1.0))
    assert r.se["p2"] == math.inf and np.isfinite([r.se["p0"], r.se["p1"]]).all()
    np.testing.assert_allclose([r.se["p0"], r.se["p1"]],
                               np.sqrt(np.diag(np.linalg.inv(info.fisher_trim()[:2, :2]))), rtol=1e-8)


def test_the_trim_anchor_takes_what_the_trims_cannot_see_from_the_time_series():
    """Anchor B minimises J_trim, then J_time among the trims' optima (lexicographic). A parameter the trims do not
    see (like Iyy) is then set by the time series: finite, not the pure trim fit's infinity (case2's committed B row
    read inf until the null test moved to nominal scales). Second method: the two-stage estimator's covariance,
    theta_1 from the trims alone, theta_2 = argmin J_time given theta_1 (time and trim noise independent)."""
    info = _linear_info(np.random.default_rng(7))
    info.S_trim["col"][:, 2] = 0.0
    for S in info.S_time.values():  # p2 an inertia-like parameter: 1e3 its nominal scale
        S[:, 2] *= 1e-3
    info.scale = np.array([1.0, 1.0, 1e3])
    info.values["p2"] = 4e3
    free = _free(2) + [FreeParameter("p2", 4e3, 1e3, 1e4, 1e3)]
    r = cramer_rao(info, free, kind="B")
    Ft, Hr, Gr = info.fisher_time(), info.hessian_trim(), info.gradient_covariance_trim()
    H11 = np.linalg.inv(Hr[:2, :2])
    cov1 = H11 @ Gr[:2, :2] @ H11
    k = Ft[2, :2] / Ft[2, 2]  # d theta_2 / d theta_1 at J_time's conditional optimum
    var2 = 1.0 / Ft[2, 2] + k @ cov1 @ k
    np.testing.assert_allclose([r.se["p0"], r.se["p1"], r.se["p2"]],
                               np.sqrt([cov1[0, 0], cov1[1, 1], var2]), rtol=1e-4)


def test_a_large_valued_parameter_beside_a_small_one_is_determined():
    """The flap spring K_beta (1e5 N m/rad) freed beside the twist (rad/m): in SI their information differs by 1e14,
    which an unscaled eigenvalue test reads as a null direction (an infinite standard error). In the parameters'
    nominal scales the problem is well conditioned: the standard errors are those of the inverse information."""
    rng = np.random.default_rng(3)
    N = 200
    S = {"q": np.column_stack([rng.normal(size=N) * 1e-6, rng.normal(size=N) * 10.0])}
    info = PointInformation(names=["K_beta", "theta_twist"], values={"K_beta": 2e5, "theta_twist": -0.03},
                            scale=np.array([1e5, 0.01]), S_time=S, e_time={"q": np.zeros(N)}, R_time={"q": 0.01},
                            S_trim={}, e_trim={}, R_trim={})
    free = [FreeParameter("K_beta", 2e5, 1e4, 1e6, 1e5), FreeParameter("theta_twist", -0.03, -0.2, 0.0, 0.01)]
    se = cramer_rao(info, free, kind="A").se
    direct = np.sqrt(np.diag(np.linalg.inv(info.fisher_time())))
    assert se["K_beta"] == pytest.approx(direct[0], rel=1e-8)
    assert se["theta_twist"] == pytest.approx(direct[1], rel=1e-8)


def test_fewer_trim_rows_than_parameters_leave_an_unseen_direction_with_an_infinite_bound():
    """Two trim rows, three parameters: the third direction is seen by no row. It is in the table with singular value
    0 and an infinite bound (a thin SVD would leave it out and report a finite condition number)."""
    A = np.array([[3.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    info = PointInformation(names=["a", "b", "c"], values={"a": 1.0, "b": 1.0, "c": 1.0}, scale=np.ones(3),
                            S_trim={"col": A}, e_trim={"col": np.zeros(2)}, R_trim={"col": 1.0})
    ident = identifiability(info)
    t = ident.table[ident.table.objective == "trim"]
    assert t.singular_value.tolist() == [3.0, 2.0, 0.0] and t.direction.iloc[2] == "+1.00 c"
    assert ident.condition("trim") == np.inf and ident.weakest("trim").se_scaled == np.inf


def test_noise_model_terms_the_information_leaves_out_are_named():
    """The Cramer-Rao information takes each output's noise white: with an AR output-noise model, input reference
    errors or a full covariance the standard errors are approximate, and ``approximations`` names each (the
    results record them and the report says so); the plain errors-in-variables config has none."""
    from pyomo_heli.uncertainty.front import approximations

    path = CONFIGS / "tiny_case1_input_errors.toml"
    assert approximations(load_identification_config(path)) == []
    cfg = load_identification_config(path, {"objectives": {"output_error_ar": 2, "input_reference_error": True}})
    got = approximations(cfg)
    assert len(got) == 2 and "AR(2)" in got[0] and "input_reference_error" in got[1]
