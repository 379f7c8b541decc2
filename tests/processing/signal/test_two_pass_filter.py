"""Tests of the two-pass filter of gyro increments and its integration (processing.signal.two_pass_filter; 000)."""

import numpy as np
import pytest

from processing.attitude import rotations
from processing.signal.gyro_integration import interval_rotations, plan_substeps
from processing.signal.two_pass_filter import TwoPassFilterError, increments_from_rates, two_pass_filter
from processing.simulate.seed000 import simulate_seed000

ARCSEC_RAD = np.pi / 648000.0
H = 1.0 / 128.0
COEF = np.array([[0.3, -1.2, 0.8], [0.02, 0.05, -0.03], [-1e-3, 2e-3, 5e-4], [1e-4, -3e-5, 2e-5]])
"""Cubic quasi-coordinate F(t) = sum_p COEF[p] t^p per axis (rad, t in s)."""


def _cubic(t):
    t = np.asarray(t, dtype=float)[..., None]
    return sum(c * t**p for p, c in enumerate(COEF))


def _cubic_rate(t):
    t = np.asarray(t, dtype=float)[..., None]
    return sum(p * c * t ** (p - 1) for p, c in enumerate(COEF) if p > 0)


def _increments(t_end, t_start):
    return _cubic(t_end) - _cubic(t_start)


def test_reproduces_a_cubic_quasi_coordinate_exactly():
    """The first pass is exact for cubics and the quintic Hermite spline reproduces them too."""
    t_end = 1.0 + H * np.arange(1, 301)
    spline = two_pass_filter(t_end, _increments(t_end, t_end - H), np.full(t_end.size, H))
    assert spline.t_s.size == 301 and np.all(spline.valid)
    f_ref = _cubic(spline.t_s) - _cubic(spline.t_s[0])
    np.testing.assert_allclose(spline.f, f_ref, atol=1e-14)
    np.testing.assert_allclose(spline.d1, _cubic_rate(spline.t_s), atol=1e-11)
    t = np.linspace(spline.t_s[0], spline.t_s[-1], 1001)
    np.testing.assert_allclose(spline.rate(t), _cubic_rate(t), atol=1e-11)
    np.testing.assert_allclose(spline.angle(t), _cubic(t) - _cubic(spline.t_s[0]), atol=1e-14)


def test_irregular_spacing_uses_the_general_fit():
    rng = np.random.default_rng(0)
    dt = H * (1.0 + 0.2 * rng.uniform(-1, 1, 200))
    t_end = 2.0 + np.cumsum(dt)
    spline = two_pass_filter(t_end, _increments(t_end, t_end - dt), dt)
    t = np.linspace(spline.t_s[0], spline.t_s[-1], 500)
    np.testing.assert_allclose(spline.rate(t), _cubic_rate(t), atol=1e-10)


def test_spline_is_c2_and_rate_integrates_to_the_angle():
    rng = np.random.default_rng(1)
    t_end = H * np.arange(1, 2001)
    incr = _increments(t_end, t_end - H) + rng.normal(scale=1e-6, size=(2000, 3))
    spline = two_pass_filter(t_end, incr, np.full(2000, H))
    nodes = spline.t_s[5:-5]
    eps = 1e-9
    np.testing.assert_allclose(spline.rate(nodes - eps), spline.rate(nodes + eps), atol=1e-8)
    np.testing.assert_allclose(spline.rate(nodes), spline.d1[5:-5], atol=1e-12)
    # rate' continuity: second-order one-sided difference quotients agree with each other and with F^''
    e = 1e-6
    r0, r_m1, r_m2 = spline.rate(nodes), spline.rate(nodes - e), spline.rate(nodes - 2 * e)
    r_p1, r_p2 = spline.rate(nodes + e), spline.rate(nodes + 2 * e)
    d_left = (3 * r0 - 4 * r_m1 + r_m2) / (2 * e)
    d_right = (-3 * r0 + 4 * r_p1 - r_p2) / (2 * e)
    np.testing.assert_allclose(d_left, spline.d2[5:-5], atol=3e-8)
    np.testing.assert_allclose(d_right, spline.d2[5:-5], atol=3e-8)
    # int rate = angle difference on every segment (3-point Gauss-Legendre is exact for the quartic rate)
    x, wts = np.polynomial.legendre.leggauss(3)
    a, b = spline.t_s[:-1], spline.t_s[1:]
    nodes_gl = 0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * x
    integral = 0.5 * (b - a)[:, None] * np.einsum("j,njk->nk", wts, spline.rate(nodes_gl))
    np.testing.assert_allclose(integral, spline.f[1:] - spline.f[:-1], atol=1e-15)


