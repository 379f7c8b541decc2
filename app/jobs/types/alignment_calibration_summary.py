"""Job ``alignment_calibration``: what a finished calibration becomes in the report - its notes, summary
(alignment, observability, drift, process), the not_observable warnings, the calibration version and the
tables. The run is in :mod:`app.jobs.types.alignment_calibration`, the figures in
:mod:`app.jobs.types.alignment_calibration_figures`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from processing.attitude import rotations
from processing.gyro_calibration.calibration import GyroCalibration
from processing.gyro_calibration.drift_observer import MODE_NAMES, stationary_noise
from processing.tasks import ResultWarning
from processing.units import ARCSEC_PER_RAD, DEG_PER_RAD, NS_PER_S, RAD_PER_ARCSEC, RAD_PER_DEG

if TYPE_CHECKING:
    from app.jobs.types.alignment_calibration import Params

RESIDUAL_TABLE_MAX_ROWS = 30_000
"""The rate-residual table keeps every k-th window sample so that it has at most this many rows."""


def _floats(x: Any) -> list[float | None]:
    return [float(v) if np.isfinite(v) else None for v in np.asarray(x, dtype=np.float64).reshape(-1)]


def _history_entry(entry: dict[str, object]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in entry.items():
        if isinstance(value, list):
            out[key] = _floats(value)
        elif isinstance(value, int):
            out[key] = value
        else:
            v = float(value)  # type: ignore[arg-type]
            out[key] = v if np.isfinite(v) else None
    return out


@dataclass(frozen=True)
class CalibrationRun:
    """A finished calibration with what it was computed from: the sensors and streams used, their
    frames (q_BS, q_BG configured, q_GS_nom = q_BG^-1 o q_BS), the time origin t0 (TAI ns) of the
    calibration's seconds and the job window."""

    cal: GyroCalibration
    params: Params
    sensor: str
    source: str
    t0: int
    q_BS: NDArray[np.float64]
    q_BG: NDArray[np.float64]
    q_GS_nom: NDArray[np.float64]
    n_gyro: int
    n_st: int
    window_start_tai_ns: int
    window_end_tai_ns: int

    def ns(self, t_s: Any) -> NDArray[np.int64]:
        """Calibration seconds -> TAI ns."""
        return self.t0 + np.round(np.asarray(t_s, dtype=np.float64) * NS_PER_S).astype(np.int64)

    @property
    def complete(self) -> bool:
        """Every parameter determined and the iteration converged: only then a calibration version."""
        return bool(self.cal.alignment.complete and self.cal.converged)


def calibration_notes(r: CalibrationRun) -> list[str]:
    observable = r.cal.alignment.observable_axes
    notes = []
    if not np.all(observable):
        notes.append(
            "misalignment about " + ", ".join("xyz"[i] for i in np.flatnonzero(~observable)) + " (star-tracker axes) "
            "is not observable from the rate directions in the window: reported as null and kept at the "
            "configured mounting in the quaternions"
        )
    if not r.cal.converged:
        notes.append(f"the calibration did not settle within {r.params.iterations} passes (change above "
                     f"{r.params.change_tolerance_sigma} sigma)")
    return notes


def calibration_summary(r: CalibrationRun) -> dict[str, Any]:
    """DESIGN.md summary of alignment_calibration (module docstring), in report order."""
    return {
        "sensor": r.sensor,
        "gyro_stream": r.source,
        "n_star_tracker_samples": r.n_st,
        "n_gyro_samples": r.n_gyro,
        "window_start_tai_ns": r.window_start_tai_ns,
        "window_end_tai_ns": r.window_end_tai_ns,
        **_alignment_summary(r),
        **_drift_summary(r),
        **_process_summary(r),
        "calibration_complete": r.complete,
        "calibration": _calibration(r),
    }


