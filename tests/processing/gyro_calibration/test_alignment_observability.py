"""Observability of the alignment parameters from the information matrix and the honest covariance
(processing.gyro_calibration.observability and its use in alignment.estimate_alignment; issue 17 item 2)."""

import numpy as np
import pytest

from processing.attitude import rotations
from processing.gyro_calibration.alignment import RateNoise, estimate_alignment
from processing.gyro_calibration.observability import (
    analyse_information,
    noise_floor,
    noise_meat,
    parameter_jacobian,
    truncated_inverse,
)
from processing.gyro_calibration.window_rates import star_tracker_window_rates

ARCSEC_RAD = np.pi / 648000.0
DEG_RAD = np.pi / 180.0
NAMES7 = ("scale_factor", "misalignment_x", "misalignment_y", "misalignment_z", "drift_x", "drift_y", "drift_z")


def _normal(w_A, per_axis=False, q_GS=(1.0, 0.0, 0.0, 0.0)):
    jac, names = parameter_jacobian(w_A, np.zeros(len(w_A)), np.asarray(q_GS), drift_degree=0,
                                    per_axis_scale_factor=per_axis)
    return np.einsum("nki,nkj->ij", jac, jac), names


def test_jacobian_matches_finite_differences_of_the_rate_model():
    """J of r = R_SG ((I + diag m) R_GS w + b) - w against finite differences of that model (per-axis scale)."""
    rng = np.random.default_rng(3)
    w = rng.normal(size=(5, 3)) * DEG_RAD
    q0 = rotations.quat_from_axis_angle([1.0, 2.0, -1.0], 0.7)
    jac, names = parameter_jacobian(w, np.zeros(5), q0, drift_degree=0, per_axis_scale_factor=True)
    assert names[:3] == ("scale_factor_x", "scale_factor_y", "scale_factor_z") and names[3:] == NAMES7[1:]

    def model(p):
        q = rotations.quat_multiply(q0, rotations.rotvec_to_quat(p[3:6]))  # S^Delta = R(q0) (I + [theta x])
        w_G = rotations.quat_rotate(q, w) * (1.0 + p[:3])
        return rotations.quat_rotate(rotations.quat_conjugate(q0), w_G + rotations.quat_rotate(q0, p[6:9])) - w

    h = 1e-7
    num = np.stack([(model(h * e) - model(-h * e)) / (2 * h) for e in np.eye(9)], axis=-1)
    # the drift column is in S axes (b_S); the model's drift enters in G and is mapped back, the same thing
    np.testing.assert_allclose(jac, num, rtol=1e-6, atol=1e-9)  # round-off of h = 1e-7 on unit columns


def test_constant_rate_determines_nothing():
    """Nadir pointing: one constant rate vector -> m, theta and b all confounded (rank 3 of 7)."""
    w = np.tile([0.0, -0.06, 0.0], (500, 1)) * DEG_RAD
    e_std = 1e-4 * 0.06 * DEG_RAD
    w = w + np.random.default_rng(0).normal(scale=e_std, size=w.shape)  # star-tracker rate noise
    nn, names = _normal(w)
    floor = noise_floor(names, np.full(500, e_std**2), np.ones(3), np.array([1.0, 0, 0, 0]))
    info = analyse_information(nn, names, noise_floor=floor)
    assert info.rank == 3 and not np.any(info.determinable)
    assert np.all(np.isinf(info.variance_inflation))
    # without the noise floor the rotation about the rate axis, a column of pure noise, looks informative
    # once scaled to unit diagonal (step 0 of the module docstring)
    assert analyse_information(nn, names).rank == 4


