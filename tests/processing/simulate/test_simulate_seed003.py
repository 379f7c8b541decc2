"""Tests of the paper-003 truth simulator (processing.simulate.seed003)."""

import dataclasses

import numpy as np
import pytest

from processing.attitude import rotations
from processing.frames.earth_orientation import itrs_to_gcrs_state
from processing.frames.orbital import q_IO_003
from processing.orbits.two_body import specific_energy_j_kg
from processing.simulate.orbital_attitude_model import SinusoidSeries, body_rate_from_pitch_yaw_roll
from processing.simulate.seed003 import (
    Scenario003,
    Seed003ParameterError,
    gap_mask,
    mounting_dcm_BS_003,
    mounting_q_BS_003,
    simulate_seed003,
)
from processing.streams import STREAMS
from processing.time.timescales import iso_to_tai_ns
from processing.units import RAD_PER_ARCSEC, RAD_PER_DEG
from tests.processing.helpers import assert_same_streams, chi2_bounds

START = int(iso_to_tai_ns("2009-12-01T10:00:00"))
ALPHA = 15.0 * RAD_PER_DEG
NS = 1_000_000_000


@pytest.fixture(scope="module")
def scenario() -> Scenario003:
    return simulate_seed003(start_tai_ns=START, seed=7)


def test_determinism_by_seed():
    a = simulate_seed003(start_tai_ns=START, seed=3, duration_s=300.0)
    b = simulate_seed003(start_tai_ns=START, seed=3, duration_s=300.0)
    c = simulate_seed003(start_tai_ns=START, seed=4, duration_s=300.0)
    assert_same_streams(a.streams, b.streams)
    np.testing.assert_array_equal(a.truth.q_IB_gyro, b.truth.q_IB_gyro)
    np.testing.assert_array_equal(a.truth.st_removed_time_tai_ns, b.truth.st_removed_time_tai_ns)
    assert not np.array_equal(a.streams["gyro"]["wx"], c.streams["gyro"]["wx"])
    assert not np.array_equal(a.truth.pitch_rad, c.truth.pitch_rad)


def test_streams_follow_the_canonical_schemas(scenario):
    for stream, cols in scenario.streams.items():
        assert set(cols) == {"time_tai_ns", "sensor", *STREAMS[stream].column_names}
        assert cols["time_tai_ns"].dtype == np.int64
        n = cols["time_tai_ns"].size
        for name in STREAMS[stream].column_names:
            assert cols[name].dtype == np.float64 and cols[name].shape == (n,)
    st = scenario.streams["star_tracker"]
    assert set(st["sensor"]) == {"st1"}
    q = np.stack([st[f"q{i}"] for i in range(4)], axis=-1)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-15)
    assert np.all(q[:, 0] >= 0)
    cfg = scenario.config
    np.testing.assert_allclose(cfg["star_trackers"]["st1"]["q_BS"], mounting_q_BS_003(ALPHA), atol=0)
    assert cfg["gyro"]["q_BG"] == [1.0, 0.0, 0.0, 0.0]


