"""Tests of the realistic-telemetry mode (processing.simulate.realistic) against independent truth."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from processing.attitude import rotations
from processing.simulate.realistic import simulate_realistic
from processing.simulate.seed003 import Seed003ParameterError
from processing.time.timescales import iso_to_tai_ns
from processing.units import NS_PER_S

T0 = int(iso_to_tai_ns("2023-06-01T00:00:00"))


@pytest.fixture(scope="module")
def sc():
    return simulate_realistic(start_tai_ns=T0, duration_s=3000.0, seed=3, manoeuvre_start_s=1000.0)


def test_deterministic_and_seed_dependent():
    a = simulate_realistic(start_tai_ns=T0, duration_s=300.0, seed=5)
    b = simulate_realistic(start_tai_ns=T0, duration_s=300.0, seed=5)
    c = simulate_realistic(start_tai_ns=T0, duration_s=300.0, seed=6)
    np.testing.assert_array_equal(a.streams["gyro"]["wx"], b.streams["gyro"]["wx"])
    assert not np.array_equal(a.streams["star_tracker"]["time_tai_ns"], c.streams["star_tracker"]["time_tai_ns"])


def test_quantised_irregular_and_gappy(sc):
    q = np.stack([sc.streams["star_tracker"][f"q{i}"] for i in range(4)], axis=1)
    lsb = sc.truth.lsb["quaternion"]
    np.testing.assert_allclose(q / lsb, np.round(q / lsb), atol=1e-6)
    w = sc.streams["gyro"]["wx"] / sc.truth.lsb["gyro_rad_s"]
    np.testing.assert_allclose(w, np.round(w), atol=1e-6)
    dt = np.diff(sc.streams["star_tracker"]["time_tai_ns"]) / NS_PER_S
    assert np.all(dt > 0)
    off = dt - np.round(dt)
    assert np.std(off[np.round(dt) == 1]) > 0.1  # jitter of +-0.2 s on both ends
    assert np.sum(np.round(dt) >= 2) > 50  # many short gaps
    gaps = sc.truth.long_gaps_tai_ns["gyro"]
    longest = np.max(np.diff(sc.streams["gyro"]["time_tai_ns"])) / NS_PER_S
    assert 135.0 <= longest <= 137.5 and gaps.shape == (3, 2)


def test_manoeuvre_is_a_yaw_turn_of_180_deg_and_kinematics_hold(sc):
    t = sc.truth.st_time_tai_ns
    ypr = Rotation.from_quat(sc.truth.st_q_OB, scalar_first=True).as_euler("ZYX")  # independent 3-2-1 angles
    a, b = sc.truth.manoeuvre_tai_ns
    before, after = t < a, t > b
    yaw_change = np.degrees(np.mean(np.unwrap(ypr[:, 0])[after]) - np.mean(np.unwrap(ypr[:, 0])[before]))
    assert abs(abs(yaw_change) - 180.0) < 1.0
    assert np.max(np.abs(np.degrees(ypr[:, 1]))) < 0.5  # pitch stays small in the 3-2-1 sequence
    # w_B consistent with q_IB: integrate finely across the manoeuvre
    ts = np.linspace(900.0, 2000.0, 110001)
    s = sc.truth.model.evaluate(ts)
    dq = rotations.quat_multiply(rotations.quat_conjugate(s.q_IB[:-1]), s.q_IB[1:])
    w_fd = rotations.quat_to_rotvec(dq) / np.diff(ts)[:, None]
    # midpoint-rule error h^2 |w_dot_dot| / 12 ~ 2e-9 rad/s at h = 0.01 s; the psi rate is 3.5e-3 rad/s
    np.testing.assert_allclose(w_fd, 0.5 * (s.w_B[1:] + s.w_B[:-1]), atol=1e-8)


def test_late_gnss_tags_report_an_old_state(sc):
    late = sc.truth.gnss_late
    assert 50 < late.sum() < 200
    g = sc.streams["gnss"]
    r = np.stack([g[c] for c in ("x", "y", "z")], axis=1)
    err = np.linalg.norm(r - sc.truth.r_E, axis=1)
    speed = np.linalg.norm(sc.truth.v_E, axis=1)
    np.testing.assert_allclose(err[late], sc.truth.late_tag_s * speed[late], rtol=0.01)
    assert np.max(err[~late]) < 8.0  # 1 m noise + 1 m LSB


def test_defaults_off_give_clean_grid():
    sc = simulate_realistic(start_tai_ns=T0, duration_s=200.0, seed=1, jitter_fraction=0.0, dropout_probability=0.0,
                            n_long_gaps=0, n_late_blocks=0, quaternion_lsb=0.0)
    dt = np.diff(sc.streams["star_tracker"]["time_tai_ns"])
    assert np.all(dt == NS_PER_S)
    assert not sc.truth.gnss_late.any()


def test_parameter_domain():
    with pytest.raises(Seed003ParameterError, match="jitter_fraction"):
        simulate_realistic(start_tai_ns=T0, jitter_fraction=0.6)
