"""In-flight gyro calibration and alignment against a star tracker, end to end (paper 000).

Somov & Butyrin (2016), 000. Inputs: gyro angle increments (eq. 1) in the gyro frame G and
star-tracker quaternions q_IS (frame A = S) every T_o. Steps:

1. two-pass filter of the increments (figure 1) -> C2 quintic spline of the quasi-coordinates
   (processing.signal.two_pass_filter);
2. motion classes from the filtered rate: a star-tracker sample is in MT_alpha when |w| <= the rate
   threshold (1 deg/s) over the intervals on both sides; alignment windows of 12..18 samples inside
   MT_alpha and their star-tracker rates from 5th-order MRP polynomials (processing.gyro_calibration.alignment);
   windows whose polynomial residual exceeds ``window_outlier_factor`` x the median (motion the
   polynomial cannot follow, e.g. across the start of a slew) are left out;
3. pass 0: QUEST alignment (eq. 9) and scale factor with a jointly estimated drift polynomial of the
   trend degree (there is no drift model yet);
4. pass i >= 1: the calibrated spline (eq. 2) is integrated over every star-tracker interval (eq. 7,
   Dormand-Prince 5(4)); the nonlinear Luenberger observer (eqs. 4-8) estimates drift and attitude, with
   the correction off and the drift predicted from its trend during slews (processing.gyro_calibration.drift_observer);
   the drift model is the least-squares trend of its corrected estimates over the whole span; the
   alignment and scale factor are re-estimated with that model subtracted and a constant residual drift
   estimated jointly;
5. stop when the change of every estimate is below ``change_tolerance`` times its standard deviation
   (000 does one pass), at most max_iterations passes after pass 0.

The last observer run (with the calibration of the last-but-one estimate, which differs from the final
one by less than the tolerance) gives the drift history, the attitude residuals and the slews; the
reported drift is the trend of the last window (``trend_window_s``) at the end of the data.

Layout: the settings, the motion classes and steps 2-5 (windows, passes, drift summary and its sigma,
slews) are in processing.gyro_calibration.calibration_steps; this module holds the result, the entry
point and :func:`apply_gyro_calibration`.

Times are float64 seconds from any epoch (the job converts int64 TAI ns); quaternions scalar first.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.gyro_calibration.alignment import AlignmentEstimate
from processing.gyro_calibration.calibration_steps import (
    CalibrationError,
    CalibrationSettings,
    align_windows,
    build_context,
    correction_flags,
    drift_convergence_time,
    drift_summary,
    iterate_passes,
    pass_slew_report,
)
from processing.gyro_calibration.drift_observer import (
    DriftObserverResult,
    DriftTrend,
)
from processing.gyro_calibration.slews import SlewReport
from processing.gyro_calibration.window_rates import (
    WindowRates,
)
from processing.signal.gyro_integration import (
    IntervalRotations,
)
from processing.signal.two_pass_filter import QuasiCoordinateSpline, two_pass_filter

__all__ = [
    "CalibrationError",
    "CalibrationSettings",
    "GyroCalibration",
    "apply_gyro_calibration",
    "calibrate_gyro",
    "correction_flags",
    "drift_convergence_time",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class GyroCalibration:
    """Result of :func:`calibrate_gyro`.

    alignment: the final :class:`AlignmentEstimate` (q_GS, misalignment, scale factor, sigmas).
    drift_rad_s (3,): drift at the end of the data (trend of the last window), gyro frame;
    drift_model: whole-span trend; drift_noise_rad_s (3,): std of the corrected observer estimates
    about the model; drift_convergence_s: time from the first star-tracker sample after which every
    corrected drift estimate stays within the tolerance of the model (NaN if never);
    drift_sigma_rad_s (3,): 1-sigma of drift_rad_s (the end-of-trend functional of the observer's
    estimates: their correlated noise about the trend, with the correlation time drift_correlation_time_s
    (3,) from their lag-1 autocorrelation, and the apparent drift that the misalignment and scale-factor
    errors put into them); NaN where the alignment's information matrix does not determine the drift.
    observer: the last observer run; windows: the star-tracker window rates; rotations: the interval
    rotations of the last run; spline: the two-pass filtered raw gyro data (gyro frame);
    iterations: list of dicts (misalignment_rad, scale_factor_error, change in sigmas) per pass;
    converged: the change fell below the tolerance; slews: :class:`SlewReport`;
    st_noise_rad (3,): star-tracker noise per axis from the window fits; integration_error_rad: the
    largest Dormand-Prince error estimate over an interval; windows_used (W,): windows that passed the
    fit-residual test; observer_rate_map, observer_drift_ref_rad_s: the rate_map and drift_ref_rad_s of
    the last observer run (with ``rotations`` they reproduce it, e.g. with other motion classes).
    """

    alignment: AlignmentEstimate
    drift_rad_s: FloatArray
    drift_model: DriftTrend
    drift_noise_rad_s: FloatArray
    drift_convergence_s: float
    drift_sigma_rad_s: FloatArray
    drift_correlation_time_s: FloatArray
    observer: DriftObserverResult
    windows: WindowRates
    rotations: IntervalRotations
    spline: QuasiCoordinateSpline
    iterations: list[dict[str, object]] = field(default_factory=list)
    converged: bool = False
    slews: SlewReport | None = None
    st_noise_rad: FloatArray = field(default_factory=lambda: np.full(3, np.nan))
    integration_error_rad: float = float("nan")
    windows_used: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))
    observer_rate_map: FloatArray = field(default_factory=lambda: np.eye(3))
    observer_drift_ref_rad_s: FloatArray = field(default_factory=lambda: np.zeros(3))


def calibrate_gyro(
    gyro_time_s: ArrayLike,
    increments: ArrayLike,
    interval_s: ArrayLike,
    st_time_s: ArrayLike,
    q_IS: ArrayLike,
    *,
    q_GS_nominal: ArrayLike = (1.0, 0.0, 0.0, 0.0),
    settings: CalibrationSettings | None = None,
    progress: Callable[[float, str], None] | None = None,
) -> GyroCalibration:
    """Calibrate drift, misalignment and scale factor of a gyro against a star tracker (000).

    gyro_time_s (N,) [s] ends of the increments, increments (N, 3) [rad] in the gyro frame G,
    interval_s (N,) [s]; st_time_s (K,) [s], q_IS (K, 4) star-tracker attitude (frame A = S);
    q_GS_nominal: configured mounting of the gyro relative to the star tracker (q_BG^-1 o q_BS).
    Star-tracker samples outside the gyro data are dropped. See the module docstring for the steps.
    Returns :class:`GyroCalibration`.
    """
    cfg = settings or CalibrationSettings()
    report = progress or (lambda fraction, stage: None)
    t_st = np.asarray(st_time_s, dtype=np.float64)
    q_st = rotations.quat_normalize(np.asarray(q_IS, dtype=np.float64))
    if t_st.ndim != 1 or q_st.shape != (t_st.size, 4):
        raise CalibrationError(f"expected st_time_s (K,) and q_IS (K, 4), got {t_st.shape} and {q_st.shape}")
    if not np.all(np.diff(t_st) > 0):
        raise CalibrationError("star-tracker times must be strictly increasing (one star tracker at a time)")
    report(0.02, "two-pass filter of the gyro increments")
    spline = two_pass_filter(gyro_time_s, increments, interval_s)  # 1
    report(0.05, "motion classes and alignment windows")
    ctx = build_context(spline, t_st, q_st, q_GS_nominal, cfg)  # 2
    report(0.1, "pass 0: alignment and scale factor (QUEST) with a joint drift polynomial")
    est = align_windows(ctx, None, ctx.q_nom, 0.0, cfg.trend_degree)  # 3
    passes = iterate_passes(ctx, est, report)  # 4-5
    report(0.92, "drift trend, convergence and slews")
    drift = drift_summary(ctx, passes)
    slews = pass_slew_report(ctx, passes, drift.noise_rad_s)
    report(1.0, "done")
    last = passes.last
    return GyroCalibration(
        alignment=last.est, drift_rad_s=drift.end_rad_s, drift_model=last.model, drift_noise_rad_s=drift.noise_rad_s,
        drift_convergence_s=drift.convergence_s, drift_sigma_rad_s=drift.sigma_rad_s,
        drift_correlation_time_s=drift.correlation_time_s, observer=last.obs, windows=ctx.windows.rates,
        rotations=last.rot,
        spline=spline, iterations=list(passes.history), converged=passes.converged, slews=slews,
        st_noise_rad=ctx.windows.st_noise_rad, integration_error_rad=float(np.max(last.rot.error_rad)),
        windows_used=ctx.windows.used, observer_rate_map=last.rate_map, observer_drift_ref_rad_s=last.b_ref,
    )


def apply_gyro_calibration(
    values_G: ArrayLike,
    *,
    q_BG: ArrayLike,
    scale_factor_error: float,
    drift_rad_s: ArrayLike,
    interval_s: ArrayLike | None = None,
) -> FloatArray:
    """Calibrated gyro data in the body frame (000, eq. 2): R(q_BG) (x - b tau) / (1 + m).

    values_G (N, 3): rates [rad/s] (interval_s None) or increments [rad] over interval_s (N,) [s], in the
    gyro frame; q_BG: calibrated mounting (summary ``calibration.q_BG`` = q_BS o q_GS^-1);
    scale_factor_error m and drift_rad_s b (3,) or (N, 3) in the gyro frame, in the sense
    w_meas = (1 + m) S^Delta w + b. Returns (N, 3) body-frame rates or increments. This is what later
    jobs apply when they use a stored calibration version.
    """
    x = np.asarray(values_G, dtype=np.float64)
    b = np.asarray(drift_rad_s, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3 or b.shape not in {(3,), x.shape}:
        raise CalibrationError(f"expected values (N, 3) and drift (3,) or (N, 3), got {x.shape} and {b.shape}")
    if interval_s is not None:
        tau = np.asarray(interval_s, dtype=np.float64)
        if tau.shape != x.shape[:1]:
            raise CalibrationError(f"interval_s must be (N,) = {x.shape[:1]}, got {tau.shape}")
        b = b * tau[:, None]
    return rotations.quat_rotate(rotations.quat_normalize(np.asarray(q_BG, dtype=np.float64)), x - b) / (
        1.0 + float(scale_factor_error)
    )