def test_sample_spacing_and_grids(scenario):
    gyro_t = scenario.streams["gyro"]["time_tai_ns"]
    gnss_t = scenario.streams["gnss"]["time_tai_ns"]
    st_t = scenario.truth.st_nominal_time_tai_ns
    assert gyro_t[0] == START and gyro_t[-1] == START + 1200 * NS and gyro_t.size == 12001
    assert np.all(np.diff(gyro_t) == NS // 10)
    assert np.all(np.diff(gnss_t) == NS) and gnss_t.size == 1201
    assert np.all(np.diff(st_t) == 3 * NS) and st_t[0] == START + 37_000_000
    # star-tracker times are not gyro nodes (003 §1.2)
    assert not np.any(np.isin(st_t, gyro_t))
    kept = scenario.streams["star_tracker"]["time_tai_ns"]
    assert np.all(np.diff(kept) % (3 * NS) == 0)


def test_gaps_equal_the_truth(scenario):
    truth = scenario.truth
    kept = scenario.streams["star_tracker"]["time_tai_ns"]
    n = truth.st_nominal_time_tai_ns.size
    assert truth.st_removed_time_tai_ns.size == round(0.03 * n) == 12
    removed = truth.st_removed_time_tai_ns
    np.testing.assert_array_equal(np.sort(np.concatenate([kept, removed])), truth.st_nominal_time_tai_ns)
    np.testing.assert_array_equal(kept, truth.st_time_tai_ns)
    # gaps seen in the stream (spacing above one period) are the truth's intervals, 3 of them
    jumps = np.flatnonzero(np.diff(kept) > 3 * NS)
    found = np.stack([kept[jumps], kept[jumps + 1]], axis=-1)
    np.testing.assert_array_equal(found, truth.st_gap_intervals_tai_ns)
    assert found.shape == (3, 2)
    # removed samples lie inside the intervals and account for their length
    inside = (removed[:, None] > found[:, 0]) & (removed[:, None] < found[:, 1])
    assert np.all(inside.sum(axis=1) == 1)
    np.testing.assert_array_equal(inside.sum(axis=0), (found[:, 1] - found[:, 0]) // (3 * NS) - 1)


def test_gap_mask_properties():
    rng = np.random.default_rng(0)
    for _ in range(50):
        mask = gap_mask(400, 0.05, 4, rng)
        assert mask.sum() == 380 and mask[0] and mask[-1]
        assert np.count_nonzero(np.diff(mask.astype(int)) == -1) == 4
    assert gap_mask(10, 0.0, 3, rng).all()
    assert np.count_nonzero(~gap_mask(100, 0.02, 5, rng)) == 2  # 2 samples: at most 2 blocks


def test_star_tracker_noise_statistics(scenario):
    truth = scenario.truth
    st = scenario.streams["star_tracker"]
    q_IS = np.stack([st[f"q{i}"] for i in range(4)], axis=-1)
    q_ref = rotations.quat_multiply(truth.q_IB_st, truth.q_BS)
    residual = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(q_ref), q_IS))
    np.testing.assert_allclose(residual, truth.st_noise_rotvec_S, atol=1e-13)
    n = residual.shape[0]
    lo, hi = chi2_bounds(n)
    ratio = np.mean(residual**2, axis=0) / truth.st_noise_std_rad**2
    assert np.all((ratio > lo) & (ratio < hi)), (ratio, lo, hi)
    np.testing.assert_allclose(truth.st_noise_std_rad, np.array([2.5, 5.0, 15.0]) * RAD_PER_ARCSEC)
    # mean consistent with zero (4 sigma / sqrt(n))
    assert np.all(np.abs(residual.mean(axis=0)) < 4 * truth.st_noise_std_rad / np.sqrt(n))


def test_gyro_minus_truth_mean_is_the_bias(scenario):
    truth = scenario.truth
    g = scenario.streams["gyro"]
    w = np.stack([g["wx"], g["wy"], g["wz"]], axis=-1)
    err = w - truth.w_B_gyro  # q_BG = identity
    np.testing.assert_allclose(truth.gyro_bias0_rad_s, np.array([-1.84, 4.52, 0.55]) * RAD_PER_ARCSEC)
    n = err.shape[0]
    sigma = truth.gyro_noise_std_rad_s
    assert sigma == pytest.approx(1.5 * RAD_PER_ARCSEC)
    assert np.all(np.abs(err.mean(axis=0) - truth.gyro_bias0_rad_s) < 4 * sigma / np.sqrt(n))
    lo, hi = chi2_bounds(n)
    ratio = np.mean((err - truth.gyro_bias_rad_s) ** 2, axis=0) / sigma**2
    assert np.all((ratio > lo) & (ratio < hi))


def test_gyro_bias_drift_and_mounting():
    drift = np.array([1e-4, -2e-4, 5e-5]) * RAD_PER_ARCSEC  # "/s per s
    q_BG = rotations.quat_from_axis_angle([1.0, 2.0, 3.0], 0.2)
    s = simulate_seed003(start_tai_ns=START, seed=1, duration_s=600.0, gyro_bias_drift_rad_s2=tuple(drift),
                         q_BG=tuple(q_BG), gyro_noise_std_rad_s=0.0)
    t = (s.truth.gyro_time_tai_ns - START) / 1e9
    np.testing.assert_allclose(s.truth.gyro_bias_rad_s, s.truth.gyro_bias0_rad_s + drift * t[:, None], rtol=1e-15)
    w_G = np.stack([s.streams["gyro"][c] for c in ("wx", "wy", "wz")], axis=-1)
    w_B_meas = rotations.quat_rotate(q_BG, w_G - s.truth.gyro_bias_rad_s)
    np.testing.assert_allclose(w_B_meas, s.truth.w_B_gyro, atol=1e-18)
    assert s.config["gyro"]["q_BG"] == pytest.approx(rotations.quat_canonical(q_BG).tolist(), abs=1e-16)


