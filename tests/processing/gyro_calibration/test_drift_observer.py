"""Tests of the Luenberger drift observer of paper 000 (processing.gyro_calibration.drift_observer, eqs. 3-8)."""

import numpy as np
import pytest

from processing.attitude import rotations
from processing.gyro_calibration.drift_observer import (
    MODE_CORRECTED,
    MODE_INIT,
    MODE_PREDICTED,
    MODE_RESUMED,
    DriftObserverError,
    acquisition_gains,
    fit_drift_trend,
    observer_gains,
    ramp_lag_s,
    run_drift_observer,
    slew_error_bound,
    stationary_noise,
)

ARCSEC_RAD = np.pi / 648000.0


def _channel(alpha, beta, n, drift, noise=None, ramp=0.0, gains=None):
    """One linear channel of eq. (4) in current form: returns the drift error after each step."""
    p = p_hat = b_hat = 0.0
    err = np.empty(n)
    for k in range(n):  # test only: the scalar recursion
        a, bb = gains(k) if gains else (alpha, beta)
        y = p + (noise[k] if noise is not None else 0.0)
        d = y - p_hat
        p_hat += a * d
        b_hat += bb * d  # here b_hat is the rate added to the prediction (the paper's sign)
        b_true = drift + ramp * k
        err[k] = b_true - b_hat
        p += b_true
        p_hat += b_hat
    return err


@pytest.mark.parametrize(("t_o", "t_r"), [(1.0, 60.0), (1.0, 200.0), (0.5, 30.0)])
def test_gains_place_the_poles(t_o, t_r):
    """000: z* = exp(nu T_o (-xi +- j sqrt(1 - xi^2))), nu = 3/(xi T_r), a1 = -(2 - g1), a0 = 1 - (g1 - T_o g2)."""
    xi = 0.95
    g1, g2 = observer_gains(t_o, t_r, xi)
    roots = np.roots([1.0, -(2.0 - g1), 1.0 - (g1 - t_o * g2)])
    nu = 3.0 / (xi * t_r)
    z = np.exp(nu * t_o * (-xi + 1j * np.sqrt(1 - xi * xi)))
    np.testing.assert_allclose(np.sort_complex(roots), np.sort_complex([z, np.conj(z)]), rtol=1e-10)
    # the envelope |z*|^(T_r / T_o) is the 5 % tube of 000
    assert abs(z) ** (t_r / t_o) == pytest.approx(np.exp(-3.0), rel=1e-12)
    # the current-form channel with alpha = g1 - T g2, beta = T g2 has the same poles: the error decays
    err = _channel(g1 - t_o * g2, t_o * g2, int(4 * t_r / t_o), drift=1.0)
    assert abs(err[-1]) < 0.01 and np.max(np.abs(err[int(2.5 * t_r / t_o):])) < 0.05


def test_gain_errors():
    with pytest.raises(DriftObserverError, match="0 < xi < 1"):
        observer_gains(1.0, 60.0, 1.0)


def test_acquisition_gains_are_the_least_squares_line():
    rng = np.random.default_rng(0)
    n = 40
    y = 0.3 + 0.02 * np.arange(n) + rng.normal(scale=0.01, size=n)
    p_hat, v_hat = y[0], 0.0
    for k in range(1, n):  # measurement k + 1
        p_pred = p_hat + v_hat
        a, b = acquisition_gains(k + 1)
        d = y[k] - p_pred
        p_hat, v_hat = p_pred + a * d, v_hat + b * d
    slope, intercept = np.polyfit(np.arange(n), y, 1)
    assert v_hat == pytest.approx(slope, rel=1e-12)
    assert p_hat == pytest.approx(intercept + slope * (n - 1), rel=1e-12)


