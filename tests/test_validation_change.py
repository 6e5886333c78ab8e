"""The paired (Diebold-Mariano) test of a validation error change against analytic and Monte Carlo cases."""
import numpy as np
import pytest

from pyomo_heli.diagnosis.validation_change import mean_square_change


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