def _integrate(model, t_grid_s):
    """Integrate q' = 1/2 q o w_B with RK4 on a uniform grid from the truth at t[0]; q at the grid.

    The equation is linear in q, so each step's increment dq_k (RK4 from the identity, w_B at the
    step's start, middle and end) is computed for all steps at once; only the products
    q_{k+1} = q_k o dq_k are sequential.
    """
    h = t_grid_s[1] - t_grid_s[0]
    t0 = t_grid_s[:-1]
    w1, w2, w3 = (model.evaluate(t0 + c * h).w_B for c in (0.0, 0.5, 1.0))

    def rate(q, w):
        return 0.5 * rotations.quat_multiply(q, np.concatenate([np.zeros_like(w[:, :1]), w], axis=-1))

    one = np.zeros((t0.size, 4))
    one[:, 0] = 1.0
    k1 = rate(one, w1)
    k2 = rate(one + 0.5 * h * k1, w2)
    k3 = rate(one + 0.5 * h * k2, w2)
    k4 = rate(one + h * k3, w3)
    dq = rotations.quat_normalize(one + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4))
    out = np.empty((t_grid_s.size, 4))
    q = model.evaluate(t_grid_s[:1]).q_IB[0]
    out[0] = q
    for k in range(dq.shape[0]):  # test only: the sequential product of increments
        a0, a1, a2, a3 = q
        b0, b1, b2, b3 = dq[k]
        q = np.array([a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3, a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
                      a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1, a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0])
        out[k + 1] = q
    return out


def test_integrating_body_rate_reproduces_attitude(scenario):
    truth = scenario.truth
    t = (truth.gyro_time_tai_ns - START) / 1e9
    q_int = _integrate(truth.model, t)
    err = rotations.angle_between(q_int, truth.q_IB_gyro)
    # RK4 at 0.1 s over 1200 s reaches ~1e-5 arcsec; the requirement is 0.01 arcsec
    assert err.max() < 0.01 * RAD_PER_ARCSEC, err.max() / RAD_PER_ARCSEC
    # sensitivity: a rate error of 1e-9 rad/s (0.0002 "/s) about x already exceeds the bound

    class Offset:
        def evaluate(self, t_s):
            state = truth.model.evaluate(t_s)
            return dataclasses.replace(state, w_B=state.w_B + np.array([1e-9, 0.0, 0.0]))

    err_off = rotations.angle_between(_integrate(Offset(), t), truth.q_IB_gyro)
    assert err_off.max() > 0.01 * RAD_PER_ARCSEC


def test_body_rate_formula_matches_numerical_derivative():
    rng = np.random.default_rng(5)
    a, b, g, ad, bd, gd = rng.uniform(-1, 1, (6, 20))
    h = 1e-6
    qp = rotations.quat_from_pitch_yaw_roll(a + ad * h, b + bd * h, g + gd * h)
    qm = rotations.quat_from_pitch_yaw_roll(a - ad * h, b - bd * h, g - gd * h)
    q = rotations.quat_from_pitch_yaw_roll(a, b, g)
    qm = np.where(np.sum(qm * qp, axis=-1, keepdims=True) < 0, -qm, qm)
    q = np.where(np.sum(q * qp, axis=-1, keepdims=True) < 0, -q, q)
    w = 2 * rotations.quat_multiply(rotations.quat_conjugate(q), (qp - qm) / (2 * h))
    np.testing.assert_allclose(w[:, 0], 0, atol=1e-9)
    np.testing.assert_allclose(w[:, 1:], body_rate_from_pitch_yaw_roll(a, b, g, ad, bd, gd), atol=1e-9)


def test_truth_quaternions_and_orbital_angles_are_consistent(scenario):
    truth = scenario.truth
    np.testing.assert_allclose(
        rotations.quat_canonical(rotations.quat_multiply(truth.q_IB_st, truth.q_BS)), truth.q_IS_st, atol=1e-15
    )
    state = truth.model.evaluate((truth.gyro_time_tai_ns - START) / 1e9)
    q_OB = rotations.quat_multiply(rotations.quat_conjugate(q_IO_003(state.r_I, state.v_I)), truth.q_IB_gyro)
    pitch, yaw, roll = rotations.pitch_yaw_roll_from_quat(q_OB)
    np.testing.assert_allclose(pitch, truth.pitch_rad, atol=1e-13)
    np.testing.assert_allclose(yaw, truth.yaw_rad, atol=1e-13)
    np.testing.assert_allclose(roll, truth.roll_rad, atol=1e-13)


def test_pitch_yaw_roll_ranges_and_vibration(scenario):
    truth = scenario.truth
    deg = 1 / RAD_PER_DEG
    assert np.abs(truth.pitch_rad).max() * deg < 0.4 and np.abs(truth.roll_rad).max() * deg < 0.4
    assert np.abs(truth.yaw_rad - 1.2 * RAD_PER_DEG).max() * deg <= 0.3
    assert 1.0 <= truth.yaw_rad.mean() * deg <= 1.4
    for angle in (truth.pitch_rad, truth.yaw_rad, truth.roll_rad):  # slow motion is really there
        assert np.ptp(angle) * deg > 0.05
    # 0.4 Hz line in the body rate: amplitude 2 pi 0.4 Hz * 3" = 7.54 "/s about y2 (pitch), y3 (yaw),
    # y1 (roll), read from the amplitude spectrum A(f) = 2 |sum x e^(-2 pi i f t)| / N (003 §1.5)
    t = (truth.gyro_time_tai_ns - START) / 1e9
    x = truth.w_B_gyro - truth.w_B_gyro.mean(axis=0)
    amp = 2 * np.abs(np.exp(-2j * np.pi * 0.4 * t) @ x) / t.size / RAD_PER_ARCSEC
    np.testing.assert_allclose(amp[[1, 2, 0]], 2 * np.pi * 0.4 * 3.0, rtol=0.05)


