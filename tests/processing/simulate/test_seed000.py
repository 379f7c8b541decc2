"""Tests of the paper-000 truth simulator (processing.simulate.seed000)."""

import numpy as np
import pytest

from processing.attitude import rotations
from processing.orbits.two_body import sun_synchronous_inclination_rad
from processing.simulate.seed000 import (
    GYRO_PERIOD_NS,
    Q_OB_NADIR,
    Scenario000,
    Seed000ParameterError,
    plan_maneuvers,
    simulate_seed000,
)
from processing.streams import STREAMS
from processing.time.timescales import iso_to_tai_ns
from processing.units import R_EARTH_M, RAD_PER_ARCSEC, RAD_PER_DEG
from tests.processing.helpers import assert_same_streams, chi2_bounds

START = int(iso_to_tai_ns("2016-06-01T00:00:00"))
NS = 1_000_000_000


@pytest.fixture(scope="module")
def scenario() -> Scenario000:
    return simulate_seed000(start_tai_ns=START, duration_s=600.0, seed=5)


def test_determinism_by_seed():
    a = simulate_seed000(start_tai_ns=START, duration_s=120.0, seed=3)
    b = simulate_seed000(start_tai_ns=START, duration_s=120.0, seed=3)
    c = simulate_seed000(start_tai_ns=START, duration_s=120.0, seed=4)
    assert_same_streams(a.streams, b.streams)
    assert a.parameters["misalignment_rad"] == b.parameters["misalignment_rad"]
    assert not np.array_equal(a.streams["gyro_increments"]["dax"], c.streams["gyro_increments"]["dax"])
    assert a.parameters["scale_factor_error"] != c.parameters["scale_factor_error"]


def test_streams_follow_the_canonical_schemas(scenario):
    assert set(scenario.streams) == {"star_tracker", "gyro_increments"}
    for stream, cols in scenario.streams.items():
        assert set(cols) == {"time_tai_ns", "sensor", *STREAMS[stream].column_names}
        assert cols["time_tai_ns"].dtype == np.int64
        n = cols["time_tai_ns"].size
        for name in STREAMS[stream].column_names:
            assert cols[name].dtype == np.float64 and cols[name].shape == (n,)
    st = scenario.streams["star_tracker"]
    q = np.stack([st[f"q{i}"] for i in range(4)], axis=-1)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-15)
    assert np.all(q[:, 0] >= 0) and set(st["sensor"]) == {"st1"}
    assert set(scenario.streams["gyro_increments"]["sensor"]) == {"gyro"}
    cfg = scenario.config
    # the gyro is nominally aligned with the star tracker (000: bases A and G coincide nominally)
    assert cfg["gyro"]["q_BG"] == cfg["star_trackers"]["st1"]["q_BS"]
    # boresight 30 deg from anti-nadir (-z body)
    boresight_B = rotations.quat_rotate(scenario.truth.q_BS, [0.0, 0.0, 1.0])
    np.testing.assert_allclose(boresight_B, [0.0, 0.5, -np.sqrt(3) / 2], atol=1e-15)


def test_grids(scenario):
    g = scenario.streams["gyro_increments"]
    st = scenario.streams["star_tracker"]
    assert g["time_tai_ns"].size == 600 * 128 == 76_800
    assert g["time_tai_ns"][0] == START + GYRO_PERIOD_NS and g["time_tai_ns"][-1] == START + 600 * NS
    assert np.all(np.diff(g["time_tai_ns"]) == GYRO_PERIOD_NS)
    np.testing.assert_array_equal(g["interval_s"], 1.0 / 128.0)
    assert st["time_tai_ns"].size == 601 and np.all(np.diff(st["time_tai_ns"]) == NS)
    assert np.all(np.isin(st["time_tai_ns"][1:], g["time_tai_ns"]))  # T_o a multiple of T_q (000)


def test_calibration_errors_drawn_in_their_ranges():
    for seed in range(8):
        p = simulate_seed000(start_tai_ns=START, duration_s=1.0, seed=seed).parameters
        mis = np.abs(np.asarray(p["misalignment_rad"])) / RAD_PER_ARCSEC
        assert np.all((mis >= 20) & (mis <= 60))  # "tens of arcseconds"
        assert 0.001 <= abs(p["scale_factor_error"]) <= 0.005  # "a few tenths of a percent"
    s = simulate_seed000(start_tai_ns=START, duration_s=1.0, misalignment_rad=(1e-4, 0.0, -2e-4),
                         scale_factor_error=-0.002)
    np.testing.assert_allclose(s.truth.misalignment_rad, [1e-4, 0.0, -2e-4], rtol=1e-12)
    assert s.truth.scale_factor_error == -0.002


