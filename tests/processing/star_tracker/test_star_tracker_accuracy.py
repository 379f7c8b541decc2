"""Tests of the 003 §1.3-1.5 star-tracker accuracy analysis against the seed-003 simulator's truth.

The "Done when" statistics of issue 4 use seeds 0..19 of processing.simulate.seed003 (20 min,
~388 quaternions at 3 s with 3 % gaps, noise 2.5/5/15" about x1 x2 x3, 0.4 Hz 3" vibration on each
attitude angle, gyro at 10 Hz with 1.5"/s white noise and the 003 §2.4 offsets). The vibration's
truth is the difference from the same seed simulated with zero vibration amplitude (the simulator
draws every random quantity from its own stream, so attitude phases, noise and gaps are identical).
"""

from dataclasses import dataclass

import numpy as np
import pytest

from processing.attitude import rotations
from processing.signal.spectral_lines import fit_sinusoid
from processing.simulate.seed003 import simulate_seed003
from processing.star_tracker.accuracy import (
    StarTrackerAccuracy,
    StarTrackerAccuracyError,
    analyze_star_tracker_accuracy,
)
from processing.star_tracker.smoothing import (
    mean_quaternion,
    rate_from_mrp,
    residual_mrps,
    sensor_axis_residuals,
    split_segments,
)
from processing.time.timescales import iso_to_tai_ns
from processing.units import RAD_PER_ARCSEC

START = int(iso_to_tai_ns("2009-12-01T10:00:00"))
SEEDS = range(20)
NS = 1_000_000_000


def simulate(seed: int, **kwargs):
    """seed-003 scenario; GNSS every 1200 s only (not used here, and its ERFA work is the slow part)."""
    return simulate_seed003(start_tai_ns=START, seed=seed, gnss_period_s=1200.0, **kwargs)


def _streams(sc):
    st, g = sc.streams["star_tracker"], sc.streams["gyro"]
    q = np.column_stack([st[f"q{i}"] for i in range(4)])
    w = np.column_stack([g["wx"], g["wy"], g["wz"]])
    return st["time_tai_ns"], q, g["time_tai_ns"], w


@dataclass
class Run:
    seed: int
    result: StarTrackerAccuracy
    noise_nominal: np.ndarray  # (3,) rad, configured std about x1 x2 x3
    noise_realized: np.ndarray  # (3,) rad, std of the noise actually drawn
    combined_realized: np.ndarray  # (3,) rad, rms of noise + vibration about the sensor axes
    combined_nominal: np.ndarray
    vibration_rms: np.ndarray  # (3,) rad about the sensor axes
    line_amplitude_rad_s: np.ndarray  # (3,) true 0.4 Hz rate amplitude per body axis
    gyro_noise_rad_s: float
    gyro_bias_B_rad_s: np.ndarray


@pytest.fixture(scope="module")
def runs() -> list[Run]:
    out = []
    for seed in SEEDS:
        sc = simulate(seed)
        calm = simulate(seed, vibration_amplitude_rad=(0.0, 0.0, 0.0))
        tr = sc.truth
        t_st, q, t_g, w = _streams(sc)
        result = analyze_star_tracker_accuracy(t_st, q, tr.q_BS, gyro_time_tai_ns=t_g, w_G_rad_s=w)
        q_calm_inv = rotations.quat_conjugate(calm.truth.q_IS_st)
        vib = rotations.quat_to_rotvec(rotations.quat_multiply(q_calm_inv, tr.q_IS_st))
        t_g_s = (tr.gyro_time_tai_ns - START) / NS
        line = fit_sinusoid(t_g_s, tr.w_B_gyro - calm.truth.w_B_gyro, 0.4, refine=False)
        out.append(Run(
            seed=seed,
            result=result,
            noise_nominal=tr.st_noise_std_rad,
            noise_realized=np.std(tr.st_noise_rotvec_S, axis=0),
            combined_realized=np.sqrt(np.mean((tr.st_noise_rotvec_S + vib) ** 2, axis=0)),
            combined_nominal=np.sqrt(tr.st_noise_std_rad**2 + np.mean(vib**2, axis=0)),
            vibration_rms=np.sqrt(np.mean(vib**2, axis=0)),
            line_amplitude_rad_s=line.amplitude,
            gyro_noise_rad_s=tr.gyro_noise_std_rad_s,
            gyro_bias_B_rad_s=rotations.quat_rotate(tr.q_BG, tr.gyro_bias0_rad_s),
        ))
    return out


def _rel(runs, estimate, truth) -> np.ndarray:
    return np.array([getattr(r.result, estimate) / getattr(r, truth) - 1.0 for r in runs])


