"""Issue 17 item 3: robust star-tracker accuracy on the seed-003 simulator's failure cases, against truth.

Cases (20-min arcs, 3 s samples, 3 % gaps; noise 2.5/5/15" about x1 x2 x3 unless noted):
outliers (1 % of the samples 300" off about a random axis), first-order Gauss-Markov noise (tau 30 s),
a vibration line in the gyro only, clean white noise (no warning, 12 % accuracy kept, interval coverage).
The many-seed figures are in bench/star_tracker_robust.py; here a few seeds per case, chosen so that each
assertion would fail with the pre-issue-17 analysis (outlier_alpha=0 reproduces it for outliers).
"""

import numpy as np
import pytest
import scipy.signal
import scipy.stats

from processing.simulate.seed003 import simulate_seed003
from processing.star_tracker.accuracy import analyze_star_tracker_accuracy
from processing.star_tracker.robust import reject_outliers
from processing.star_tracker.whiteness import ResidualSeries, f_sf, sigma_interval, whiteness_test
from processing.time.timescales import iso_to_tai_ns
from processing.units import RAD_PER_ARCSEC

START = int(iso_to_tai_ns("2009-12-01T10:00:00"))
TRUTH = np.array([2.5, 5.0, 15.0]) * RAD_PER_ARCSEC
CALM = (0.0, 0.0, 0.0)


def simulate(seed, **kwargs):
    return simulate_seed003(start_tai_ns=START, seed=seed, gnss_period_s=1200.0, **kwargs)


def quiet(seed, **kwargs):
    """No vibration (no motion line above the cutoff), gyro every 1 s (not used), no gaps (the DST route):
    fast gyro-less runs for the many-seed statistics (gaps are in the other cases and in the bench)."""
    return simulate(seed, vibration_amplitude_rad=CALM, gyro_period_s=1.0, gap_fraction=0.0, **kwargs)


def analyze(sc, gyro=True, **kwargs):
    st, g = sc.streams["star_tracker"], sc.streams["gyro"]
    q = np.column_stack([st[f"q{i}"] for i in range(4)])
    extra = {}
    if gyro:
        extra = {"gyro_time_tai_ns": g["time_tai_ns"], "w_G_rad_s": np.column_stack([g["wx"], g["wy"], g["wz"]])}
    return analyze_star_tracker_accuracy(st["time_tai_ns"], q, sc.truth.q_BS, **extra, **kwargs)


# ---------------------------------------------------------------------------------------------
# Outliers


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_outliers_are_rejected_and_sigma_is_back_within_12_percent(seed):
    sc = simulate(seed, st_outlier_fraction=0.01)
    r = analyze(sc)
    true_mask = sc.truth.st_outlier_mask
    assert true_mask.sum() >= 3
    np.testing.assert_array_equal(r.outlier, true_mask)  # 300" is >= 20 sigma on every axis: all found, no other
    assert np.all(np.abs(r.sigma_rad / TRUTH - 1) < 0.12), r.sigma_rad / RAD_PER_ARCSEC
    # the reported residuals of the rejected samples are the outliers (against the fit through the others)
    size = np.linalg.norm(r.residuals_smoothing_rad[r.outlier], axis=1) / RAD_PER_ARCSEC
    assert np.all(np.abs(size - 300.0) < 40.0), size
    # the same data without the rejection: the issue's 20"-class figures
    plain = analyze(sc, outlier_alpha=0.0)
    assert plain.n_outliers == 0 and np.all(plain.sigma_rad[:2] > 2.5 * TRUTH[:2])


def test_rejection_reaches_a_fixed_point_and_rejected_samples_stay_out():
    sc = simulate(5, st_outlier_fraction=0.05, st_outlier_size_rad=60.0 * RAD_PER_ARCSEC, vibration_amplitude_rad=CALM,
                  gyro_period_s=1.0)  # with gaps
    r = analyze(sc, gyro=False, harmonics=40)
    found = r.outlier
    true_mask = sc.truth.st_outlier_mask
    # 60" is 24 / 12 / 4 sigma: nearly all found; what is missed lies mostly along x3 (the noisy axis)
    assert np.count_nonzero(found & true_mask) >= 0.8 * true_mask.sum()
    assert np.count_nonzero(found & ~true_mask) <= 1
    assert np.all(np.abs(r.sigma_rad / TRUTH - 1) < 0.15), r.sigma_rad / RAD_PER_ARCSEC
    seg = r.segments[0]
    assert seg.dof == (seg.stop - seg.start) - found.sum() - (40 + 2)
    # the sigma is the least-squares figure over the accepted samples only
    rss = np.sum(r.residuals_rad[~found] ** 2, axis=0)
    np.testing.assert_allclose(r.sigma_rad, np.sqrt(rss / seg.dof), rtol=1e-12)


