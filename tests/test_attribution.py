"""The score test's errors-in-variables weighting (diagnosis/attribution.py, ``input_errors``).

With the measured inputs' errors eliminated, the time residuals of a maneuver have covariance
V = R + S_u Sigma_u S_u^T; the attribution whitens them with the Cholesky factor of V in time order.
Checked here against a second form of the same metric, the Schur complement over the input errors
(Woodbury: V^-1 = W - W S_u (S_u^T W S_u + Sigma_u^-1)^-1 S_u^T W, the form of the Cramer-Rao elimination),
and for causality (a whitened row depends on samples up to its own only, so batch means stay local).
"""
from __future__ import annotations

import numpy as np
import pytest

from pyomo_heli.dataset import load_flight_test
from pyomo_heli.diagnosis.attribution import _input_error_whitening, attribute, segment_ids
from pyomo_heli.nlp.identification import prepare_data
from pyomo_heli.nlp.objectives import lead_in_sigma
from pyomo_heli.simulation.compiled import input_sensitivities
from pyomo_heli.studies.small_instances import WAKE_MANEUVERS, make_case
from pyomo_heli.simulation.trim import trim_float

OUTPUTS = ["q", "theta", "n_x", "n_z", "TAS"]
TRIMS = ["col", "lon", "theta"]


@pytest.fixture(scope="module")
def instance(tmp_path_factory, flight_test_cache):
    root = tmp_path_factory.mktemp("attr")
    cfg = make_case(root, seed=21, free=("theta_twist",), points=2, maneuvers=WAKE_MANEUVERS, input_reference_s=1.9,
                    data_cache=flight_test_cache)
    # 3 s of each record (2 s lead-in, 1 s of the input) keep the dense matrices small
    data = prepare_data(load_flight_test(cfg.dataset), cfg.maneuvers, 25, 3.0, 1.9)
    return cfg, data


def test_whitening_is_the_input_error_eliminated_metric_and_causal(instance):
    cfg, data = instance
    model = cfg.model
    n_trims = len(data.trims)
    n_time = sum(len(mv.data) for mv in data.maneuvers)
    rows = n_time * len(OUTPUTS) + n_trims * len(TRIMS)
    rng = np.random.default_rng(7)
    w = np.concatenate([np.ones(n_time * len(OUTPUTS)), rng.uniform(1e3, 1e5, n_trims * len(TRIMS))])
    seg = segment_ids(data, OUTPUTS, n_trims, TRIMS, 1.0)
    whiten, seg_w = _input_error_whitening(model, data, OUTPUTS, w, seg, ("col", "lon"), None, 2)

    # the second form: Woodbury over the stacked (output-major) rows, maneuver by maneuver
    sigma = lead_in_sigma(data.maneuvers, OUTPUTS + ["col", "lon"])
    P = np.zeros((rows, rows))
    smooth, W_time = np.zeros(rows), np.zeros(n_time * len(OUTPUTS))
    start = 0
    for mv in data.maneuvers:
        t = mv.data["t"].to_numpy()
        _, S_u = input_sensitivities(model, trim_float(model, mv.trim_speed), t, mv.increments(), OUTPUTS,
                                     ("col", "lon"), 2)
        idx = np.concatenate([j * n_time + start + np.arange(len(t)) for j in range(len(OUTPUTS))])
        Su = np.vstack([S_u[o] for o in OUTPUTS])
        Wd = np.repeat([1.0 / sigma[o] ** 2 for o in OUTPUTS], len(t))
        prior = np.repeat([1.0 / sigma["col"] ** 2, 1.0 / sigma["lon"] ** 2], len(t))
        F_ee = (Su * Wd[:, None]).T @ Su + np.diag(prior)
        WSu = Wd[:, None] * Su
        P[np.ix_(idx, idx)] = np.diag(Wd) - WSu @ np.linalg.solve(F_ee, WSu.T)
        smooth[idx] = 1e-3 * Su[:, len(t):].sum(axis=1)  # a constant 1 mrad lon error over the record
        W_time[idx] = Wd
        start += len(t)
    trim_rows = np.arange(n_time * len(OUTPUTS), rows)
    P[trim_rows, trim_rows] = w[trim_rows]
    X = rng.standard_normal((rows, 4))
    X[: n_time * len(OUTPUTS)] *= 0.01  # SI-sized time residuals (rad, g)
    Z = whiten(X)
    G, G_ref = Z.T @ Z, X.T @ P @ X
    assert np.allclose(G, G_ref, rtol=1e-8, atol=1e-10 * np.abs(G_ref).max())
    # the input noise matters: the response to a lon input error spread over a record (a smooth direction)
    # weighs much less than with the sensor noise alone
    plain = float(smooth @ (np.concatenate([W_time, w[trim_rows]]) * smooth))
    eliminated = float(whiten(smooth) @ whiten(smooth))
    print(f"smooth direction: plain {plain:.4g}, input errors eliminated {eliminated:.4g}")
    assert eliminated < 0.5 * plain

    # causality: a change at samples >= k0 of the second maneuver leaves the whitened rows before k0
    n0, n1 = (len(mv.data) for mv in data.maneuvers)
    k0 = n1 // 2
    x = np.zeros(rows)
    for j in range(len(OUTPUTS)):
        x[j * n_time + n0 + k0: j * n_time + n0 + n1] = rng.standard_normal(n1 - k0)
    z = whiten(x)
    before = np.concatenate([j * n_time + np.arange(n0 + k0) for j in range(len(OUTPUTS))])
    assert np.all(z[before] == 0.0)
    # and every whitened row keeps the segment of its own sample
    assert np.array_equal(np.sort(seg_w), np.sort(seg))
    for j in range(len(OUTPUTS)):
        assert np.array_equal(seg_w[j * n_time: (j + 1) * n_time], seg[:n_time])