def test_stationary_noise_and_ramp_lag_match_the_recursion():
    g1, g2 = observer_gains(1.0, 60.0)
    alpha, beta = g1 - g2, g2
    rng = np.random.default_rng(1)
    n = 40000
    err = _channel(alpha, beta, n, drift=0.0, noise=rng.normal(size=n))
    _, sd_drift = stationary_noise(1.0, 60.0, 1.0)
    assert np.std(err[1000:]) == pytest.approx(sd_drift, rel=0.1)
    ramp = 1e-4
    lag_err = _channel(alpha, beta, 3000, drift=0.0, ramp=ramp)[-1]
    assert lag_err / ramp == pytest.approx(ramp_lag_s(1.0, 60.0), abs=1.0)


def test_fit_drift_trend():
    t = np.linspace(0.0, 600.0, 601)
    b = np.stack([1e-6 + 1e-9 * t, -2e-6 + 1e-12 * (t - 300) ** 2, 3e-7 * np.ones_like(t)], axis=-1)
    trend = fit_drift_trend(t, b, 2)
    assert trend.degree == 2
    np.testing.assert_allclose(trend(t), b, atol=1e-20)
    np.testing.assert_allclose(trend.shifted(10.0)(t[:-10]), b[10:], atol=1e-20)
    assert fit_drift_trend(t[:150], b[:150], 2).degree == 1  # 149 s span: degree 1 at most
    assert fit_drift_trend(t[:1], b[:1], 2).degree == 0
    with pytest.raises(DriftObserverError, match="drift"):
        fit_drift_trend(t, b[:, :2], 2)