# ---------------------------------------------------------------------------------------------
# Done when (issue 4), over 20 seeds


def test_sensor_sigma_within_5_percent_on_average_and_12_percent_every_run(runs):
    err = np.abs(_rel(runs, "sigma_rad", "noise_nominal"))
    assert np.all(err.mean(axis=0) < 0.05), err.mean(axis=0)  # measured 3.5 / 3.1 / 3.5 %
    assert np.all(err < 0.12), err.max(axis=0)  # measured max 10.5 / 8.8 / 7.0 %
    # Against the noise actually drawn (removes the sampling spread of the simulation itself):
    err_real = np.abs(_rel(runs, "sigma_rad", "noise_realized"))
    assert np.all(err_real.mean(axis=0) < 0.03) and np.all(err_real < 0.07), err_real.max(axis=0)


def test_smoothing_sigma_is_noise_plus_vibration(runs):
    err = np.abs(_rel(runs, "sigma_smoothing_rad", "combined_realized"))
    assert np.all(err < 0.10), err.max(axis=0)  # measured max 3.2 / 3.4 / 4.9 %
    err_nom = np.abs(_rel(runs, "sigma_smoothing_rad", "combined_nominal"))
    assert np.all(err_nom.mean(axis=0) < 0.05), err_nom.mean(axis=0)  # measured 2.7 / 3.0 / 3.3 %


def test_removed_motion_is_the_simulated_vibration(runs):
    err = np.abs(_rel(runs, "motion_rms_rad", "vibration_rms"))
    assert np.all(err < 0.03), err.max(axis=0)


def test_the_0p4_hz_line_its_amplitude_and_its_alias(runs):
    for r in runs:
        gyro = [line for line in r.result.lines if line.source == "gyro"]
        assert len(gyro) == 3, gyro  # one line, three body axes; nothing else above the cutoff
        assert [line.axis for line in gyro] == ["y1", "y2", "y3"]
        for k, line in enumerate(gyro):
            assert line.freq_hz == pytest.approx(0.4, abs=2e-5)
            assert line.amplitude_rad_s == pytest.approx(r.line_amplitude_rad_s[k], rel=0.10)
            assert line.attitude_amplitude_rad == pytest.approx(line.amplitude_rad_s / (2 * np.pi * 0.4), rel=1e-4)
            assert line.aliased_freq_hz == pytest.approx(0.4 - 1 / 3.0, abs=2e-5)  # 003 §2.4: 15 s
            assert line.removed
        st = [line for line in r.result.lines if line.source == "star_tracker"]
        assert st and all(line.freq_hz == pytest.approx(1 / 15.0, abs=1e-3) and line.removed for line in st)
        assert {line.axis for line in st} <= {"x1", "x2"}  # 3" is below the x3 noise floor


def test_gyro_comparison_is_consistent_with_the_simulated_noise(runs):
    ratio = []
    for r in runs:
        g = r.result.gyro
        assert g is not None
        np.testing.assert_allclose(g.noise_sigma_rad_s, r.gyro_noise_rad_s, rtol=0.03)
        np.testing.assert_allclose(g.offset_rad_s, r.gyro_bias_B_rad_s, atol=0.05 * RAD_PER_ARCSEC)
        # smoothing residuals of 003 §1.4 hold the 0.4 Hz line: sqrt(noise^2 + A^2/2)
        np.testing.assert_allclose(g.smoothing_sigma_rad_s,
                                   np.sqrt(r.gyro_noise_rad_s**2 + r.line_amplitude_rad_s**2 / 2), rtol=0.03)
        ratio.append(g.rms_diff_rad_s / g.expected_rms_diff_rad_s)
    ratio = np.array(ratio)
    # The rate difference is dominated by the star tracker's noise through the derivative of the
    # fit (few effective degrees of freedom: ~12 % spread per run); measured means 1.00/1.13/1.10.
    assert np.all((ratio.mean(axis=0) > 0.85) & (ratio.mean(axis=0) < 1.25)), ratio.mean(axis=0)
    assert np.all((ratio > 0.6) & (ratio < 1.6)), ratio


def test_rates_follow_the_true_body_rate(runs):
    r = runs[0]
    sc = simulate(r.seed)
    w_true = sc.truth.w_B_st
    line = fit_sinusoid((sc.truth.st_time_tai_ns - START) / NS, w_true, 0.4, refine=False)
    slow = w_true - line.evaluate((sc.truth.st_time_tai_ns - START) / NS)
    err = r.result.w_B_rad_s - slow
    inner = slice(20, -20)  # the fit's derivative is noisiest at the segment ends
    assert np.all(np.sqrt(np.mean(err[inner] ** 2, axis=0)) < 1.0 * RAD_PER_ARCSEC)