def _alignment_summary(r: CalibrationRun) -> dict[str, Any]:
    est = r.cal.alignment
    observable = est.observable_axes
    mis = np.where(observable, est.misalignment_rad, np.nan)
    sig = est.misalignment_sigma_rad
    sf_ok = bool(np.all(est.scale_factor_observable))
    m = est.scale_factor_error if sf_ok else float("nan")
    m_sig = est.scale_factor_sigma if sf_ok else float("nan")
    out: dict[str, Any] = {
        "misalignment_rad": _floats(mis),
        "misalignment_arcsec": _floats(mis / RAD_PER_ARCSEC),
        "misalignment_sigma_rad": _floats(sig),
        "misalignment_sigma_arcsec": _floats(sig / RAD_PER_ARCSEC),
        "misalignment_quaternion": _floats(rotations.quat_canonical(rotations.rotvec_to_quat(est.misalignment_rad))),
        "misalignment_observable": [bool(v) for v in observable],
        "q_GS": _floats(est.q_GS),
        "q_GS_nominal": _floats(r.q_GS_nom),
        "rate_spread_eigenvalues": _floats(est.spread_eigenvalues),
        "scale_factor_error": _floats([m])[0],
        "scale_factor_error_sigma": _floats([m_sig])[0],
        "scale_factor_error_percent": _floats([100.0 * m])[0],
        "scale_factor_observable": sf_ok,
    }
    if r.params.per_axis_scale_factor:
        per_axis_ok = est.observability.determinable[:3]
        out["scale_factor_error_per_axis"] = _floats(est.scale_factor_per_axis)
        out["scale_factor_error_per_axis_sigma"] = _floats(np.where(per_axis_ok, est.scale_factor_per_axis_sigma,
                                                                    np.nan))
        out["scale_factor_observable"] = [bool(v) for v in per_axis_ok]
    out["observability"] = _observability_summary(r)
    return out


def _observability_summary(r: CalibrationRun) -> dict[str, Any]:
    """The information-matrix analysis of the last alignment pass (processing.gyro_calibration.observability)."""
    est = r.cal.alignment
    info = est.observability
    return {
        "parameters": list(info.names),
        "determinable": [bool(v) for v in info.determinable],
        "relative_eigenvalues": _floats(info.eigenvalues),
        "rank": info.rank,
        "rank_tolerance": info.rank_tolerance,
        "null_component": _floats(info.null_component),
        "variance_inflation": _floats(info.variance_inflation),
        "correlation": [_floats(row) for row in info.correlation],
        "residual_variance_factor": _floats([est.residual_variance_factor])[0],
        "misalignment_sigma_jackknife_arcsec": _floats(_jackknife_misalignment_sigma(est) / RAD_PER_ARCSEC),
    }


def _jackknife_misalignment_sigma(est: Any) -> NDArray[np.float64]:
    names = est.observability.names
    idx = [names.index(f"misalignment_{a}") for a in "xyz"]
    return np.sqrt(np.diag(est.jackknife_cov)[idx])


def _drift_summary(r: CalibrationRun) -> dict[str, Any]:
    cal = r.cal
    model = cal.drift_model
    ok = cal.alignment.drift_observable
    drift = np.where(ok, cal.drift_rad_s, np.nan)
    sigma = np.where(ok, cal.drift_sigma_rad_s, np.nan)
    return {
        "drift_rad_s": _floats(drift),
        "drift_arcsec_s": _floats(drift / RAD_PER_ARCSEC),
        "drift_sigma_rad_s": _floats(sigma),
        "drift_sigma_arcsec_s": _floats(sigma / RAD_PER_ARCSEC),
        "drift_observable": [bool(v) for v in ok],
        "apparent_drift_rad_s": _floats(cal.drift_rad_s),
        "drift_frame": "gyro (w_meas = (1 + m) S^Delta w + b)",
        "drift_time_tai_ns": int(r.ns(cal.observer.t_s[-1])),
        "drift_noise_rad_s": _floats(cal.drift_noise_rad_s),
        "drift_correlation_time_s": _floats(cal.drift_correlation_time_s),
        "drift_convergence_s": float(cal.drift_convergence_s) if np.isfinite(cal.drift_convergence_s) else None,
        "drift_model": {
            "t_ref_tai_ns": int(r.ns(model.t_ref_s)), "scale_s": model.scale_s,
            "coefficients_rad_s": [_floats(c) for c in model.coefficients],
        },
        "alignment_drift_offset_rad_s": _floats(cal.alignment.drift_offset(cal.observer.t_s[-1])),
    }