def test_reject_outliers_alone_on_clean_segments_changes_nothing():
    from processing.star_tracker.accuracy import _check_inputs, _smooth_segments

    sc = quiet(7)
    st = sc.streams["star_tracker"]
    inp = _check_inputs(st["time_tai_ns"], np.column_stack([st[f"q{i}"] for i in range(4)]), sc.truth.q_BS, None)
    segs = _smooth_segments(inp, None, 1200.0, 120.0, "auto", 0.0).segments
    rej = reject_outliers(segs, "auto")
    assert rej.n_rejected == 0 and rej.iterations == 0 and rej.converged
    assert rej.segments[0] is segs[0]
    np.testing.assert_allclose(rej.scale_rad, TRUTH, rtol=0.15)  # the MAD scale estimates the noise


# ---------------------------------------------------------------------------------------------
# Whiteness


def test_gauss_markov_noise_is_flagged_and_white_noise_is_not():
    # 20 seeds each, no gyro (no motion lines: vibration off) to keep it fast; 200 in the bench
    gm = [analyze(quiet(s, st_noise_tau_s=30.0), gyro=False) for s in range(20)]
    white = [analyze(quiet(s), gyro=False) for s in range(20)]
    assert sum(r.whiteness.correlated for r in gm) >= 19
    assert sum(r.whiteness.correlated for r in white) <= 2  # alpha = 1 %: P(>= 3 of 20) = 0.1 %
    for r in gm:
        if r.whiteness.correlated:
            # GM noise with tau = 30 s: the sigma is a small fraction of the truth, and says so: the lower
            # bound is above it but still below the truth (the data cannot tell how much is absorbed)
            assert np.all(r.sigma_rad < 0.5 * TRUTH)
            assert np.all(r.sigma_lower_bound_rad >= r.sigma_rad) and np.any(r.sigma_lower_bound_rad > r.sigma_rad)
            assert np.all(r.sigma_lower_bound_rad < TRUTH)
            assert np.all(r.sigma_above_cutoff_rad < r.sigma_rad)
            assert np.all(r.sigma_dof < r.segments[0].dof)  # effective dof shrink
    for r in white:
        if not r.whiteness.correlated:
            np.testing.assert_array_equal(r.sigma_lower_bound_rad, r.sigma_rad)
            np.testing.assert_array_equal(r.sigma_dof, r.segments[0].dof)


def test_whiteness_test_alone_on_ar1_and_white_series():
    rng = np.random.default_rng(3)
    n, h = 400, 3.0
    t = np.arange(n) * h
    keep = np.ones(n, dtype=bool)
    keep[100:112] = False  # a gap
    phi = np.exp(-h / 10.0)
    p_white, p_red = [], []
    for _ in range(40):
        w = rng.standard_normal((n, 3))
        red = _ar1(w, phi)
        p_white.append(whiteness_test([ResidualSeries(t[keep], w[keep], np.ones(keep.sum(), bool), 0.02)], h).p_value)
        p_red.append(whiteness_test([ResidualSeries(t[keep], red[keep], np.ones(keep.sum(), bool), 0.02)], h).p_value)
    p_white, p_red = np.array(p_white), np.array(p_red)
    # white: p-values roughly uniform; red (tau 10 s): always tiny
    assert 0.35 < p_white.mean() < 0.65 and np.mean(p_white < 0.05) < 0.15
    assert np.all(p_red < 1e-3)


def _ar1(w, phi):
    drive = w * np.sqrt(1 - phi**2)
    drive[0] = w[0]
    return scipy.signal.lfilter([1.0], [1.0, -phi], drive, axis=0)


def test_f_sf_and_sigma_interval_match_scipy_stats():
    x = np.array([0.3, 1.0, 1.7, 4.0])
    np.testing.assert_allclose(f_sf(x, 30.0, 70.0), scipy.stats.f.sf(x, 30.0, 70.0), rtol=1e-10)
    sig = np.array([1.0, 2.0, 3.0])
    ci = sigma_interval(sig, np.array([10.0, 100.0, 1000.0]))
    nu = np.array([10.0, 100.0, 1000.0])
    np.testing.assert_allclose(ci[:, 0], sig * np.sqrt(nu / scipy.stats.chi2.ppf(0.975, nu)), rtol=1e-10)
    np.testing.assert_allclose(ci[:, 1], sig * np.sqrt(nu / scipy.stats.chi2.ppf(0.025, nu)), rtol=1e-10)


# ---------------------------------------------------------------------------------------------
# Clean data: no warning, accuracy and interval coverage


