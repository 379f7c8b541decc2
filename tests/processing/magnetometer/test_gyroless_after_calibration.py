"""Issue 18 "Done when": with an uncalibrated magnetometer (2 % scale, a few hundred nT bias, non-orthogonality)
the gyroless EKF of 004 is off by about a degree; after the |B| calibration is applied, its attitude error is
within its 3-sigma bound on >= 90 % of the epochs after convergence and under 2 deg. The existing
processing.gyroless pipeline is used as it is; the calibration runs on three orbits, the filter on the last hour."""

from __future__ import annotations

import numpy as np
import pytest

from processing.gyroless.estimation import GyrolessSettings, estimate_gyroless_attitude
from processing.gyroless.filtering import attitude_errors_rad
from processing.magnetometer.calibration import CalibrationSettings, calibrate_magnetometer
from processing.magnetometer.reference import reference_field_norm_nT
from processing.simulate.seed004 import orbit_period_s, simulate_seed004
from processing.time.timescales import iso_to_tai_ns

T0 = int(iso_to_tai_ns(["2025-03-20T12:00:00"])[0])
FILTER_S = 3600.0


def _xyz(cols: dict, names: str) -> np.ndarray:
    return np.column_stack([cols[n] for n in names.split()])


@pytest.fixture(scope="module")
def scenario():  # noqa: ANN201
    """004 closed loop (averaged LQR, on-board EKF), three orbits, magnetometer with injected errors."""
    return simulate_seed004(start_tai_ns=T0, duration_s=3 * orbit_period_s(), seed=5, controller="lqr",
                            estimator="ekf", magnetometer_bias_nT=(400.0, -300.0, 250.0),
                            magnetometer_scale_factor_errors=(0.02, -0.015, 0.01),
                            magnetometer_non_orthogonality_rad=(0.004, -0.003, 0.005))


def _ekf(sc, b_M: np.ndarray, first: int) -> tuple[np.ndarray, np.ndarray, float]:  # noqa: ANN001
    """Filtered attitude errors and 1-sigma (after convergence) of the 004 EKF from step ``first`` on."""
    st = sc.streams
    m, s, g, tq = st["magnetometer"], st["sun_sensor"], st["gnss"], st["magnetorquer"]
    t0 = m["time_tai_ns"][first]
    sun = s["time_tai_ns"] >= t0
    r = estimate_gyroless_attitude(
        mag_time_tai_ns=m["time_tai_ns"][first:], mag_M_nT=b_M[first:], sun_time_tai_ns=s["time_tai_ns"][sun],
        sun_S=_xyz(s, "sx sy sz")[sun], gnss_time_tai_ns=g["time_tai_ns"], gnss_r_E_m=_xyz(g, "x y z"),
        gnss_v_E_m_s=_xyz(g, "vx vy vz"), inertia_kg_m2=sc.config["inertia_kg_m2"],
        torquer_time_tai_ns=tq["time_tai_ns"], torquer_mu_B_A_m2=_xyz(tq, "mx my mz"),
        q_BM=sc.config["magnetometer"]["q_BM"], q_BS=sc.config["sun_sensor"]["q_BS"],
        settings=GyrolessSettings(filter="ekf", smoother=False))
    i = np.searchsorted(sc.truth.time_tai_ns, r.time_tai_ns)
    conv = r.time_to_converge_s if r.time_to_converge_s is not None else 600.0
    after = (r.time_tai_ns - r.time_tai_ns[0]) / 1e9 >= conv
    err = attitude_errors_rad(r.filtered.q_OB, sc.truth.q_OB[i])[after]
    return np.degrees(err), np.degrees(r.filtered.attitude_sigma_rad[after]), float(np.mean(after))


def test_ekf_is_consistent_after_the_calibration(scenario) -> None:  # noqa: ANN001
    sc = scenario
    m = sc.streams["magnetometer"]
    b_M = _xyz(m, "bx by bz")
    g = sc.streams["gnss"]
    ref, ok = reference_field_norm_nT(m["time_tai_ns"], g["time_tai_ns"], _xyz(g, "x y z"), _xyz(g, "vx vy vz"))
    assert ok.all()
    cal = calibrate_magnetometer(b_M, ref, sample_period_s=1.0,
                                 settings=CalibrationSettings(magnetometer_noise_nT=100.0))
    assert cal.complete and not cal.notes
    inj = sc.truth.magnetometer_errors
    truth = np.concatenate([inj.bias_nT, inj.scale_factor_errors, inj.non_orthogonality_rad])
    assert np.all(np.abs(cal.estimate - truth) < 3 * cal.sigma)
    corrected = cal.errors.correct(b_M)
    first = b_M.shape[0] - int(FILTER_S)

    err, sig, frac = _ekf(sc, corrected, first)
    assert frac > 0.5
    within = np.all(np.abs(err) <= 3 * sig, axis=1)
    assert np.mean(within) >= 0.9
    assert np.max(np.linalg.norm(err, axis=1)) < 2.0

    # the same filter on the raw magnetometer: errors well above its claimed sigma (the finding)
    err_raw, sig_raw, _ = _ekf(sc, b_M, first)
    assert np.sqrt(np.mean(err_raw**2)) > 3 * np.sqrt(np.mean(err**2))
    assert np.mean(np.all(np.abs(err_raw) <= 3 * sig_raw, axis=1)) < 0.9