def observability_warnings(r: CalibrationRun) -> list[ResultWarning]:
    """``not_observable`` naming what the arc does not determine and the motion that would determine it."""
    from processing.gyro_calibration.observability import motion_summary

    est = r.cal.alignment
    undet: list[str] = [f"misalignment about {a}" for a, ok in zip("xyz", est.observable_axes, strict=True) if not ok]
    if not np.all(est.scale_factor_observable):
        undet.append("the scale factor")
    undet += [f"drift {a}" for a, ok in zip("xyz", est.drift_observable, strict=True) if not ok]
    if r.params.per_axis_scale_factor:
        undet += [f"scale factor {a}" for a, ok in zip("xyz", est.observability.determinable[:3], strict=True)
                  if not ok]
    if not undet:
        return []
    win = r.cal.windows
    used = r.cal.windows_used[win.window]
    motion = motion_summary(win.w_A_rad_s[used], 1.0 / win.rate_variance_s2[used])
    dcm_BS = rotations.quat_to_dcm(r.q_BS)
    axes_B = dcm_BS @ motion.axes
    rms = motion.rms_rate_rad_s / RAD_PER_DEG
    mean, std = motion.mean_rate_rad_s / RAD_PER_DEG, motion.std_rate_rad_s / RAD_PER_DEG

    def axis(v: NDArray[np.float64]) -> str:
        return "body (" + ", ".join(f"{c:+.2f}" for c in v) + ")"

    weak = [i for i in range(1, 3) if rms[i] < 0.1 * rms[0]]
    # rates that would give a 1" misalignment sigma and a 0.005 % scale-factor sigma (000's targets) with
    # windows like these: sigma_theta ~ sigma_offset / w_perp, sigma_m ~ sigma_offset / std|w|
    offset = float(np.nanmax(est.rate_offset_sigma_rad_s)) if np.any(np.isfinite(est.rate_offset_sigma_rad_s)) \
        else float("nan")
    need_w = max(offset / RAD_PER_ARCSEC / RAD_PER_DEG, 0.05) if np.isfinite(offset) else 0.1
    need_s = max(offset / 5e-5 / RAD_PER_DEG, 0.01) if np.isfinite(offset) else 0.1
    advice = []
    if any(u.startswith("misalignment") for u in undet):
        if weak:
            advice.append("rotate also about " + " or ".join(axis(axes_B[:, i]) for i in weak)
                          + f" at >= {need_w:.2g} deg/s rms in the slow (<= 1 deg/s) windows, as many as here, for a "
                          f"1 arcsec sigma (the arc turns mainly about {axis(axes_B[:, 0])} at {rms[0]:.3f} deg/s "
                          "rms; about the others only " + ", ".join(f"{rms[i]:.4f}" for i in range(1, 3)) + " deg/s)")
        else:
            advice.append("rotate about more directions (the misalignment about an axis is seen only through rates "
                          "perpendicular to it)")
    if any(u.startswith(("the scale factor", "drift", "scale factor")) for u in undet):
        advice.append(f"vary the rate magnitude and sense (|w| is {mean:.3f} +- {std:.4f} deg/s here; a spread of "
                      f">= {need_s:.2g} deg/s gives a 0.005 % scale-factor sigma: the scale factor and the drift "
                      "along the rate axis are separated only by changes of the rate, e.g. scans at 0.3-1 deg/s in "
                      "both senses about several axes)")
    message = ("the rate history of the calibration windows does not determine " + ", ".join(undet)
               + " (reported as null; no calibration version is stored). To determine them: "
               + "; ".join(advice) + ".")
    info = est.observability
    evidence = {
        "undetermined": undet, "parameters": list(info.names),
        "relative_eigenvalues": _floats(info.eigenvalues), "rank_tolerance": info.rank_tolerance,
        "null_component": _floats(info.null_component), "rate_axes_body": [_floats(axes_B[:, i]) for i in range(3)],
        "rms_rate_deg_s": _floats(rms), "rate_magnitude_deg_s": {"mean": mean, "std": std},
        "rate_spread_eigenvalues": _floats(est.spread_eigenvalues),
        "rate_offset_sigma_arcsec_s": _floats(est.rate_offset_sigma_rad_s / RAD_PER_ARCSEC),
        "rate_needed_deg_s": {"misalignment_1_arcsec": need_w, "scale_factor_0_005_percent_spread": need_s},
    }
    return [ResultWarning("not_observable", message, evidence)]