def test_noise_is_reduced_and_the_total_angle_is_kept():
    rng = np.random.default_rng(2)
    sigma = 0.001 * ARCSEC_RAD
    n = 20000
    t_end = H * np.arange(1, n + 1)
    incr = rng.normal(scale=sigma, size=(n, 3))
    spline = two_pass_filter(t_end, incr, np.full(n, H))
    raw_rate_std = sigma / H  # rate from single increments
    # the cubic 9-sample fit of the random-walk quasi-coordinate: 0.55 of the raw std at the nodes
    assert np.std(spline.d1) < 0.6 * raw_rate_std
    # the smoothed quasi-coordinate does not wander from the raw sum (no accumulated error)
    np.testing.assert_allclose(spline.f[-100:] - np.cumsum(incr, axis=0)[-100:], 0.0, atol=5 * sigma)


def test_gaps_split_the_spline():
    t_end = H * np.arange(1, 1001)
    keep = np.ones(1000, dtype=bool)
    keep[400:450] = False
    incr = _increments(t_end, t_end - H)
    spline = two_pass_filter(t_end[keep], incr[keep], np.full(keep.sum(), H))
    assert spline.t_s.size == 950 + 2 and np.count_nonzero(~spline.valid) == 1
    assert np.all(np.isnan(spline.rate([t_end[420]])))
    # both runs are still exact (windows shifted inside each run)
    t = np.concatenate([np.linspace(0.0, t_end[399], 50), np.linspace(t_end[450] - H, t_end[-1], 50)])
    np.testing.assert_allclose(spline.rate(t), _cubic_rate(t), atol=1e-10)
    rot = interval_rotations(spline, [0.0, 2.0, 4.0, 7.0])
    np.testing.assert_array_equal(rot.valid, [True, False, True])
    # a run shorter than the window is fitted whole with a reduced degree
    short = two_pass_filter(t_end[:5], incr[:5], np.full(5, H))
    np.testing.assert_allclose(short.rate(t_end[:5]), _cubic_rate(t_end[:5]), atol=1e-9)


def test_increments_from_rates():
    t = np.arange(0.0, 10.0, 0.1)
    w = np.stack([0.1 + 0.01 * t, -0.2 * np.ones_like(t), 0.03 * t], axis=-1)  # linear: trapezoid exact
    t_end, incr, dt = increments_from_rates(t, w)
    np.testing.assert_allclose(t_end, t[1:])
    np.testing.assert_allclose(dt, 0.1)
    exact = dt[:, None] * (0.5 * (w[1:] + w[:-1]))
    np.testing.assert_allclose(incr, exact, rtol=1e-15, atol=0)
    t_gap = np.delete(t, np.arange(30, 40))
    t_end2, _, _ = increments_from_rates(t_gap, np.delete(w, np.arange(30, 40), axis=0))
    assert t_end2.size == t_gap.size - 2  # the interval across the gap is dropped
    with pytest.raises(TwoPassFilterError, match="strictly increasing"):
        increments_from_rates(t[::-1], w)


def test_correction_of_eq2():
    t_end = H * np.arange(1, 501)
    spline = two_pass_filter(t_end, _increments(t_end, t_end - H), np.full(500, H))
    dcm = rotations.quat_to_dcm(rotations.quat_from_axis_angle([1.0, 2.0, 3.0], 0.3))
    b, m = np.array([1e-5, -2e-5, 3e-5]), 0.004
    corr = spline.corrected(dcm, m, b)
    t = np.linspace(0.1, 3.8, 77)
    np.testing.assert_allclose(corr.rate(t), (spline.rate(t) - b) @ dcm.T / (1 + m), atol=1e-14)