def test_one_axis_with_varying_rate_leaves_only_the_rotation_about_it():
    u = np.array([0.0, -np.sqrt(3) / 2, 0.5])
    mag = np.random.default_rng(1).uniform(0.05, 0.9, size=400) * DEG_RAD
    nn, names = _normal(mag[:, None] * u)
    info = analyse_information(nn, names)
    assert info.rank == 6
    np.testing.assert_array_equal(info.determinable, [True, True, False, False, True, True, True])
    # the null direction in parameter units is the rotation about u
    d = info.null_directions(slice(1, 4))
    assert d.shape == (3, 1) and abs(abs(d[:, 0] @ u) - 1.0) < 1e-9
    assert info.flags("misalignment_").tolist() == [True, False, False] and info.flags("drift_").all()


def test_all_axes_determine_everything_and_per_axis_scale_needs_each_axis():
    rng = np.random.default_rng(2)
    w = rng.normal(size=(600, 3)) * 0.5 * DEG_RAD
    info = analyse_information(*_normal(w))
    assert info.rank == 7 and info.determinable.all() and np.all(info.variance_inflation < 3)
    corr = info.correlation
    np.testing.assert_allclose(np.diag(corr), 1.0)
    # rates in the x-y plane only: the z scale factor has a zero column, and the misalignment about x and y
    # is seen only through the z-free rates (about z of the plane's normal: theta_x, theta_y need rates
    # perpendicular to them, which the plane has) -> only m_z is undetermined
    w_xy = w * [1.0, 1.0, 0.0]
    info = analyse_information(*_normal(w_xy, per_axis=True))
    assert info.names[2] == "scale_factor_z" and not info.determinable[2] and info.determinable[[0, 1]].all()


def test_truncated_inverse_is_the_inverse_of_the_determinable_problem():
    rng = np.random.default_rng(4)
    a = rng.normal(size=(50, 4)) * [1.0, 1e3, 1e-3, 1.0]  # badly scaled columns
    nn = a.T @ a
    np.testing.assert_allclose(truncated_inverse(nn), np.linalg.inv(nn), rtol=1e-9)
    # a fifth parameter identical to the first: neither determined, the others exactly as without them
    b = np.column_stack([a, a[:, 0]])
    n5 = b.T @ b
    inv5 = truncated_inverse(n5)
    a0, a1 = a[:, 0], a[:, 1:]  # the others given the confounded pair's sum (a nuisance regressor a0)
    sub = np.linalg.inv(a1.T @ a1 - np.outer(a1.T @ a0, a0 @ a1) / (a0 @ a0))
    np.testing.assert_allclose(inv5[1:4, 1:4], sub, rtol=1e-8)
    assert analyse_information(n5, tuple("abcde")).determinable.tolist() == [False, True, True, True, False]
    # stacks of matrices
    np.testing.assert_allclose(truncated_inverse(np.stack([nn, 2 * nn])), np.stack([np.linalg.inv(nn),
                                                                                    np.linalg.inv(nn) / 2]),
                               rtol=1e-9)


def _windows(rng, n_windows=40, axis=None, noise="white", sigma=0.3 * ARCSEC_RAD, n_seeds=1):
    """Star-tracker quaternions of n_windows 18-sample windows (1 Hz) of constant rotation about random axes
    (or one axis), with white or Gauss-Markov (tau 20 s) noise; n_seeds independent noise draws stacked as
    further windows. Returns t, q, starts, stops, the true rates per window (W, 3)."""
    t_all, q_all, w_all = [], [], []
    for j in range(n_windows):
        d = rng.normal(size=3) if axis is None else np.asarray(axis, float)
        d = d / np.linalg.norm(d)
        w = rng.uniform(0.2, 0.9) * DEG_RAD * d * rng.choice([-1.0, 1.0])
        tau = np.arange(18.0)
        q = rotations.quat_multiply(rotations.quat_from_axis_angle(rng.normal(size=3), 1.0),
                                    rotations.rotvec_to_quat(np.outer(tau, w)))
        t_all.append(40.0 * j + tau)
        q_all.append(q)
        w_all.append(w)
    t0, q0, w0 = np.concatenate(t_all), np.concatenate(q_all), np.array(w_all)
    k = t0.size
    t = np.concatenate([t0 + s * 40.0 * n_windows for s in range(n_seeds)])
    q = np.tile(q0, (n_seeds, 1))
    if noise == "white":
        n = rng.normal(scale=sigma, size=(k * n_seeds, 3))
    else:  # first-order Gauss-Markov, tau 20 s, the same variance
        phi = np.exp(-1.0 / 20.0)
        white = rng.normal(scale=sigma * np.sqrt(1 - phi**2), size=(k * n_seeds, 3))
        n = np.empty_like(white)
        n[0] = rng.normal(scale=sigma, size=3)
        for i in range(1, n.shape[0]):  # sequential recursion
            n[i] = phi * n[i - 1] + white[i]
    q = rotations.quat_multiply(q, rotations.rotvec_to_quat(n))
    starts = np.arange(n_windows * n_seeds) * 18
    return t, q, starts, starts + 18, np.tile(w0, (n_seeds, 1))


