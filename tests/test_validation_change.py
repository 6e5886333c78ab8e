"""The paired (Diebold-Mariano) test of a validation error change against analytic and Monte Carlo cases."""
import numpy as np
import pytest

from pyomo_heli.diagnosis.validation_change import joint_mean_square_change, mean_square_change


def test_identical_models_change_nothing():
    rng = np.random.default_rng(1)
    n = rng.normal(0, 0.2, 1500)
    c = mean_square_change([n], [n.copy()], 50)
    assert c.ms1 == pytest.approx(c.ms0) and c.z == 0.0 and not c.rise_significant


def test_constant_offset_matches_the_analytic_standard_error():
    """r0 = n (white, sigma), r1 = n + c: D = c^2 + 2 c mean(n), se(D) = 2 sigma |c| / sqrt(N) exactly."""
    rng = np.random.default_rng(2)
    sigma, c, N = 0.3, 0.01, 20000
    n = rng.normal(0, sigma, N)
    ch = mean_square_change([n[:10000], n[10000:]], [n[:10000] + c, n[10000:] + c], 50)
    assert ch.ms1 - ch.ms0 == pytest.approx(c**2 + 2 * c * n.mean(), rel=1e-9)
    assert ch.segments == 400
    assert ch.se == pytest.approx(2 * sigma * c / N**0.5, rel=0.15)


def test_batch_standard_error_is_the_textbook_batch_means_one():
    """Six equal batches (whole records): se(D) = sd(batch means, ddof=1) / sqrt(6) (batch means), so that z is
    Student's t on 5 df for normal batches. A review found sum (m_b - m)^2 / B^2 (no ddof): se too small by
    sqrt(5 / 6), the rule firing at 6.3 % for a 5 % level."""
    rng = np.random.default_rng(11)
    r0 = [rng.normal(0, 0.2, 300) for _ in range(6)]
    r1 = [a + rng.normal(0, 0.05, 300) for a in r0]
    c = mean_square_change(r0, r1)
    means = np.array([np.mean(b**2 - a**2) for a, b in zip(r0, r1)])
    assert c.segments == 6
    assert c.se == pytest.approx(means.std(ddof=1) / 6**0.5, rel=1e-12)
    assert c.z == pytest.approx(means.mean() / (means.std(ddof=1) / 6**0.5), rel=1e-12)


def test_false_alarm_rate_with_six_normal_batches_is_alpha():
    """Equal-accuracy models, six records of white noise (normal batch means): the one-sided t test fires at
    alpha = 0.05 (4000 seeds, binomial sd 0.0034; the uncorrected se gave 0.0626)."""
    rng = np.random.default_rng(12)
    fired = 0
    for _ in range(4000):
        n = rng.normal(0, 1.0, (6, 40))
        e = rng.normal(0, 0.3, (6, 40))  # the two models' errors: equal energy, independent of the noise
        fired += mean_square_change(list(n + e), list(n - e), alpha=0.05).rise_significant
    assert 0.040 <= fired / 4000 <= 0.060


def test_large_offset_is_a_significant_rise_and_a_fall_is_not():
    rng = np.random.default_rng(3)
    n = rng.normal(0, 0.2, 3000)
    worse = mean_square_change([n], [n + 0.05], 50)
    better = mean_square_change([n + 0.05], [n], 50)
    assert worse.rise_significant and worse.rms_change_pct > 0
    assert not better.rise_significant and better.z < 0


@pytest.mark.parametrize("samples", [1500, 250])
def test_false_alarm_rate_under_equal_accuracy_is_near_alpha(samples):
    """Two models with errors of equal energy but different shape (sin vs cos over whole periods) plus the
    same white noise: no real rise, so the test should fire at about its level (Monte Carlo, 400 seeds).
    With 5 segments (250 samples) a normal reference would fire about 9 % of the time (P(t_4 > 1.645));
    Student's t keeps it at 5 %."""
    t = np.arange(samples) * 0.02
    e0, e1 = 0.05 * np.sin(2 * np.pi * 0.5 * t), 0.05 * np.cos(2 * np.pi * 0.5 * t)
    alpha, fired = 0.05, 0
    for seed in range(400):
        n = np.random.default_rng(seed).normal(0, 0.2, t.size)
        fired += mean_square_change([n + e0], [n + e1], 50, alpha=alpha).rise_significant
    assert 8 <= fired <= 32  # 20 expected, binomial sd 4.4