def _process_summary(r: CalibrationRun) -> dict[str, Any]:
    """Windows, iterations, observer, noise, slews: how the calibration was obtained."""
    cal, params = r.cal, r.params
    est, obs, slews = cal.alignment, cal.observer, cal.slews
    assert slews is not None
    corrected = obs.mode == 1
    innov = obs.innovation_rad
    residual_rms = np.sqrt(np.mean(innov[corrected] ** 2, axis=0)) if np.any(corrected) else np.full(3, np.nan)
    st_noise = float(np.sqrt(np.mean(cal.st_noise_rad**2)))
    att_sd, drift_sd = stationary_noise(float(np.median(np.diff(obs.t_s))), params.t_r_s, st_noise, params.xi)
    return {
        "calibration_windows": int(est.n_windows),
        "calibration_windows_found": int(cal.windows.starts.size),
        "alignment_samples": int(est.n_samples),
        "iterations": len(cal.iterations) - 1,
        "converged": bool(cal.converged),
        "iteration_history": [_history_entry(h) for h in cal.iterations],
        "observer": {
            "t_r_s": params.t_r_s, "xi": params.xi, "g1": obs.g1, "g2_per_s": obs.g2,
            "stationary_attitude_sigma_arcsec": att_sd / RAD_PER_ARCSEC,
            "stationary_drift_sigma_arcsec_s": drift_sd / RAD_PER_ARCSEC,
            "samples_by_mode": {name: int(np.sum(obs.mode == code)) for code, name in MODE_NAMES.items()},
        },
        "star_tracker_noise_arcsec": _floats(cal.st_noise_rad / RAD_PER_ARCSEC),
        "attitude_residual_rms_arcsec": _floats(residual_rms / RAD_PER_ARCSEC),
        "n_slews": int(slews.start_s.size),
        "slew_end_error_max_arcsec": (float(np.max(slews.end_error_rad) * ARCSEC_PER_RAD)
                                      if slews.start_s.size else None),
        "slew_error_bound_max_arcsec": float(np.max(slews.bound_rad) / RAD_PER_ARCSEC) if slews.start_s.size else None,
        "slew_bound_exceeded": int(np.sum(slews.end_error_rad > slews.bound_rad)),
        "integration_error_max_arcsec": cal.integration_error_rad / RAD_PER_ARCSEC,
        "solver_disagreement_rad": est.solver_disagreement_rad,
    }


def _calibration(r: CalibrationRun) -> dict[str, Any]:
    """The calibration version the service stores for the spacecraft's gyro (q_BG = q_BS o q_GS^-1)."""
    est, obs = r.cal.alignment, r.cal.observer
    q_BG_cal = rotations.quat_canonical(rotations.quat_multiply(r.q_BS, rotations.quat_conjugate(est.q_GS)))
    return {
        "kind": "gyro", "paper": "000", "star_tracker": r.sensor, "valid_from_tai_ns": int(r.ns(obs.t_s[0])),
        "valid_to_tai_ns": int(r.ns(obs.t_s[-1])), "q_BG": _floats(q_BG_cal), "q_BG_configured": _floats(r.q_BG),
        "q_GS": _floats(est.q_GS),
        "scale_factor_error": float(est.scale_factor_error) if np.all(est.scale_factor_observable) else None,
        "drift_rad_s": _floats(np.where(est.drift_observable, r.cal.drift_rad_s, np.nan)), "complete": r.complete,
    }