def _estimate(t, q, starts, stops, seeds, m=0.002, drift=(0.5, -0.3, 0.2), q_GS=None):
    """estimate_alignment per seed (windows split evenly), gyro rates exact: (1 + m) R w_true + b."""
    wr = star_tracker_window_rates(t, q, starts, stops)
    q_GS = rotations.rotvec_to_quat(np.array([30.0, -20.0, 45.0]) * ARCSEC_RAD) if q_GS is None else q_GS
    per = starts.size // seeds
    out = []
    sigma = np.sqrt(np.median(wr.residual_rms_rad**2, axis=0))
    for s in range(seeds):
        sel = (wr.window >= s * per) & (wr.window < (s + 1) * per)
        # the truth's rate at the T_p samples: constant per window
        w_true = _true_rates(t, q, starts, stops, wr, sel)
        w_G = (1.0 + m) * rotations.quat_rotate(q_GS, w_true) + np.asarray(drift) * ARCSEC_RAD
        est = estimate_alignment(wr.t_s[sel], w_G, wr.w_A_rad_s[sel], wr.window[sel], 1.0 / wr.rate_variance_s2[sel],
                                 q_GS_prior=q_GS, scale_factor_prior=m,
                                 noise=RateNoise(wr.rate_noise_gain[sel], sigma))
        out.append(est)
    return out, q_GS


_TRUE = {}


def _true_rates(t, q, starts, stops, wr, sel):
    return _TRUE["w"][wr.window[sel]]


@pytest.mark.parametrize("noise", ["white", "gauss_markov"])
def test_sigma_covers_the_truth_over_seeds(noise):
    """White star-tracker noise: z-scores of std ~1 (the white-noise model); Gauss-Markov noise (tau 20 s,
    which the window polynomials partly follow): the model alone would be too small, the residual factor
    and the jackknife check inflate it. Values within 3 sigma: >= 96 % of 4 x 40 seeds (expected 99.7 %).
    The many-seed figures of the whole chain: bench/alignment_observability.py."""
    rng = np.random.default_rng(7 if noise == "white" else 8)
    seeds = 40
    t, q, a, b, w = _windows(rng, n_windows=30, noise=noise, n_seeds=seeds)
    _TRUE["w"] = w
    ests, q_GS = _estimate(t, q, a, b, seeds)
    theta = rotations.quat_to_rotvec(q_GS)
    z = np.array([np.r_[(e.misalignment_rad - theta) / e.misalignment_sigma_rad,
                        (e.scale_factor_error - 0.002) / e.scale_factor_sigma] for e in ests])
    assert np.all(np.isfinite(z)) and all(e.complete for e in ests)
    assert np.mean(np.abs(z) <= 3.0) >= 0.96, np.std(z, axis=0)
    if noise == "white":
        assert np.all((np.std(z, axis=0) > 0.7) & (np.std(z, axis=0) < 1.35)), np.std(z, axis=0)
        assert np.median([e.residual_variance_factor for e in ests]) == pytest.approx(1.0, abs=0.15)