def test_false_alarm_rate_with_noise_coloured_over_seconds_is_near_alpha():
    """The noise of a replayed output is coloured far beyond a second (measured-input noise integrated through
    the dynamics). Twelve 13.5 s records of AR(1) noise with a 3 s correlation time, model errors of equal
    energy e0 = -e1 (so D = -4 mean(n e0) has mean zero): with whole records as batches (the default) the test
    fires at about its level; 1 s batches underestimate se(D) and fire several times as often (Monte Carlo,
    400 seeds)."""
    from scipy.signal import lfilter

    dt, n_rec, n_s, tau = 0.02, 12, 675, 3.0
    t = np.arange(n_s) * dt
    e0 = 0.05 * np.sin(2 * np.pi * t / 13.5)
    phi = np.exp(-dt / tau)
    alpha, fired, fired_1s = 0.05, 0, 0
    for seed in range(400):
        w = np.random.default_rng(seed).normal(0, 0.2 * (1 - phi**2) ** 0.5, (n_rec, n_s))
        n = lfilter([1.0], [1.0, -phi], w, axis=1)
        r0, r1 = [x + e0 for x in n], [x - e0 for x in n]
        c = mean_square_change(r0, r1, alpha=alpha)
        assert c.segments == n_rec
        fired += c.rise_significant
        fired_1s += mean_square_change(r0, r1, 50, alpha=alpha).rise_significant
    assert 8 <= fired <= 32  # 20 expected, binomial sd 4.4
    assert fired_1s > 60


@pytest.mark.parametrize("records, batches", [(1, 6), (2, 6), (4, 8), (6, 6), (12, 12)])
def test_few_records_are_cut_into_equal_batches(records, batches):
    rng = np.random.default_rng(4)
    r0 = [rng.normal(0, 0.2, 301) for _ in range(records)]
    c = mean_square_change(r0, [x + 0.01 for x in r0])
    assert c.segments == batches


def test_batches_are_cut_from_the_finite_samples():
    """A record with dropouts (NaN) is cut into six batches of its finite samples, not of its length."""
    rng = np.random.default_rng(5)
    r0 = rng.normal(0, 0.2, 301)
    r0[100:131] = np.nan
    assert mean_square_change([r0], [r0 + 0.01]).segments == 6


def test_bad_records_are_named():
    with pytest.raises(ValueError, match="record 0 has 3 samples for model 0, 2 for 1"):
        mean_square_change([np.zeros(3)], [np.zeros(2)], 1)
    with pytest.raises(ValueError, match="same non-empty list"):
        mean_square_change([], [], 1)


# --- all outputs at once (joint_mean_square_change) ---------------------------------------------------------------
def test_joint_change_is_the_sum_of_the_relative_mean_square_changes():
    """D = sum_o (ms1_o / ms0_o - 1) exactly, whatever the outputs' units; one output alone gives its own test."""
    rng = np.random.default_rng(6)
    r0 = {"q": [rng.normal(0, 0.01, 400) for _ in range(6)], "theta": [rng.normal(0, 3.0, 400) for _ in range(6)]}
    r1 = {"q": [x * 1.1 for x in r0["q"]], "theta": [x * 0.95 for x in r0["theta"]]}
    j = joint_mean_square_change(r0, r1)
    assert j.ms0 == 2 and j.ms1 - j.ms0 == pytest.approx((1.1**2 - 1) + (0.95**2 - 1), rel=1e-12)
    assert j.segments == 6
    one = joint_mean_square_change({"q": r0["q"]}, {"q": r1["q"]})
    alone = mean_square_change(r0["q"], r1["q"])
    assert one.z == pytest.approx(alone.z, rel=1e-12) and one.p_rise == pytest.approx(alone.p_rise, rel=1e-12)