# ---------------------------------------------------------------------------------------------
# Building blocks


def test_rate_from_mrp_matches_quaternion_kinematics():
    def z_of(t):
        return np.column_stack([0.1 * np.sin(t / 9), 0.05 * np.cos(t / 7), 0.16 * t / 100 - 0.08])

    t = np.linspace(0.0, 100.0, 201)
    z = z_of(t)
    zd = np.column_stack([0.1 / 9 * np.cos(t / 9), -0.05 / 7 * np.sin(t / 7), np.full_like(t, 0.0016)])
    q_c = rotations.quat_normalize(np.array([0.3, -0.5, 0.2, 0.7]))

    def q_of(tt):
        return rotations.quat_multiply(q_c, rotations.mrp_to_quat(z_of(tt)))

    dt = 1e-4
    q_dot = (q_of(t + dt) - q_of(t - dt)) / (2 * dt)
    w_fd = 2.0 * rotations.quat_multiply(rotations.quat_conjugate(q_of(t)), q_dot)[:, 1:]  # q' = 1/2 q o w
    np.testing.assert_allclose(rate_from_mrp(z, zd), w_fd, atol=1e-10)
    # and the inverse of the MRP kinematics z' = 1/4 [(1 - z.z) w + 2 z x w + 2 (z.w) z]
    w = rate_from_mrp(z, zd)
    zz = np.sum(z * z, axis=-1, keepdims=True)
    zd_back = 0.25 * ((1 - zz) * w + 2 * np.cross(z, w) + 2 * np.sum(z * w, axis=-1, keepdims=True) * z)
    np.testing.assert_allclose(zd_back, zd, atol=1e-16)


def test_mean_quaternion_ignores_signs_and_residual_mrps_are_small():
    rng = np.random.default_rng(0)
    q0 = rotations.quat_normalize(np.array([0.9, 0.1, -0.3, 0.2]))
    q = rotations.quat_multiply(q0, rotations.rotvec_to_quat(1e-2 * rng.standard_normal((50, 3))))
    flipped = q * np.where(rng.random(50) < 0.5, -1.0, 1.0)[:, None]
    np.testing.assert_allclose(mean_quaternion(flipped), mean_quaternion(q), atol=1e-15)
    np.testing.assert_allclose(mean_quaternion(q), rotations.quat_canonical(rotations.quat_normalize(q.sum(0))))
    z = residual_mrps(flipped, mean_quaternion(q))
    assert np.max(np.abs(z)) < 0.02


def test_sensor_axis_residuals_are_exact_and_reduce_to_eq2_for_small_z():
    rng = np.random.default_rng(1)
    theta = 10 * RAD_PER_ARCSEC * rng.standard_normal((100, 3))
    z_fit = np.column_stack([np.zeros(100), np.zeros(100), np.linspace(-0.16, 0.16, 100)])  # ~+-36 deg
    z = rotations.quat_to_mrp(rotations.quat_multiply(rotations.mrp_to_quat(z_fit), rotations.rotvec_to_quat(theta)))
    np.testing.assert_allclose(sensor_axis_residuals(z, z_fit), theta, atol=1e-15)
    eq2 = 4 * (z - z_fit)
    assert np.max(np.abs(eq2 - theta)) > 0.1 * np.max(np.abs(theta))  # eq. 2 mixes axes at |z| = 0.16
    small = np.zeros_like(z_fit)
    z_small = rotations.quat_to_mrp(rotations.rotvec_to_quat(theta))
    np.testing.assert_allclose(4 * (z_small - small), theta, atol=1e-12)


def test_split_segments():
    t = np.int64(START) + np.arange(86400, dtype=np.int64) * NS  # 24 h at 1 Hz
    seg = split_segments(t, 1200.0, 120.0)
    assert len(seg) == 72 and seg[0].start == 0 and seg[-1].stop == 86400
    assert all(a.stop == b.start for a, b in zip(seg[:-1], seg[1:], strict=True))
    gap = np.concatenate([t[:1000], t[1500:2000]])  # a 500 s gap
    assert [(s.start, s.stop) for s in split_segments(gap, 1200.0, 120.0)] == [(0, 1000), (1000, 1500)]


# ---------------------------------------------------------------------------------------------
# Routes, options and errors