def test_unknown_variance_is_a_clear_error():
    with pytest.raises(ValueError, match="variance = 'hac'"):
        attribute(None, [], None, [], [], variance="hac")


def test_a_significant_candidate_below_a_non_significant_top_is_named():
    """Candidates are ranked by LM but judged on their own df: A (LM 40 on 2 df, p = 0.024) tops B (LM 15 on 200 df,
    p = 1.5e-4 < level 1e-3). The decision stays "none" (the top is not significant), but the message names B as
    significant below it instead of calling the residual unexplained by the library alone."""
    import pandas as pd

    from pyomo_heli.diagnosis.attribution import decide, none_message

    scores = pd.DataFrame({"name": ["A", "B"], "evidence": [40.0, 15.0], "LM": [40.0, 15.0], "df": [2.0, 200.0],
                           "p_value": [0.024, 1.5e-4], "significant": [False, True], "LM_needed": [60.0, 12.0]})
    proj = {"A": np.ones(3), "B": np.arange(3.0)}
    assert decide(["A", "B"], [40.0, 15.0], [False, True], proj)["decision"] == "none"
    msg = none_message(scores, 1e-3)
    assert "not decided: B (LM 15, df 200, p = 0.00015) is significant below it" in msg
    assert "not decided" not in none_message(scores.assign(significant=False), 1e-3)


def test_batch_means_score_is_the_t_test_of_the_segment_scores_and_keeps_its_level():
    """With a candidate of equal energy in each of B segments and no nuisance, the batch-means LM is the
    square of the one-sample t statistic of the segment scores (scipy.stats.ttest_1samp), and its p the t test's:
    F(1, B - 1) exactly. Over 4000 seeded white-noise draws with B = 5 the 1 % test fires 1 % of the time
    (before the variance was scaled back for kappa_hat it fired at 1.35 %)."""
    from scipy import stats

    from pyomo_heli.diagnosis.attribution import score_column

    B, n = 5, 40
    seg = np.repeat(np.arange(B), n)
    b, A = np.ones(B * n), np.zeros((B * n, 0))
    rng = np.random.default_rng(7)
    for _ in range(5):
        e = rng.normal(size=B * n)
        sc = score_column(A, e, b, seg, one_sided=False, variance="batch")
        t = stats.ttest_1samp(np.bincount(seg, weights=e), 0.0)
        assert sc["df"] == pytest.approx(B - 1, rel=1e-12)
        assert sc["LM"] == pytest.approx(t.statistic**2, rel=1e-10)
        assert sc["p_value"] == pytest.approx(t.pvalue, rel=1e-8)
    p = np.array([score_column(A, rng.normal(size=B * n), b, seg, False, "batch")["p_value"] for _ in range(4000)])
    assert abs(np.mean(p < 0.01) - 0.01) < 3 * np.sqrt(0.01 * 0.99 / 4000)