def test_noise_meat_matches_monte_carlo():
    """M = J^T W Cov(e) W J against the scatter of J^T W e over white-noise draws (vectorised over draws as
    windows): the T_p samples of a window are strongly correlated, so sum w_i J_i^T J_i var_i is far off."""
    rng = np.random.default_rng(11)
    sigma = 0.3 * ARCSEC_RAD
    t, q_clean, a, b, _ = _windows(rng, n_windows=1, noise="white", sigma=0.0, n_seeds=400)
    wr0 = star_tracker_window_rates(t, q_clean, a, b)
    q = rotations.quat_multiply(q_clean, rotations.rotvec_to_quat(rng.normal(scale=sigma, size=(t.size, 3))))
    wr = star_tracker_window_rates(t, q, a, b)
    e = wr.w_A_rad_s - wr0.w_A_rad_s
    sw = 1.0 / wr.rate_variance_s2
    jac, _ = parameter_jacobian(wr0.w_A_rad_s, np.zeros(sw.size), np.array([1.0, 0, 0, 0]), drift_degree=0)
    score = np.einsum("n,nkp,nk->np", sw, jac, e)
    per_window = np.stack([np.bincount(wr.window, weights=score[:, j]) for j in range(jac.shape[2])], axis=-1)
    empirical = per_window.T @ per_window / per_window.shape[0]
    meat = noise_meat(jac[wr.window == 0], sw[wr.window == 0], wr.rate_noise_gain[wr.window == 0],
                      np.zeros(int(np.sum(wr.window == 0)), dtype=np.intp), np.full(3, sigma))
    d = np.sqrt(np.diag(meat))
    np.testing.assert_allclose(empirical / np.outer(d, d), meat / np.outer(d, d), atol=0.2)
    independent = np.einsum("n,nki,nkj->ij", sw[wr.window == 0], jac[wr.window == 0], jac[wr.window == 0]) * sigma**2
    assert np.all(np.diag(meat) > 3 * np.diag(independent))  # treating T_p samples as independent: far too small


def test_per_axis_scale_factors_are_recovered():
    """Different scale factors per gyro axis, rates about all axes, exact data: the linear step recovers
    each (about the scalar prior), the scalar m is their rate-weighted mean."""
    rng = np.random.default_rng(5)
    n_win, per = 30, 40
    d = rng.normal(size=(n_win, 3))
    mag = rng.uniform(0.2, 0.9, size=(n_win, 1)) * DEG_RAD
    w_A = np.repeat(d / np.linalg.norm(d, axis=1, keepdims=True) * mag, per, axis=0)
    w_A = w_A * (1.0 + 0.2 * np.sin(np.arange(w_A.shape[0]) / 7.0))[:, None]
    win = np.repeat(np.arange(n_win), per)
    t = np.arange(w_A.shape[0]) * 0.125 + win * 20.0
    q_GS = rotations.quat_multiply(rotations.quat_from_axis_angle([1.0, 0.0, 0.0], -2.6),
                                   rotations.rotvec_to_quat(np.array([20.0, -30.0, 10.0]) * ARCSEC_RAD))
    m_true = np.array([0.001, 0.003, -0.002])
    w_G = rotations.quat_rotate(q_GS, w_A) * (1.0 + m_true) + np.array([0.4, -0.2, 0.1]) * ARCSEC_RAD
    est = estimate_alignment(t, w_G, w_A, win, q_GS_prior=q_GS, q_GS_nominal=q_GS, per_axis_scale_factor=True)
    est = estimate_alignment(t, w_G, w_A, win, q_GS_prior=est.q_GS, scale_factor_prior=est.scale_factor_error,
                             q_GS_nominal=q_GS, per_axis_scale_factor=True)
    np.testing.assert_allclose(est.scale_factor_per_axis, m_true, atol=2e-6)
    assert est.observability.names[:3] == ("scale_factor_x", "scale_factor_y", "scale_factor_z")
    assert m_true.min() < est.scale_factor_error < m_true.max()