def _synthetic(n=400, drift_arcsec_s=(1.0, -0.8, 0.3), noise_arcsec=0.3, seed=0, w=(0.002, -0.001, 0.003)):
    """Constant rate about a fixed axis; the gyro measures w + b in the star-tracker axes (L = I)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    w = np.asarray(w)
    b = np.asarray(drift_arcsec_s) * ARCSEC_RAD
    q0 = rotations.quat_from_axis_angle([1.0, 2.0, 2.0], 0.4)
    q_true = rotations.quat_multiply(q0, rotations.rotvec_to_quat(w * t[:, None]))
    q_meas = rotations.quat_multiply(q_true, rotations.rotvec_to_quat(rng.normal(scale=noise_arcsec * ARCSEC_RAD,
                                                                                  size=(n, 3))))
    step = np.tile(rotations.rotvec_to_quat(w + b), (n - 1, 1))
    rotvec = np.tile(w + b, (n - 1, 1))
    return t, q_true, q_meas, step, rotvec, b


def test_observer_converges_to_the_drift():
    t, q_true, q_meas, step, rotvec, b = _synthetic()
    res = run_drift_observer(t, q_meas, step, rotvec, np.ones(t.size - 1, bool), np.ones(t.size, bool),
                             rate_map=np.eye(3), t_r_s=60.0)
    assert res.mode[0] == MODE_INIT and np.all(res.mode[1:] == MODE_CORRECTED)
    err = (res.drift_rad_s - b) / ARCSEC_RAD
    late = np.flatnonzero(np.any(np.abs(err) > 0.01, axis=1))
    assert late.max() < 60, late.max()  # within 0.01 "/s after 60 s (000: about 60 s)
    att = rotations.angle_between(res.q_post, q_true) / ARCSEC_RAD
    assert np.sqrt(np.mean(att[100:] ** 2)) < 0.3  # filtered attitude better than one star-tracker sample
    assert res.stationary[-1] and not res.stationary[5]
    g1, g2 = observer_gains(1.0, 60.0)
    assert res.gain_attitude[-1] == pytest.approx(g1 - g2) and res.gain_drift_s[-1] == pytest.approx(g2)
    # without acquisition gains the stationary observer converges too, later
    res_s = run_drift_observer(t, q_meas, step, rotvec, np.ones(t.size - 1, bool), np.ones(t.size, bool),
                               rate_map=np.eye(3), t_r_s=60.0, acquisition=False)
    err_s = np.abs(res_s.drift_rad_s - b) / ARCSEC_RAD
    assert np.all(err_s[-50:] < 0.02) and np.any(err_s[60] > 0.02)


def test_slew_prediction_and_resumption():
    t, q_true, q_meas, step, rotvec, b = _synthetic(n=500, noise_arcsec=0.0)
    on = np.ones(t.size, bool)
    on[300:360] = False  # a 60 s slew: correction off
    res = run_drift_observer(t, q_meas, step, rotvec, np.ones(t.size - 1, bool), on, rate_map=np.eye(3), t_r_s=60.0)
    assert np.all(res.mode[300:360] == MODE_PREDICTED) and res.mode[360] == MODE_RESUMED
    np.testing.assert_allclose(res.drift_rad_s[300:360], np.tile(b, (60, 1)), atol=1e-4 * ARCSEC_RAD)  # trend
    idx, innov = res.slew_end_errors()
    np.testing.assert_array_equal(idx, [360])
    # noise-free and the drift known: the prediction error over the slew is tiny, and the reset is exact
    assert np.linalg.norm(innov) < 0.01 * ARCSEC_RAD
    np.testing.assert_allclose(rotations.angle_between(res.q_post[360], q_true[360]), 0.0, atol=1e-12)
    # a gyro gap: the interval is skipped and the next sample re-initialises the attitude
    valid = np.ones(t.size - 1, bool)
    valid[200] = False
    res_g = run_drift_observer(t, q_meas, step, rotvec, valid, np.ones(t.size, bool), rate_map=np.eye(3))
    assert res_g.mode[201] == MODE_RESUMED


def test_observer_uses_the_rate_map_and_reference_drift():
    """With a scale factor in the rate map the drift comes out in the gyro frame (w_meas = (1 + m) w + b)."""
    t, q_true, q_meas, _, _, _ = _synthetic(noise_arcsec=0.0)
    m = 0.003
    w = np.array([0.002, -0.001, 0.003])
    b_G = np.array([1.0, -0.8, 0.3]) * ARCSEC_RAD
    b_ref = np.array([0.9, -0.7, 0.2]) * ARCSEC_RAD
    w_corr = ((1 + m) * w + b_G - b_ref) / (1 + m)  # the spline corrected with b_ref and m (eq. 2)
    step = np.tile(rotations.rotvec_to_quat(w_corr), (t.size - 1, 1))
    rotvec = np.tile(w_corr, (t.size - 1, 1))
    res = run_drift_observer(t, q_meas, step, rotvec, np.ones(t.size - 1, bool), np.ones(t.size, bool),
                             rate_map=np.eye(3) / (1 + m), drift_ref_rad_s=b_ref, t_r_s=60.0)
    np.testing.assert_allclose(res.drift_rad_s[-1], b_G, atol=1e-5 * ARCSEC_RAD)


def test_observer_input_errors():
    t, _, q_meas, step, rotvec, _ = _synthetic(n=10)
    with pytest.raises(DriftObserverError, match="shapes"):
        run_drift_observer(t, q_meas, step[:-1], rotvec, np.ones(9, bool), np.ones(10, bool), rate_map=np.eye(3))
    with pytest.raises(DriftObserverError, match="strictly increasing"):
        run_drift_observer(t[::-1], q_meas, step, rotvec, np.ones(9, bool), np.ones(10, bool), rate_map=np.eye(3))


def test_slew_error_bound():
    # 60 s, 150 deg, e0 = 0.3", db = 0.01 "/s, dm = 5e-5, dtheta = 1": 0.3 + 0.6 + 2.618 rad x (5e-5 + 4.85e-6)
    bound = slew_error_bound(60.0, np.radians(150.0), initial_error_rad=0.3 * ARCSEC_RAD,
                             drift_error_rad_s=0.01 * ARCSEC_RAD, scale_factor_error=-5e-5,
                             misalignment_error_rad=1.0 * ARCSEC_RAD)
    expected = 0.3 + 0.6 + np.radians(150.0) * (5e-5 / ARCSEC_RAD + 1.0)
    assert bound / ARCSEC_RAD == pytest.approx(expected, rel=1e-12)
    noisy = slew_error_bound(60.0, 0.0, initial_error_rad=0.0, drift_error_rad_s=0.0, scale_factor_error=0.0,
                             misalignment_error_rad=0.0, gyro_noise_rad=1e-9)
    assert noisy == pytest.approx(3e-9 * np.sqrt(60 * 128))