def calibration_tables(cal: GyroCalibration, ns: Any) -> dict[str, dict[str, NDArray[Any]]]:
    obs = cal.observer
    win = cal.windows
    est = cal.alignment
    b = obs.drift_rad_s / RAD_PER_ARCSEC
    model = cal.drift_model(obs.t_s) / RAD_PER_ARCSEC
    post = rotations.quat_to_mrp(rotations.quat_multiply(rotations.quat_conjugate(obs.q_post),
                                                         _measured(obs))) * 4.0 / RAD_PER_ARCSEC
    mode_names = np.array([MODE_NAMES[int(m)] for m in range(4)], dtype=object)[obs.mode]
    tables: dict[str, dict[str, NDArray[Any]]] = {
        "drift": {
            "time_tai_ns": ns(obs.t_s), "mode": mode_names,
            **{f"drift_{a}_arcsec_s": b[:, i] for i, a in enumerate("xyz")},
            **{f"model_{a}_arcsec_s": model[:, i] for i, a in enumerate("xyz")},
        },
        "attitude_residuals": {
            "time_tai_ns": ns(obs.t_s), "mode": mode_names,
            **{f"prior_{a}_arcsec": obs.innovation_rad[:, i] / RAD_PER_ARCSEC for i, a in enumerate("xyz")},
            **{f"post_{a}_arcsec": post[:, i] for i, a in enumerate("xyz")},
        },
    }
    # Rate-direction coverage: one row per window (mean rate over the window, star-tracker axes).
    counts = np.bincount(win.window, minlength=win.starts.size)
    mean_w = np.stack([np.bincount(win.window, weights=win.w_A_rad_s[:, i], minlength=win.starts.size) for i in
                       range(3)], axis=-1) / np.maximum(counts, 1)[:, None]
    norm = np.linalg.norm(mean_w, axis=-1)
    unit = mean_w / np.where(norm > 0, norm, 1.0)[:, None]
    t_mid = np.bincount(win.window, weights=win.t_s, minlength=win.starts.size) / np.maximum(counts, 1)
    tables["rate_coverage"] = {
        "time_tai_ns": ns(t_mid), "n_star_tracker_samples": (win.stops - win.starts).astype(np.int64),
        "used": cal.windows_used.astype(bool), "mean_rate_deg_s": norm / RAD_PER_DEG,
        **{f"direction_{a}": unit[:, i] for i, a in enumerate("xyz")},
        **{f"fit_residual_{a}_arcsec": win.residual_rms_rad[:, i] / RAD_PER_ARCSEC for i, a in enumerate("xyz")},
    }
    used_samples = cal.windows_used[win.window]
    t_used = win.t_s[used_samples]
    step = max(1, -(-t_used.size // RESIDUAL_TABLE_MAX_ROWS))
    res = est.residual_rad_s[::step] / RAD_PER_ARCSEC
    tables["rate_residuals"] = {
        "time_tai_ns": ns(t_used[::step]),
        "rate_deg_s": np.linalg.norm(win.w_A_rad_s[used_samples][::step], axis=-1) / RAD_PER_DEG,
        **{f"residual_{a}_arcsec_s": res[:, i] for i, a in enumerate("xyz")},
    }
    slews = cal.slews
    assert slews is not None
    tables["slews"] = {
        "time_tai_ns": ns(slews.start_s), "end_tai_ns": ns(slews.end_s), "duration_s": slews.end_s - slews.start_s,
        "rotation_angle_deg": slews.rotation_angle_rad * DEG_PER_RAD,
        "peak_rate_deg_s": slews.peak_rate_rad_s * DEG_PER_RAD,
        "end_error_arcsec": slews.end_error_rad / RAD_PER_ARCSEC, "bound_arcsec": slews.bound_rad / RAD_PER_ARCSEC,
    }
    return tables


def _measured(obs: Any) -> NDArray[np.float64]:
    """Measured quaternions reconstructed from the prior and the innovation (4 sigma)."""
    sigma = obs.innovation_rad / 4.0
    return rotations.quat_multiply(obs.q_prior, rotations.mrp_to_quat(sigma))
