"""Orbital attitude of 003 §1.6 (processing/star_tracker/orbital_attitude.py): smoothing pieces and invariants.

The end-to-end accuracy against the seed-003 truth is tested through the job in
tests/app/test_job_orbital_attitude.py.
"""

import numpy as np
import pytest

from processing.attitude import rotations
from processing.signal.sine_series import fit_sine_series
from processing.simulate.seed003 import simulate_seed003
from processing.star_tracker.orbital_attitude import (
    OrbitalAttitudeError,
    angle_stats_deg,
    orbital_attitude,
    smooth_attitude,
)
from processing.star_tracker.trend_sines import fit_trend_sines
from processing.time.timescales import iso_to_tai_ns

START = int(iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])
NS = 1_000_000_000
ARCSEC = np.radians(1 / 3600)


def test_trend_degree_1_is_exactly_the_003_sine_series():
    rng = np.random.default_rng(0)
    t = np.arange(200) * 3.0
    y = np.sin(t / 90.0) + 0.01 * rng.standard_normal(t.size)
    fitted, m = fit_trend_sines(t, y, trend_degree=1, harmonics=12)
    np.testing.assert_array_equal(fitted, fit_sine_series(t, y, 12).fitted)
    assert m == 12


def test_cubic_trend_follows_a_slow_motion_with_fewer_harmonics():
    """A slow sinusoid that does not start/end at rest: the cubic trend absorbs the end curvature."""
    rng = np.random.default_rng(1)
    t = np.arange(400) * 3.0
    truth = 1e-3 * np.sin(2 * np.pi * t / 700.0 + 0.4) + 5e-4 * np.sin(2 * np.pi * t / 260.0 + 2.0)
    y = truth + 2e-5 * rng.standard_normal(t.size)
    f1, m1 = fit_trend_sines(t, y, trend_degree=1)
    f3, m3 = fit_trend_sines(t, y, trend_degree=3)
    assert m3 < m1
    assert np.sqrt(np.mean((f3 - truth) ** 2)) < np.sqrt(np.mean((f1 - truth) ** 2))
    # The GCV choice reproduces an explicit fit with that M.
    f3_fixed, _ = fit_trend_sines(t, y, trend_degree=3, harmonics=m3)
    np.testing.assert_allclose(f3, f3_fixed, atol=1e-15)


def test_smooth_attitude_keeps_a_noise_free_slow_rotation_and_splits_at_gaps():
    t = START + np.concatenate([np.arange(0, 300), np.arange(400, 700)]) * 3 * NS
    angle = 0.01 * np.sin((t - START) / NS / 500.0)
    q = rotations.quat_from_axis_angle([0.0, 0.0, 1.0], angle)
    q_sm, segs = smooth_attitude(t, q, max_gap_s=60.0)
    assert len(segs) == 2 and all(s.smoothed for s in segs)
    assert np.max(rotations.angle_between(q_sm, q)) < 1e-9
    q_few, segs_few = smooth_attitude(t[:5], q[:5])
    assert segs_few[0].harmonics == (-1, -1, -1) and np.array_equal(q_few, rotations.quat_canonical(q[:5]))


def test_angle_statistics_unwrap_near_180_degrees():
    a = np.radians(np.array([179.9, -179.9, 179.95, -179.95]))
    s = angle_stats_deg(a)
    assert abs(abs(s["mean"]) - 180.0) < 1e-9 and s["std"] < 0.1
    assert s["max"] - s["min"] == pytest.approx(0.2)


@pytest.fixture(scope="module")
def scenario():
    return simulate_seed003(start_tai_ns=START, seed=2, duration_s=600.0, gyro_period_s=10.0)


def _inputs(sc):
    st, g = sc.streams["star_tracker"], sc.streams["gnss"]
    q = np.stack([st[f"q{i}"] for i in range(4)], axis=-1)
    r = np.stack([g[c] for c in ("x", "y", "z")], axis=-1)
    v = np.stack([g[c] for c in ("vx", "vy", "vz")], axis=-1)
    return st["time_tai_ns"], q, g["time_tai_ns"], r, v


def test_noise_free_attitude_gives_the_truth_angles_exactly(scenario):
    """With the noise-free q_IS of the truth, raw angles equal the truth to the GNSS-fit level."""
    t, _, tg, r, v = _inputs(scenario)
    tr = scenario.truth
    res = orbital_attitude(t, tr.q_IS_st, tg, r, v, q_BS=tr.q_BS, smoothing=False)
    st = tr.model.evaluate((res.time_tai_ns - START) / NS)
    for got, want in ((res.pitch_rad, st.pitch_rad), (res.yaw_rad, st.yaw_rad), (res.roll_rad, st.roll_rad)):
        assert np.max(np.abs(got - want)) < 0.05 * ARCSEC
    # q_GB = q_GO o q_OB is the body attitude (the AEM content).
    assert np.max(rotations.angle_between(res.q_GB, tr.q_IB_st)) < 0.05 * ARCSEC


def test_lvlh_004_angles_are_the_003_ones_turned_by_180_deg_about_axis_1(scenario):
    """lvlh_004 axes are (1, -2, -3) of orbital_003, i.e. O_004 = O_003 turned by pi about axis 1."""
    t, q, tg, r, v = _inputs(scenario)
    a = orbital_attitude(t, q, tg, r, v, q_BS=scenario.truth.q_BS, smoothing=False)
    b = orbital_attitude(t, q, tg, r, v, q_BS=scenario.truth.q_BS, smoothing=False, orbital_frame="lvlh_004")
    q_x_pi = np.array([0.0, 1.0, 0.0, 0.0])
    np.testing.assert_allclose(rotations.angle_between(rotations.quat_multiply(q_x_pi, a.q_OB), b.q_OB), 0.0,
                               atol=1e-12)


def test_inputs_checked(scenario):
    t, q, tg, r, v = _inputs(scenario)
    with pytest.raises(OrbitalAttitudeError, match=r"quaternions \(N, 4\)"):
        orbital_attitude(t, q[:, :3], tg, r, v)
    with pytest.raises(OrbitalAttitudeError, match="orbital_frame"):
        orbital_attitude(t, q, tg, r, v, orbital_frame="vvlh")
    with pytest.raises(ValueError, match="unknown inertial frame"):
        orbital_attitude(t, q, tg, r, v, inertial_frame="B1950")
    with pytest.raises(OrbitalAttitudeError, match="do not overlap"):
        orbital_attitude(t + 10_000 * NS, q, tg, r, v)