def test_gap_free_data_use_the_dst_route_and_agree_with_the_general_route():
    sc = simulate(3, gap_fraction=0.0)
    t_st, q, _, _ = _streams(sc)
    fast = analyze_star_tracker_accuracy(t_st, q, sc.truth.q_BS)
    dense = analyze_star_tracker_accuracy(t_st, q, sc.truth.q_BS, method="lstsq")
    assert [s.method for s in fast.segments] == ["dst"] and [s.method for s in dense.segments] == ["lstsq"]
    assert fast.harmonics == dense.harmonics
    np.testing.assert_allclose(fast.sigma_rad, dense.sigma_rad, rtol=1e-9)
    np.testing.assert_allclose(fast.residuals_rad, dense.residuals_rad, atol=1e-10 * RAD_PER_ARCSEC * 1e3)


def test_without_gyro_nothing_is_removed_but_the_alias_is_reported():
    sc = simulate(1)
    t_st, q, _, _ = _streams(sc)
    r = analyze_star_tracker_accuracy(t_st, q, sc.truth.q_BS, harmonics=40)
    assert r.harmonics == [40] and r.gyro is None
    np.testing.assert_array_equal(r.sigma_rad, r.sigma_smoothing_rad)
    np.testing.assert_array_equal(r.motion_rad, 0.0)
    st = [line for line in r.lines if line.source == "star_tracker"]
    assert st and all(abs(line.freq_hz - 1 / 15) < 1e-3 and not line.removed for line in st)
    assert any("no gyro" in n for n in r.notes)
    assert r.spectra["star_tracker_rate"].freq_hz[-1] <= 1 / 6


def test_bad_inputs():
    sc = simulate(0, duration_s=300.0)
    t_st, q, t_g, w = _streams(sc)
    with pytest.raises(StarTrackerAccuracyError, match=r"q_IS must have shape \(\d+, 4\)"):
        analyze_star_tracker_accuracy(t_st, q[:, :3], sc.truth.q_BS)
    with pytest.raises(StarTrackerAccuracyError, match="int64 nanoseconds"):
        analyze_star_tracker_accuracy(t_st / 1e9, q, sc.truth.q_BS)
    with pytest.raises(StarTrackerAccuracyError, match="strictly increasing"):
        analyze_star_tracker_accuracy(t_st[::-1], q, sc.truth.q_BS)
    with pytest.raises(StarTrackerAccuracyError, match=r"harmonics must be <= N - 2"):
        analyze_star_tracker_accuracy(t_st, q, sc.truth.q_BS, harmonics=t_st.size)
    with pytest.raises(StarTrackerAccuracyError, match="w_G_rad_s must have shape"):
        analyze_star_tracker_accuracy(t_st, q, sc.truth.q_BS, gyro_time_tai_ns=t_g, w_G_rad_s=w[:, :2])
    with pytest.raises(StarTrackerAccuracyError, match="at least 12 star-tracker samples"):
        analyze_star_tracker_accuracy(t_st[:5], q[:5], sc.truth.q_BS)


def test_the_per_segment_smoothings_give_the_same_result_on_any_mapper():
    """The per-segment smoothings (star tracker, gyro) and gyro comparisons go through the mapper (a cluster's
    workers in a job): run in reverse order on other threads, the parts come back in place, outputs bit-identical."""
    from concurrent.futures import ThreadPoolExecutor

    sc = simulate(3, duration_s=1800.0)
    t_st, q, t_g, w = _streams(sc)
    calls: list[int] = []

    def reversed_threads(func, parts):  # noqa: ANN001, ANN202
        calls.append(len(parts))
        with ThreadPoolExecutor(2) as pool:
            return list(reversed(list(pool.map(func, list(reversed(parts))))))

    kw = {"gyro_time_tai_ns": t_g, "w_G_rad_s": w, "segment_max_s": 400.0}
    serial = analyze_star_tracker_accuracy(t_st, q, sc.truth.q_BS, **kw)
    mapped = analyze_star_tracker_accuracy(t_st, q, sc.truth.q_BS, mapper=reversed_threads, **kw)
    assert len(calls) == 3 and calls[0] == len(serial.segments) >= 4  # star tracker, gyro, comparison
    for name in ("z_fit", "residuals_rad", "residuals_smoothing_rad", "motion_rad", "w_B_rad_s", "sigma_rad",
                 "sigma_smoothing_rad", "sigma_robust_rad", "outlier"):
        np.testing.assert_array_equal(getattr(mapped, name), getattr(serial, name), err_msg=name)
    assert mapped.gyro is not None and serial.gyro is not None
    np.testing.assert_array_equal(mapped.gyro.rms_diff_rad_s, serial.gyro.rms_diff_rad_s)
    assert [x.freq_hz for x in mapped.lines] == [x.freq_hz for x in serial.lines]
