"""Tests of the off-line alignment and scale-factor estimate of paper 000
(processing.gyro_calibration.alignment, eq. 9)."""

import numpy as np
import pytest

from processing.attitude import rotations
from processing.gyro_calibration.alignment import estimate_alignment
from processing.gyro_calibration.window_rates import (
    AlignmentError,
    alignment_windows,
    star_tracker_window_rates,
)

ARCSEC_RAD = np.pi / 648000.0
DEG_RAD = np.pi / 180.0


def test_windows_tile_the_calibration_runs():
    lengths_on = [5, 12, 18, 30, 40, 20]
    eligible, t = [], []
    for n in lengths_on:
        eligible += [True] * n + [False] * 3
    eligible = np.array(eligible)
    t = np.arange(eligible.size, dtype=float)
    starts, stops = alignment_windows(t, eligible)
    assert (stops - starts).tolist() == [12, 18, 18, 12, 18, 18, 18]
    assert np.all(eligible[starts]) and all(np.all(eligible[a:b]) for a, b in zip(starts, stops, strict=True))
    # a time gap (missing star-tracker samples) breaks a run like an ineligible sample
    t_gap = t.copy()
    t_gap[45:] += 10.0
    s2, e2 = alignment_windows(t_gap, eligible)
    assert all(not (a < 45 <= b - 1) for a, b in zip(s2, e2, strict=True))
    assert alignment_windows(t, np.zeros(t.size, bool))[0].size == 0
    with pytest.raises(AlignmentError, match="n_min"):
        alignment_windows(t, eligible, n_min=20, n_max=18)


def _rotating(t, w_axis_rate, q0=None):
    q0 = rotations.quat_from_axis_angle([0.3, -1.0, 0.5], 1.1) if q0 is None else q0
    return rotations.quat_multiply(q0, rotations.rotvec_to_quat(np.outer(t, w_axis_rate)))


def test_star_tracker_rates_of_a_constant_rotation():
    w = np.array([0.5, -0.6, 0.3]) * DEG_RAD
    t = np.arange(0.0, 40.0)
    q = _rotating(t, w)
    wr = star_tracker_window_rates(t, q, np.array([0, 18]), np.array([18, 36]))
    assert wr.t_s[0] == 0.0 and wr.t_s[-1] == 35.0 and np.all(np.isin(wr.window, [0, 1]))
    assert np.count_nonzero(wr.window == 0) == 17 * 8 + 1  # every T_p = 0.125 s from the first to the last sample
    np.testing.assert_allclose(wr.w_A_rad_s, np.tile(w, (wr.t_s.size, 1)), atol=1e-12)
    np.testing.assert_allclose(wr.residual_rms_rad, 0.0, atol=1e-12)
    # the rate variance is small in the middle of a window and ~6x (in std) larger at its ends
    v = wr.rate_variance_s2[wr.window == 0]
    np.testing.assert_allclose(v, v[::-1], rtol=1e-9)
    assert v[len(v) // 2] < 2 * v.min() and 25 < v.max() / v.min() < 60


def test_star_tracker_rate_noise_matches_its_variance():
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 18.0)
    w = np.array([0.2, 0.1, -0.4]) * DEG_RAD
    q = _rotating(t, w)
    sigma = 0.3 * ARCSEC_RAD
    errs = []
    for _ in range(150):
        qn = rotations.quat_multiply(q, rotations.rotvec_to_quat(rng.normal(scale=sigma, size=(18, 3))))
        wr = star_tracker_window_rates(t, qn, np.array([0]), np.array([18]))
        errs.append(wr.w_A_rad_s - w)
    errs = np.array(errs)
    var = np.mean(errs**2, axis=(0, 2))
    np.testing.assert_allclose(var, wr.rate_variance_s2 * sigma**2, rtol=0.25)
    assert np.median(wr.residual_rms_rad) < 2 * sigma


def _synthetic_rates(n_windows=60, per_window=40, q_GS=None, m=0.003, drift=(1.0, -0.8, 0.3), axis=None, seed=0,
                     noise=0.0):
    """Rates of the star tracker (frame S) in windows with random directions (or about one axis), and the
    gyro's rates (1 + m) R(q_GS) w + b; optional per-window constant noise on the star-tracker rates."""
    rng = np.random.default_rng(seed)
    q_GS = rotations.rotvec_to_quat(np.array([40.0, -25.0, 55.0]) * ARCSEC_RAD) if q_GS is None else q_GS
    t, w_A, win = [], [], []
    for j in range(n_windows):
        d = rng.normal(size=3) if axis is None else np.asarray(axis, dtype=float)
        d /= np.linalg.norm(d)
        tau = np.linspace(0.0, 17.0, per_window)
        mag = rng.uniform(0.2, 0.9) * DEG_RAD * (1.0 + 0.2 * np.sin(tau / 5.0))
        t.append(30.0 * j + tau)
        w_A.append(mag[:, None] * d)
        win.append(np.full(per_window, j))
    t, w_A, win = np.concatenate(t), np.concatenate(w_A), np.concatenate(win)
    w_G = (1.0 + m) * rotations.quat_rotate(q_GS, w_A) + np.asarray(drift) * ARCSEC_RAD
    noisy = w_A + noise * rng.normal(size=(n_windows, 3))[win]
    return t, w_G, noisy, win, q_GS