def test_interval_rotations_exact_for_a_constant_axis():
    w = np.array([0.02, -0.05, 0.04])
    t_end = H * np.arange(1, 1281)
    spline = two_pass_filter(t_end, np.tile(w * H, (1280, 1)), np.full(1280, H))
    t_out = np.array([0.0, 1.0, 2.3, 4.0, 7.9, 10.0])  # output times inside segments split them
    rot = interval_rotations(spline, t_out)
    exact = rotations.rotvec_to_quat(w * np.diff(t_out)[:, None])
    np.testing.assert_allclose(rotations.angle_between(rot.q, exact), 0.0, atol=2e-14)  # rounding, 4e-9 arcsec
    assert np.all(rot.valid) and np.all(rot.error_rad < 1e-15)
    np.testing.assert_allclose(rot.max_rate_rad_s, np.linalg.norm(w), rtol=1e-12)
    # calibration and frame change: (w - b) / (1 + m), rotated into X by q_GX
    q_GX = rotations.quat_from_axis_angle([0.0, 1.0, 1.0], 0.7)
    b, m = np.array([1e-3, 0.0, -2e-3]), -0.003
    rot_c = interval_rotations(plan_substeps(spline, t_out), q_GX=q_GX, scale_factor_error=m, drift=b)
    w_X = rotations.quat_rotate(rotations.quat_conjugate(q_GX), (w - b) / (1 + m))
    exact_c = rotations.rotvec_to_quat(w_X * np.diff(t_out)[:, None])
    np.testing.assert_allclose(rotations.angle_between(rot_c.q, exact_c), 0.0, atol=2e-14)
    np.testing.assert_allclose(rot_c.rotvec_rad, w_X * np.diff(t_out)[:, None], atol=2e-14)


def test_interval_rotations_against_the_truth_of_seed000():
    """Noise-free increments through slews up to 5 deg/s: the integrated rotation over each 1 s matches
    the simulator's attitude to < 1e-4 arcsec (spline, eq. 2 correction with the true parameters, eq. 7)."""
    s = simulate_seed000(start_tai_ns=0, duration_s=240.0, seed=1, gyro_noise_std_rad=0.0,
                         st_noise_std_rad=(0.0, 0.0, 0.0))
    tr = s.truth
    g = s.streams["gyro_increments"]
    incr = np.stack([g["dax"], g["day"], g["daz"]], axis=-1)
    spline = two_pass_filter(tr.seconds(g["time_tai_ns"]), incr, g["interval_s"])
    t_st = tr.seconds(tr.st_time_tai_ns)
    rot = interval_rotations(spline, t_st, q_GX=tr.q_GS, scale_factor_error=tr.scale_factor_error,
                             drift=tr.drift_G_rad_s(0.0))
    exact = rotations.quat_multiply(rotations.quat_conjugate(tr.q_IS_st[:-1]), tr.q_IS_st[1:])
    err = rotations.angle_between(rot.q, exact)
    assert np.all(rot.valid)
    assert err.max() < 1e-4 * ARCSEC_RAD, err.max() / ARCSEC_RAD
    assert rot.max_rate_rad_s.max() == pytest.approx(5.0 * np.pi / 180, rel=0.01)


@pytest.mark.parametrize(
    ("args", "kwargs", "match"),
    [
        ((np.arange(3.0), np.zeros((3, 2)), np.ones(3)), {}, r"increments \(N, 3\)"),
        ((np.array([0.0, 1.0, 1.0]), np.zeros((3, 3)), np.ones(3)), {}, "strictly increasing"),
        ((np.arange(1.0, 4.0), np.zeros((3, 3)), np.zeros(3)), {}, "> 0"),
        ((np.arange(1.0, 4.0), np.zeros((3, 3)), np.ones(3)), {"window": 8}, "odd"),
        ((np.arange(1.0, 4.0), np.full((3, 3), np.nan), np.ones(3)), {}, "finite"),
    ],
)
def test_input_errors(args, kwargs, match):
    with pytest.raises(TwoPassFilterError, match=match):
        two_pass_filter(*args, **kwargs)