def test_clean_data_intervals_cover_the_truth():
    # 40 seeds x 3 axes; measured over 200 seeds in the bench
    runs = [analyze(quiet(s), gyro=False) for s in range(40)]
    ci = np.array([r.sigma_ci95_rad for r in runs])  # (40, 3, 2)
    covered = (ci[..., 0] <= TRUTH) & (TRUTH <= ci[..., 1])
    assert 0.88 <= covered.mean() <= 1.0, covered.mean(axis=0)
    assert sum(r.n_outliers > 0 for r in runs) <= 2
    err = np.array([r.sigma_rad / TRUTH - 1 for r in runs])
    assert np.all(np.abs(err) < 0.12), np.abs(err).max(axis=0)
    # the interval's width is the chi-square one of the least-squares dof: ~ +-1.96 / sqrt(2 dof)
    width = (ci[..., 1] - ci[..., 0]) / np.array([r.sigma_rad for r in runs])
    dof = np.array([r.sigma_dof for r in runs])
    np.testing.assert_allclose(width, 2 * 1.96 / np.sqrt(2 * dof), rtol=0.05)


@pytest.mark.parametrize("seed", [0, 3])
def test_clean_data_with_gyro_raise_nothing(seed):
    r = analyze(simulate(seed))
    assert r.n_outliers == 0 and not r.whiteness.correlated
    assert [c.removed for c in r.line_coherence] == [True]  # the real 0.4 Hz vibration is seen and removed
    c = r.line_coherence[0]
    assert abs(c.beta - 1.0) < 4 * c.beta_sigma and not c.gyro_only
    assert np.all(np.abs(r.sigma_rad / TRUTH - 1) < 0.12)


# ---------------------------------------------------------------------------------------------
# A line in the gyro only


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gyro_only_line_is_not_removed_and_flagged(seed):
    amp = (10.0 * RAD_PER_ARCSEC,) * 3  # 10"/s at 0.25 Hz: 6.4" attitude amplitude if it were motion
    sc = simulate(seed, gyro_line_amplitude_rad_s=amp, gyro_line_hz=0.25)
    r = analyze(sc)
    by_freq = {round(c.freq_hz, 2): c for c in r.line_coherence}
    assert set(by_freq) == {0.25, 0.4}
    fake, real = by_freq[0.25], by_freq[0.4]
    assert not fake.removed and fake.gyro_only and abs(fake.beta) < 4 * fake.beta_sigma
    assert real.removed and not real.gyro_only
    assert np.all(np.abs(r.sigma_rad / TRUTH - 1) < 0.12), r.sigma_rad / RAD_PER_ARCSEC
    gyro_rows = [x for x in r.lines if x.source == "gyro"]
    assert {(round(x.freq_hz, 2), x.removed) for x in gyro_rows} == {(0.25, False), (0.4, True)}
    # had the line been removed (as before issue 17), its oscillation would be added to the residuals
    assert np.all(fake.predicted_rms_rad[:2] > 0.5 * TRUTH[:2])


@pytest.mark.parametrize("gappy", [False, True])
def test_solver_leverage_is_the_hat_diagonal(gappy):
    from processing.signal.sine_series import SineSeriesSolver, sine_series_design

    t = np.arange(200) * 3.0
    w = np.ones(t.size)
    if gappy:
        w[[0, 50, 51, 120]] = 0.0  # rejected samples (zero weight), one at the segment start
    solver = SineSeriesSolver(t, 40, weights=w if gappy else None)
    assert solver.route == ("lstsq" if gappy else "dst")
    a = sine_series_design(t, 30, 0.0, t[-1])
    info_inv = np.linalg.inv(a.T @ (w[:, None] * a))
    expected = np.einsum("ij,jk,ik->i", a, info_inv, a)
    np.testing.assert_allclose(solver.leverage(30), expected, rtol=1e-8, atol=1e-12)
    assert abs(np.sum(expected * w) - 32) < 1e-8  # trace of the hat matrix = M + 2


def test_bursts_of_adjacent_outliers_are_rejected_one_per_pass():
    from processing.attitude import rotations

    for seed in range(4):
        sc = quiet(seed)
        st = sc.streams["star_tracker"]
        q = np.column_stack([st[f"q{i}"] for i in range(4)])
        idx = np.concatenate([np.arange(50, 53), np.arange(200, 203), np.arange(380, 383)])
        rng = np.random.default_rng(seed)
        axis = rng.standard_normal((idx.size, 3))
        q[idx] = rotations.quat_multiply(q[idx], rotations.rotvec_to_quat(
            200 * RAD_PER_ARCSEC * axis / np.linalg.norm(axis, axis=1, keepdims=True)))
        r = analyze_star_tracker_accuracy(st["time_tai_ns"], q, sc.truth.q_BS)
        np.testing.assert_array_equal(np.flatnonzero(r.outlier), idx)
        assert np.all(np.abs(r.sigma_rad / TRUTH - 1) < 0.12)