def test_orbit_is_720_km_sun_synchronous(scenario):
    tr = scenario.truth
    assert tr.a_m == R_EARTH_M + 720e3
    assert tr.inc_rad == pytest.approx(float(sun_synchronous_inclination_rad(tr.a_m)))
    assert 98.0 < tr.inc_rad / RAD_PER_DEG < 98.5


def test_maneuver_plan():
    plan = plan_maneuvers(
        3600.0, np.random.default_rng(2), mean_motion=1.05e-3, initial_hold_s=120.0, slew_duration_s=(40.0, 60.0),
        slew_peak_rate_rad_s=(2 * RAD_PER_DEG, 5 * RAD_PER_DEG), scan_duration_s=(60.0, 120.0),
        scan_peak_rate_rad_s=(0.3 * RAD_PER_DEG, 0.9 * RAD_PER_DEG), hold_duration_s=(0.0, 10.0),
    )
    assert plan.kind[0] == "hold" and plan.duration_s[0] == 120.0  # orbital orientation first
    np.testing.assert_allclose(plan.start_s[1:], plan.start_s[:-1] + plan.duration_s[:-1])
    slews, scans = plan.kind == "slew", plan.kind == "scan"
    assert slews.sum() >= 15 and scans.sum() >= 15
    peak_slew = plan.peak_rate_rad_s[slews] / RAD_PER_DEG
    assert np.all((peak_slew >= 2.0) & (peak_slew <= 5.0)) and peak_slew[0] == 5.0
    d = plan.duration_s[slews]
    assert np.all((d >= 40.0) & (d <= 60.0)) and d[0] == 60.0  # the worst case first
    assert np.all(plan.peak_rate_rad_s[scans] < 1.0 * RAD_PER_DEG)
    np.testing.assert_allclose(np.linalg.norm(plan.axis_B, axis=-1), 1.0, rtol=1e-14)
    # the rate is continuous across segment boundaries and reaches the peaks in the middle
    t_b = plan.start_s[1:]
    np.testing.assert_allclose(plan.w_B(t_b - 1e-6), plan.w_B(t_b + 1e-6), atol=1e-9)
    mid = plan.start_s[slews] + 0.5 * plan.duration_s[slews]
    w_mid = np.linalg.norm(plan.w_B(mid), axis=-1)
    np.testing.assert_allclose(w_mid, plan.peak_rate_rad_s[slews], atol=2 * plan.mean_motion_rad_s)
    # the initial hold is the nadir orientation: body z to nadir, rate (0, -n, 0)
    np.testing.assert_array_equal(plan.q_OB([0.0, 60.0]), [Q_OB_NADIR, Q_OB_NADIR])
    np.testing.assert_allclose(plan.w_B(60.0), [0.0, -plan.mean_motion_rad_s, 0.0], atol=1e-18)


def test_increments_follow_eq1(scenario):
    """i_s = (1 + m) S^Delta Int(w_S + b^g) + noise: the residual is the configured white noise."""
    tr = scenario.truth
    g = scenario.streams["gyro_increments"]
    incr = np.stack([g["dax"], g["day"], g["daz"]], axis=-1)
    t_end = tr.seconds(g["time_tai_ns"])
    h = tr.gyro_period_s
    # 5-point Gauss-Legendre of the truth rate (the simulator uses 2 points)
    x, wts = np.polynomial.legendre.leggauss(5)
    nodes = (t_end - 0.5 * h)[:, None] + 0.5 * h * x
    w_S = tr.w_S(nodes) + tr.drift_rad_s(nodes)
    integral = 0.5 * h * np.einsum("j,njk->nk", wts, w_S)
    expected = (1.0 + tr.scale_factor_error) * rotations.quat_rotate(tr.q_GS, integral)
    noise = incr - expected
    sigma = tr.gyro_noise_std_rad
    assert sigma == pytest.approx(0.001 * RAD_PER_ARCSEC)
    lo, hi = chi2_bounds(noise.shape[0])
    ratio = np.mean(noise**2, axis=0) / sigma**2
    assert np.all((ratio > lo) & (ratio < hi)), ratio
    assert np.all(np.abs(noise.mean(axis=0)) < 4 * sigma / np.sqrt(noise.shape[0]))
    # noise-free: the 2-point quadrature agrees with 5 points to ~1e-16 rad per increment, 1e-14 rad
    # (2e-9 arcsec) in the increments that contain a segment boundary, where w'' jumps
    quiet = simulate_seed000(start_tai_ns=START, duration_s=200.0, seed=5, gyro_noise_std_rad=0.0)
    gq = quiet.streams["gyro_increments"]
    incr_q = np.stack([gq["dax"], gq["day"], gq["daz"]], axis=-1)
    np.testing.assert_allclose(incr_q, expected[: incr_q.shape[0]], rtol=0, atol=1e-13)
    # the truth helper: drift in the measured rate
    np.testing.assert_allclose(
        tr.drift_G_rad_s(10.0),
        (1 + tr.scale_factor_error) * rotations.quat_rotate(tr.q_GS, [1.0, -0.8, 0.3]) * RAD_PER_ARCSEC,
        rtol=1e-14,
    )