def test_exact_recovery_of_misalignment_scale_and_drift():
    t, w_G, w_A, win, q_GS = _synthetic_rates()
    first = estimate_alignment(t, w_G, w_A, win, q_GS_prior=[1.0, 0.0, 0.0, 0.0])
    # the drift step is linearised about the prior: second-order terms (|theta|^2 ~ 1e-7) remain ...
    assert rotations.angle_between(first.q_GS, q_GS) < 1e-9
    # ... and vanish when the estimate is repeated about the first result (what calibrate_gyro iterates)
    est = estimate_alignment(t, w_G, w_A, win, q_GS_prior=first.q_GS, scale_factor_prior=first.scale_factor_error)
    np.testing.assert_allclose(rotations.angle_between(est.q_GS, q_GS), 0.0, atol=1e-13)
    np.testing.assert_allclose(est.misalignment_rad, rotations.quat_to_rotvec(q_GS), atol=1e-12)
    assert est.scale_factor_error == pytest.approx(0.003, abs=1e-12)
    np.testing.assert_allclose(est.drift_offset(t[:3]), np.tile(np.array([1.0, -0.8, 0.3]) * ARCSEC_RAD, (3, 1)),
                               atol=1e-12)
    assert est.solver_disagreement_rad < 1e-12 and np.all(est.observable_axes)
    assert est.n_windows == 60 and est.n_samples == 2400
    np.testing.assert_allclose(est.residual_rad_s, 0.0, atol=1e-12)
    assert np.all(est.spread_eigenvalues > 0.5) and est.spread_eigenvalues.sum() == pytest.approx(2.0)


def test_recovery_relative_to_a_nominal_mounting_and_with_a_drift_ramp():
    q_nom = rotations.quat_from_axis_angle([1.0, 0.0, 0.0], -150 * DEG_RAD)
    small = rotations.rotvec_to_quat(np.array([-30.0, 20.0, 45.0]) * ARCSEC_RAD)
    q_GS = rotations.quat_multiply(q_nom, small)
    t, w_G, w_A, win, _ = _synthetic_rates(q_GS=q_GS, m=-0.004)
    w_G = w_G + np.outer(t - 900.0, [1e-9, -2e-9, 5e-10])  # a drift ramp, fitted by the degree-1 offset
    est = estimate_alignment(t, w_G, w_A, win, q_GS_prior=q_nom, q_GS_nominal=q_nom, drift_degree=1)
    est = estimate_alignment(t, w_G, w_A, win, q_GS_prior=est.q_GS, scale_factor_prior=est.scale_factor_error,
                             q_GS_nominal=q_nom, drift_degree=1)
    np.testing.assert_allclose(est.misalignment_rad, np.array([-30.0, 20.0, 45.0]) * ARCSEC_RAD, atol=1e-11)
    assert est.scale_factor_error == pytest.approx(-0.004, abs=1e-11)


def test_jackknife_sigma_matches_the_scatter():
    errors, sigmas, m_err, m_sig = [], [], [], []
    for seed in range(25):
        t, w_G, w_A, win, q_GS = _synthetic_rates(seed=seed, noise=0.05 * ARCSEC_RAD)
        est = estimate_alignment(t, w_G, w_A, win, q_GS_prior=q_GS)
        errors.append(est.misalignment_rad - rotations.quat_to_rotvec(q_GS))
        sigmas.append(est.misalignment_sigma_rad)
        m_err.append(est.scale_factor_error - 0.003)
        m_sig.append(est.scale_factor_sigma)
    ratio = np.std(errors, axis=0) / np.mean(sigmas, axis=0)
    assert np.all((ratio > 0.6) & (ratio < 1.6)), ratio
    assert 0.6 < np.std(m_err) / np.mean(m_sig) < 1.6


def test_rotation_about_one_axis_is_not_observable():
    t, w_G, w_A, win, q_GS = _synthetic_rates(axis=(0.0, 0.0, 1.0))
    est = estimate_alignment(t, w_G, w_A, win, q_GS_prior=[1.0, 0.0, 0.0, 0.0])
    assert est.spread_eigenvalues[0] < 1e-12
    np.testing.assert_array_equal(est.observable_axes, [True, True, False])
    assert np.isnan(est.misalignment_sigma_rad[2])
    # the rate axis is mapped like the truth; the turn about it is held at the prior (the nominal mounting),
    # so x and y equal the truth's up to the second-order coupling with its z (~ theta_z theta_xy / 2)
    # (up to the pull of the pseudo-pairs, REGULARISATION x the offset from the prior ~ 4e-11 rad)
    np.testing.assert_allclose(rotations.quat_rotate(est.q_GS, [0, 0, 1.0]), rotations.quat_rotate(q_GS, [0, 0, 1.0]),
                               atol=1e-10)
    assert abs(est.misalignment_rad[2]) < 1e-12
    np.testing.assert_allclose(est.misalignment_rad[:2], rotations.quat_to_rotvec(q_GS)[:2], atol=5e-8)
    assert est.scale_factor_error == pytest.approx(0.003, abs=1e-9)


def test_alignment_input_errors():
    t, w_G, w_A, win, _ = _synthetic_rates(n_windows=2)
    with pytest.raises(AlignmentError, match="at least 3 alignment windows"):
        estimate_alignment(t, w_G, w_A, win, q_GS_prior=[1, 0, 0, 0])
    with pytest.raises(AlignmentError, match="expected"):
        estimate_alignment(t, w_G[:, :2], w_A, win, q_GS_prior=[1, 0, 0, 0])
    with pytest.raises(AlignmentError, match="no alignment windows"):
        star_tracker_window_rates(t, np.tile([1.0, 0, 0, 0], (t.size, 1)), np.zeros(0, int), np.zeros(0, int))