def test_a_broad_small_rise_is_significant_jointly_and_on_no_output_alone():
    """Six outputs, independent white noise (sigma), each model-1 residual offset by c: each output's z has mean
    c sqrt(N) / (2 sigma) = 1.2 (p = 0.13 with 11 df), the joint z sqrt(6) times that, 2.9 (p = 0.007). Over
    200 seeds the joint test (alpha 0.01) fires about five times as often as any single output's, below the
    normal power of its expected z (0.73; the t reference with 11 df is stricter)."""
    from scipy.stats import norm

    sigma, N, K = 0.2, 3600, 6
    c = 1.2 * 2 * sigma / N**0.5
    alpha, joint, single = 0.01, 0, 0
    for seed in range(200):
        rng = np.random.default_rng(seed)
        r0 = {f"y{k}": list(rng.normal(0, sigma, (12, N // 12))) for k in range(K)}
        r1 = {o: [x + c for x in v] for o, v in r0.items()}
        joint += joint_mean_square_change(r0, r1, alpha=alpha).rise_significant
        single += sum(mean_square_change(r0[o], r1[o], alpha=alpha).rise_significant for o in r0)
    power = norm.sf(norm.isf(alpha) - 1.2 * K**0.5)
    assert 0.45 * 200 <= joint <= power * 200  # 128 of 200
    assert single / K < 0.2 * 200  # one output alone: 23 of 200


def test_joint_false_alarm_rate_with_correlated_outputs_is_near_alpha():
    """Three outputs whose noise is one AR(1) process (3 s correlation time) seen three times with different gains,
    so the outputs are fully correlated within a record; errors of equal energy e0 = -e1 per output. The whole-record
    batches carry the correlation: the joint test fires at about its level (Monte Carlo, 400 seeds)."""
    from scipy.signal import lfilter

    dt, n_rec, n_s, tau = 0.02, 12, 675, 3.0
    t = np.arange(n_s) * dt
    e0 = {"a": 0.05 * np.sin(2 * np.pi * t / 13.5), "b": 0.02 * np.cos(2 * np.pi * t / 6.75),
          "c": 0.1 * np.sin(2 * np.pi * t / 4.5)}
    gain = {"a": 1.0, "b": 0.3, "c": 2.0}
    phi = np.exp(-dt / tau)
    alpha, fired = 0.05, 0
    for seed in range(400):
        w = np.random.default_rng(seed).normal(0, 0.2 * (1 - phi**2) ** 0.5, (n_rec, n_s))
        n = lfilter([1.0], [1.0, -phi], w, axis=1)
        r0 = {o: [gain[o] * x + e0[o] for x in n] for o in e0}
        r1 = {o: [gain[o] * x - e0[o] for x in n] for o in e0}
        fired += joint_mean_square_change(r0, r1, alpha=alpha).rise_significant
    assert 8 <= fired <= 32  # 20 expected, binomial sd 4.4


def test_bad_joint_records_are_named():
    a = [np.ones(5)]
    with pytest.raises(ValueError, match="same non-empty set of outputs"):
        joint_mean_square_change({"q": a}, {"theta": a})
    with pytest.raises(ValueError, match="different records or sample counts"):
        joint_mean_square_change({"q": a, "theta": [np.ones(4)]}, {"q": a, "theta": [np.ones(4)]})
    with pytest.raises(ValueError, match="nothing to standardise by"):
        joint_mean_square_change({"q": [np.zeros(5)]}, {"q": a})


def test_by_speed_table_puts_a_rise_at_the_speed_where_it_is():
    """Two outputs, records at 0, 50 and 100 kt (two each, white noise); model 1 adds an offset to q at 100 kt only.
    By speed: every change is exactly zero but q's at 100 kt, whose RMS change is the analytic sqrt(1 + c^2 / ms0);
    the all-records table sees a smaller, diluted q rise."""
    from types import SimpleNamespace

    import pandas as pd

    from pyomo_heli.report.loop import JOINT, validation_change_by_speed, validation_change_table
    from pyomo_heli.units import KT

    rng = np.random.default_rng(7)
    t = np.arange(600) * 0.02
    mans, m0, m1, c = [], {}, {}, 0.02
    for kt in (0, 50, 100):
        for axis in ("lon", "col"):
            name = f"{axis}_{kt}"
            data = pd.DataFrame({"q": rng.normal(0, 0.01, t.size), "theta": rng.normal(0, 0.02, t.size)})
            mans.append(SimpleNamespace(name=name, t=t, data=data, trim_speed=kt * KT))
            m0[name] = pd.DataFrame({"q": np.zeros(t.size), "theta": np.zeros(t.size)})
            m1[name] = m0[name].assign(q=-c if kt == 100 else 0.0)
    p0, p1 = SimpleNamespace(maneuvers=m0), SimpleNamespace(maneuvers=m1)
    tab = validation_change_by_speed(p0, p1, mans).set_index("speed [kt]")
    assert list(tab.index) == [0.0, 50.0, 100.0] and list(tab["records"]) == [2, 2, 2]
    assert (tab.loc[[0.0, 50.0], ["q [%]", "theta [%]", "joint [%]"]].to_numpy() == 0).all()
    assert tab.loc[100.0, "theta [%]"] == 0
    q100 = np.concatenate([mv.data["q"].to_numpy() for mv in mans if mv.trim_speed == 100 * KT])
    ms0 = np.mean(q100**2)
    expected = 100 * (np.mean((q100 + c) ** 2) / ms0) ** 0.5 - 100
    assert tab.loc[100.0, "q [%]"] == pytest.approx(expected, rel=1e-9) and expected > 50
    assert tab.loc[100.0, "joint p (rise)"] < 0.01
    whole = validation_change_table(p0, p1, mans).set_index("output")
    assert 0 < whole.loc["q", "change [%]"] < expected and JOINT in whole.index


def test_the_change_table_says_when_the_two_models_pooled_other_records():
    """The loop's before/after change pools each iteration's RMS over the records its model could replay: when the
    first and the kept model lost different records (a divergence), every time-domain row says so; the trims'
    rows and a comparison over the same records carry no note."""
    import pandas as pd

    from pyomo_heli.report.loop import change_table

    def it(i, val, lost=()):
        return {"iteration": i, "extensions": [] if i == 0 else ["dM_q"], "J_time": -1.0, "J_trim": 0.1,
                "trim_rms": {"col": 0.002}, "identification_rms": {"q": 0.01}, "validation_rms": {"q": val},
                **({"not_replayed": list(lost)} if lost else {})}

    doc = {"iterations": [it(0, 0.02), it(1, 0.005, lost=["londoublet_100kt_val"])], "final_iteration": 1}
    tab = change_table(doc).set_index("error")
    note = tab.loc["val q [deg/s]", "note"]
    assert "not replayed by the first: none; by the kept: londoublet_100kt_val" in note
    assert tab.loc["id q [deg/s]", "note"] == note and pd.isna(tab.loc["trim col [deg]", "note"])
    same = {"iterations": [it(0, 0.02), it(1, 0.005)], "final_iteration": 1}
    assert "note" not in change_table(same).columns


def test_an_output_some_records_lack_is_tested_on_the_others():
    """beta_0 is optional per record: six validation records, one without it, the second model far worse on beta_0
    in every record. The table tests beta_0 on the five records that have it (a significant rise, the record left
    out named) and the joint row over the outputs every record has (a review: one record without beta_0 dropped
    the output from the validation rule without a word)."""
    from types import SimpleNamespace as NS

    import pandas as pd

    from pyomo_heli.report.loop import JOINT, validation_change_table

    rng = np.random.default_rng(0)
    outs = ["q", "theta", "n_x", "n_z", "TAS", "beta_0"]
    mans, p0, p1 = [], {}, {}
    for k in range(6):
        t = np.arange(0, 20, 0.02)
        cols = outs if k != 5 else outs[:-1]
        mans.append(NS(name=f"m{k}", data=pd.DataFrame({"t": t, **{o: rng.standard_normal(t.size) for o in cols}}),
                       t=t))
        p0[f"m{k}"] = pd.DataFrame({o: np.zeros(t.size) for o in outs})
        p1[f"m{k}"] = pd.DataFrame({**{o: np.zeros(t.size) for o in outs}, "beta_0": np.full(t.size, 0.5)})
    tab = validation_change_table(NS(maneuvers=p0), NS(maneuvers=p1), mans).set_index("output")
    assert "beta_0" in tab.index and bool(tab.loc["beta_0", "significant rise"])
    assert tab.loc["beta_0", "records without it"] == "m5" and tab.loc["beta_0", "segments"] == 10  # 5 records, 2 each
    assert tab.loc["beta_0", "change [%]"] == pytest.approx(100 * ((1 + 0.25) ** 0.5 - 1), abs=3)
    assert not tab.loc[["q", "theta", "n_x", "n_z", "TAS"], "significant rise"].astype(bool).any()
    assert JOINT in tab.index and pd.isna(tab.loc["q", "records without it"])