def test_star_tracker_noise(scenario):
    tr = scenario.truth
    st = scenario.streams["star_tracker"]
    q = np.stack([st[f"q{i}"] for i in range(4)], axis=-1)
    residual = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(tr.q_IS_st), q))
    np.testing.assert_allclose(residual, tr.st_noise_rotvec_S, atol=1e-14)
    np.testing.assert_allclose(tr.st_noise_std_rad, 0.3 * RAD_PER_ARCSEC)
    lo, hi = chi2_bounds(residual.shape[0])
    ratio = np.mean(residual**2, axis=0) / tr.st_noise_std_rad**2
    assert np.all((ratio > lo) & (ratio < hi))
    np.testing.assert_allclose(tr.q_IS(tr.seconds(tr.st_time_tai_ns)), tr.q_IS_st, atol=1e-15)


def test_rate_integrates_to_the_attitude(scenario):
    """q_IS' = 1/2 q_IS o w_S: RK4 at 1/128 s through slews reproduces the truth to < 1e-3 arcsec."""
    tr = scenario.truth
    t = np.arange(0.0, 300.0 + 1e-9, 1.0 / 128.0)
    h = t[1] - t[0]
    w1, w2, w3 = (tr.w_S(t[:-1] + c * h) for c in (0.0, 0.5, 1.0))

    def f(q, w):
        return 0.5 * rotations.quat_multiply(q, np.concatenate([np.zeros_like(w[:, :1]), w], axis=-1))

    one = np.tile([1.0, 0.0, 0.0, 0.0], (t.size - 1, 1))
    k1 = f(one, w1)
    k2 = f(one + 0.5 * h * k1, w2)
    k3 = f(one + 0.5 * h * k2, w2)
    k4 = f(one + h * k3, w3)
    steps = rotations.quat_normalize(one + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4))
    # chain 128 steps per second with a vectorised tree, then the seconds sequentially
    per_s = steps.reshape(300, 128, 4)
    while per_s.shape[1] > 1:
        per_s = rotations.quat_multiply(per_s[:, 0::2], per_s[:, 1::2])
    q = tr.q_IS(0.0)
    out = [q]
    for step in per_s[:, 0]:  # test only: 300 sequential products
        q = rotations.quat_multiply(q, step)
        out.append(q)
    err = rotations.angle_between(np.array(out), tr.q_IS(np.arange(301.0)))
    assert err.max() < 1e-3 * RAD_PER_ARCSEC, err.max() / RAD_PER_ARCSEC
    # and the scenario really slews: more than 100 deg turned in the first 300 s
    assert rotations.angle_between(tr.q_IS(0.0), tr.q_IS(180.0)) > 100 * RAD_PER_DEG


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"duration_s": 0.0}, "duration_s"),
        ({"st_period_s": 0.3}, "multiple of the gyro period"),
        ({"slew_duration_s": (60.0, 40.0)}, "slew_duration_s"),
        ({"drift_rad_s": (1.0, 2.0)}, "drift_rad_s"),
        ({"scale_factor_error": 0.5}, "scale_factor_error"),
        ({"misalignment_rad": (0.0, 0.0)}, "misalignment_rad"),
    ],
)
def test_parameter_errors(kwargs, match):
    with pytest.raises(Seed000ParameterError, match=match):
        simulate_seed000(start_tai_ns=START, **kwargs)
