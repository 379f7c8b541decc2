"""Benchmark and statistics of the magnetometer calibration (processing.magnetometer).

    .venv/bin/python bench/magnetometer_calibration.py [--seeds 200]

1. Speed: one day of 1 Hz magnetometer data (seed-004 spacecraft librating under the 004 disturbance, bias,
   scale factors and non-orthogonality injected, 100 nT noise): our calibration (TWOSTEP start + bias-corrected
   Gauss-Newton with the analytic Jacobian, covariance, whiteness, observability) against a plain
   scipy.optimize.least_squares on the same residuals (numerical Jacobian, no covariance), measured in the
   same run; the reference |B| along the GNSS orbit (the job's path: IGRF-14 every 10 s, spline) is timed
   separately (it is shared by both).
2. Coverage: the share of |estimate - truth| < 3 sigma (and 2 sigma, 1 sigma) over N noise seeds, 9
   parameters, three orbits at 0.2 Hz; mean and spread of the z-scores.
3. Coupling: the same with the magnetorquer coupling (18 parameters), a duty-cycled dipole (+-5 A m^2 or off per
   axis, switched every 60 s), N/4 seeds.
4. False alarms: clean data (no error injected), N seeds: the share of runs that would raise a warning
   (whiteness or chi-square test failing at 1e-3, an outlier rejected, a parameter not observable).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import least_squares

from processing.magnetometer.calibration import CalibrationSettings, _residual_and_jacobian, calibrate_magnetometer
from processing.magnetometer.model import MagnetometerErrors
from processing.magnetometer.reference import reference_field_norm_nT
from processing.simulate.seed004 import orbit_period_s, simulate_seed004
from processing.time.timescales import iso_to_tai_ns

T0 = int(iso_to_tai_ns(["2025-03-20T12:00:00"])[0])
ERRORS = MagnetometerErrors.from_components([300.0, -200.0, 150.0], [0.02, -0.01, 0.015], [0.005, -0.003, 0.004])
TRUTH = np.concatenate([ERRORS.bias_nT, ERRORS.scale_factor_errors, ERRORS.non_orthogonality_rad])
NOISE_NT = 100.0


def _arc(duration_s: float) -> tuple[np.ndarray, np.ndarray, float]:
    sc = simulate_seed004(start_tai_ns=T0, duration_s=duration_s, seed=1, controller="none", estimator="truth",
                          magnetometer_noise_nT=0.0)
    m, g = sc.streams["magnetometer"], sc.streams["gnss"]
    t = time.perf_counter()  # the job's path: GNSS Hermite, IGRF-14 every 10 s, spline
    ref, ok = reference_field_norm_nT(m["time_tai_ns"], g["time_tai_ns"], np.column_stack([g["x"], g["y"], g["z"]]),
                                      np.column_stack([g["vx"], g["vy"], g["vz"]]))
    assert ok.all()
    return np.column_stack([m["bx"], m["by"], m["bz"]]), ref, time.perf_counter() - t


def speed() -> None:
    B, ref, t_igrf = _arc(86400.0)
    H = ERRORS.measure(B) + np.random.default_rng(0).normal(size=B.shape) * NOISE_NT
    settings = CalibrationSettings(magnetometer_noise_nT=NOISE_NT)
    calibrate_magnetometer(H[:1000], ref[:1000], sample_period_s=1.0, settings=settings)  # warm-up
    t = time.perf_counter()
    c = calibrate_magnetometer(H, ref, sample_period_s=1.0, settings=settings)
    t_ours = time.perf_counter() - t
    t = time.perf_counter()
    ls = least_squares(lambda p: _residual_and_jacobian(p, H, ref, None)[0], np.zeros(9), method="trf")
    t_ls = time.perf_counter() - t
    print(f"one day at 1 Hz: {B.shape[0]} samples; IGRF-14 |B| along the GNSS orbit {t_igrf:.2f} s (shared; job path)")
    print(f"  ours:                      {t_ours:.3f} s, {c.iterations} iterations, complete={c.complete}, "
          f"max |z| = {np.max(np.abs((c.estimate - TRUTH) / c.sigma)):.2f}")
    print(f"  scipy least_squares (trf, numerical Jacobian, no covariance): {t_ls:.3f} s, {ls.nfev} evaluations, "
          f"max |x - ours| / sigma = {np.max(np.abs(ls.x - c.estimate) / c.sigma):.2f}")


def statistics(seeds: int) -> None:
    B, ref, _ = _arc(3 * orbit_period_s())
    B, ref = B[::5], ref[::5]
    settings = CalibrationSettings(magnetometer_noise_nT=NOISE_NT)
    rng = np.random.default_rng(2026)
    z, alarms_err, alarms_clean, t0 = [], 0, 0, time.perf_counter()
    for _ in range(seeds):
        c = calibrate_magnetometer(ERRORS.measure(B) + rng.normal(size=B.shape) * NOISE_NT, ref, sample_period_s=5.0,
                                   settings=settings)
        z.append((c.estimate - TRUTH) / c.sigma)
        alarms_err += _alarm(c)
        c0 = calibrate_magnetometer(B + rng.normal(size=B.shape) * NOISE_NT, ref, sample_period_s=5.0,
                                    settings=settings)
        alarms_clean += _alarm(c0)
    z = np.array(z)
    print(f"coverage over {seeds} seeds, 9 parameters, 3 orbits at 0.2 Hz, 100 nT "
          f"({time.perf_counter() - t0:.1f} s for {2 * seeds} fits):")
    for k in (1, 2, 3):
        print(f"  |z| < {k}: {np.mean(np.abs(z) < k):.4f}")
    print(f"  per-parameter z mean {np.array2string(z.mean(axis=0), precision=2)}")
    print(f"  per-parameter z std  {np.array2string(z.std(axis=0), precision=2)}")
    print(f"false-alarm rate (any warning condition): injected errors {alarms_err}/{seeds}, "
          f"clean {alarms_clean}/{seeds}")


def coupling(seeds: int) -> None:
    B, ref, _ = _arc(3 * orbit_period_s())
    B, ref = B[::5], ref[::5]
    rng = np.random.default_rng(99)
    mu = np.repeat(rng.choice([-5.0, 0.0, 5.0], size=(B.shape[0] // 12 + 1, 3)), 12, axis=0)[: B.shape[0]]
    C = np.array([[50.0, 10.0, 0.0], [0.0, -30.0, 5.0], [8.0, 0.0, 40.0]])
    e = MagnetometerErrors(ERRORS.bias_nT, ERRORS.D, C)
    truth = np.concatenate([TRUTH, C.ravel()])
    z, complete = [], 0
    for _ in range(seeds):
        c = calibrate_magnetometer(e.measure(B, mu) + rng.normal(size=B.shape) * NOISE_NT, ref, sample_period_s=5.0,
                                   mu_B_A_m2=mu, settings=CalibrationSettings(estimate_coupling=True))
        z.append((c.estimate - truth) / c.sigma)
        complete += c.complete
    z = np.array(z)
    print(f"coupling: {seeds} seeds, 18 parameters: |z| < 3 {np.mean(np.abs(z) < 3):.4f}, |z| < 2 "
          f"{np.mean(np.abs(z) < 2):.4f}; z mean within +-{np.max(np.abs(z.mean(axis=0))):.2f}, std "
          f"{z.std(axis=0).min():.2f}-{z.std(axis=0).max():.2f}; complete {complete}/{seeds}")


def _alarm(c: object) -> bool:
    return bool(c.inflation > 1 or (c.chi2 is not None and c.chi2[2] < 1e-3)  # type: ignore[attr-defined]
                or not c.used.all() or not c.complete)  # type: ignore[attr-defined]


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=200)
    args = parser.parse_args()
    speed()
    statistics(args.seeds)
    coupling(max(args.seeds // 4, 5))