def test_orbit_energy_constant_and_gnss_round_trip(scenario):
    truth = scenario.truth
    energy = specific_energy_j_kg(truth.r_I, truth.v_I)
    assert np.ptp(energy) / abs(energy.mean()) < 1e-9
    r_I, v_I = itrs_to_gcrs_state(truth.r_E, truth.v_E, truth.gnss_time_tai_ns, truth.eop)
    np.testing.assert_allclose(r_I, truth.r_I, atol=1e-7)
    np.testing.assert_allclose(v_I, truth.v_I, atol=1e-10)
    assert truth.eop.source == "zero (no EOP supplied)"
    g = scenario.streams["gnss"]
    dr = np.stack([g[c] for c in "xyz"], axis=-1) - truth.r_E
    dv = np.stack([g[c] for c in ("vx", "vy", "vz")], axis=-1) - truth.v_E
    lo, hi = chi2_bounds(dr.shape[0])
    assert np.all((np.mean(dr**2, axis=0) > lo * 1.0) & (np.mean(dr**2, axis=0) < hi * 1.0))
    assert np.all((np.mean(dv**2, axis=0) > lo * 1e-6) & (np.mean(dv**2, axis=0) < hi * 1e-6))
    # the orbit is the 830 km sun-synchronous one
    assert np.linalg.norm(truth.r_I, axis=-1) == pytest.approx(6378137.0 + 830e3, rel=1e-14)
    assert 98.7 < truth.model.inc_rad / RAD_PER_DEG < 98.8


def test_mounting_003():
    dcm = mounting_dcm_BS_003(ALPHA)
    assert np.linalg.det(dcm) == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_allclose(dcm @ dcm.T, np.eye(3), atol=1e-16)
    q_BS = mounting_q_BS_003(ALPHA)
    np.testing.assert_allclose(rotations.quat_to_dcm(q_BS), dcm, atol=1e-15)
    # body axis y3 in sensor coordinates is (cos a, 0, sin a)
    y3_S = rotations.quat_rotate(rotations.quat_conjugate(q_BS), [0.0, 0.0, 1.0])
    np.testing.assert_allclose(y3_S, [np.cos(ALPHA), 0.0, np.sin(ALPHA)], atol=1e-15)
    # the paper's formulas y1 = -x2, y2 = x1 sin a - x3 cos a, y3 = x1 cos a + x3 sin a
    x = np.random.default_rng(2).normal(size=(10, 3))
    y = rotations.quat_rotate(q_BS, x)
    s, c = np.sin(ALPHA), np.cos(ALPHA)
    expected = np.stack([-x[:, 1], x[:, 0] * s - x[:, 2] * c, x[:, 0] * c + x[:, 2] * s], axis=-1)
    np.testing.assert_allclose(y, expected, atol=1e-15)
    # alpha = 0 is the paper's simplified mounting of §1.5: x1 = y3, x2 = -y1, x3 = -y2
    x_of_y = mounting_dcm_BS_003(0.0).T
    np.testing.assert_array_equal(x_of_y, [[0, 0, 1], [-1, 0, 0], [0, -1, 0]])


def test_sinusoid_series_bounds_and_rate():
    s = SinusoidSeries(0.1, (0.2, 0.05), (300.0, 2.5), (0.3, 1.0))
    t = np.linspace(0, 1000, 100001)
    x, xd = s.value_and_rate(t)
    assert np.all(np.abs(x - 0.1) <= 0.25)
    np.testing.assert_allclose(np.gradient(x, t)[1:-1], xd[1:-1], atol=2e-5)
    with pytest.raises(ValueError, match="equal lengths"):
        SinusoidSeries(0.0, (1.0,), (1.0, 2.0), (0.0,))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"duration_s": 0.0}, "duration_s must be > 0"),
        ({"gyro_period_s": -0.1}, "gyro_period_s must be > 0"),
        ({"gap_fraction": 0.6}, "gap_fraction must be in"),
        ({"st_noise_std_rad": (1e-5, 1e-5)}, "st_noise_std_rad must have 3 components"),
        ({"st_time_offset_s": 3.0}, "st_time_offset_s must be in"),
    ],
)
def test_parameter_errors(kwargs, match):
    with pytest.raises(Seed003ParameterError, match=match):
        simulate_seed003(start_tai_ns=START, **kwargs)
