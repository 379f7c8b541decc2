"""Job ``alignment_calibration``: in-flight gyro drift, misalignment and scale factor against a star tracker (000).

Wraps :func:`processing.gyro_calibration.calibration.calibrate_gyro` (Somov & Butyrin 2016): two-pass filtering of
the gyro increments, the nonlinear Luenberger drift observer with motion classes and drift prediction
through slews, QUEST alignment and scale factor from rate comparisons in 12..18 s windows, iterated to
convergence. Gyro rates (stream ``gyro``) are integrated to increments when no ``gyro_increments`` are
in the window. Frames: A = the star tracker S; the gyro frame G from the configuration (gyro.q_BG).

Summary (DESIGN.md): ``misalignment_rad`` = rotation vector of the misalignment q_GS (v_G = q_GS o v_S
o q_GS^-1, S^Delta ~ I + [misalignment x]) relative to the configured mounting (identical to rotvec(q_GS)
when the configuration has the gyro aligned with the star tracker), ``misalignment_quaternion``,
``misalignment_sigma_rad``, ``scale_factor_error`` (w_meas = (1 + m) S^Delta w + b), ``drift_rad_s`` (b
in the gyro frame at the end of the window) with ``drift_sigma_rad_s``, ``drift_convergence_s``,
``calibration_windows``. Observability (issue 17; processing.gyro_calibration.observability): the
information matrix of (scale factor, misalignment, drift) from the rate history decides what is
determined; an undetermined value is null with ``misalignment_observable[3]``, ``scale_factor_observable``
(per axis with ``per_axis_scale_factor``), ``drift_observable[3]`` false and a ``not_observable`` warning
saying which motion would determine it; ``observability`` holds the analysis; ``apparent_drift_rad_s`` is
the drift that compensates the gyro under the arc's own motion (what a constant-rate arc does
determine). ``plausibility`` holds the star-tracker-against-gyro check (app.jobs.plausibility), whose
time offset is copied to ``time_offset_s`` / ``time_offset_sigma_s``. ``calibration`` holds the
calibration version the service stores for the spacecraft's gyro, only when ``calibration_complete``
(everything determined and the iteration converged). Figures follow 000 figs. 5-8.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, model_validator

from app.jobs.plausibility import HeadSamples, check_heads
from app.jobs.registry import JobType
from app.reports.headline import Answer
from processing.attitude import rotations
from processing.gyro_calibration.calibration import CalibrationSettings, GyroCalibration, calibrate_gyro
from processing.gyro_calibration.drift_observer import MODE_NAMES, stationary_noise
from processing.signal.two_pass_filter import increments_from_rates
from processing.tasks import Progress, ResultWarning, TaskError, TaskInputs, TaskResult
from processing.units import ARCSEC_PER_RAD, DEG_PER_RAD, NS_PER_S, RAD_PER_ARCSEC, RAD_PER_DEG

RESIDUAL_TABLE_MAX_ROWS = 30_000
"""The rate-residual table keeps every k-th window sample so that it has at most this many rows."""


class Params(BaseModel):
    """Parameters of ``alignment_calibration`` (000; defaults from the paper where it gives them)."""

    model_config = ConfigDict(extra="forbid")

    sensor: str | None = Field(None, description="Star tracker (frame A); None: the only one configured with data.")
    gyro_source: Literal["auto", "gyro_increments", "gyro"] = Field(
        "auto", description="Gyro stream: increments (preferred by auto) or rates integrated to increments."
    )
    t_r_s: PositiveFloat = Field(
        200.0, description="Observer settling time T_r (000: nu = 3/(xi T_r)); the start-up uses growing-memory "
        "gains, so convergence does not wait for T_r. Smaller T_r tracks a varying drift with less lag, larger "
        "T_r has less noise.",
    )
    xi: float = Field(0.95, gt=0.0, lt=1.0, description="Damping of the observer poles (000: 0.95).")
    rate_threshold_deg_s: PositiveFloat = Field(1.0, description="Class MT_alpha: |w| <= this (000: 1 deg/s).")
    window_min_samples: int = Field(12, ge=8, description="Shortest alignment window in samples (000: 12).")
    window_max_samples: int = Field(18, ge=8, description="Longest alignment window in samples (000: 18).")
    output_period_s: PositiveFloat = Field(0.125, le=1.0, description="T_p of the rate comparison (000: 0.125 s).")
    trend_window_s: PositiveFloat = Field(600.0, description="Drift trend window for the slew prediction and the "
                                          "reported drift.")
    trend_degree: int = Field(2, ge=0, le=3, description="Degree of the drift trend (000: 2).")
    iterations: int = Field(6, ge=1, le=20, description="Most calibrate / re-run passes (000 does one).")
    change_tolerance_sigma: PositiveFloat = Field(0.2, description="Stop when every change < this x its sigma.")
    acquisition: bool = Field(True, description="Growing-memory observer gains at start-up.")
    lag_compensation: bool = Field(False, description="Advance the drift trends by the observer's ramp lag.")
    min_rate_spread: float = Field(0.02, ge=0.0, lt=1.0, description="Rate-direction spread eigenvalue below "
                                   "which the misalignment about that direction is unobservable.")
    max_misalignment_sigma_arcsec: PositiveFloat = Field(10.0, description="Misalignment directions with a larger "
                                                         "sigma are unobservable.")
    convergence_tolerance_arcsec_s: PositiveFloat = Field(0.01, description="Tube of the drift convergence time.")
    per_axis_scale_factor: bool = Field(False, description="Also estimate the scale-factor error per gyro axis (linear "
                                        "step of the alignment; the chain itself applies the scalar one).")
    rank_tolerance: float = Field(1e-6, gt=0.0, lt=1.0, description="Eigenvalue of the unit-diagonal information "
                                  "matrix (relative to the largest) below which a parameter combination is not "
                                  "determined.")

    @model_validator(mode="after")
    def _windows(self) -> Params:
        if self.window_max_samples < self.window_min_samples:
            raise ValueError(f"window_max_samples ({self.window_max_samples}) must be >= window_min_samples "
                             f"({self.window_min_samples})")
        return self

    def settings(self) -> CalibrationSettings:
        return CalibrationSettings(
            t_r_s=self.t_r_s, xi=self.xi, rate_threshold_rad_s=self.rate_threshold_deg_s * RAD_PER_DEG,
            window_min=self.window_min_samples, window_max=self.window_max_samples,
            output_period_s=self.output_period_s, trend_window_s=self.trend_window_s,
            trend_degree=self.trend_degree, max_iterations=self.iterations,
            change_tolerance=self.change_tolerance_sigma, acquisition=self.acquisition,
            min_spread=self.min_rate_spread,
            max_misalignment_sigma_rad=self.max_misalignment_sigma_arcsec * RAD_PER_ARCSEC,
            convergence_tolerance_rad_s=self.convergence_tolerance_arcsec_s * RAD_PER_ARCSEC,
            lag_compensation=self.lag_compensation, per_axis_scale_factor=self.per_axis_scale_factor,
            rank_tolerance=self.rank_tolerance,
        )


# ---------------------------------------------------------------------------------------------------


def _floats(x: Any) -> list[float | None]:
    return [float(v) if np.isfinite(v) else None for v in np.asarray(x, dtype=np.float64).reshape(-1)]


def _star_tracker(inputs: TaskInputs, params: Params) -> tuple[str, NDArray[np.float64], NDArray[np.int64],
                                                               NDArray[np.float64]]:
    spacecraft = inputs.spacecraft
    configured = spacecraft.star_tracker_names
    present = list(inputs.sensors("star_tracker"))
    if not present:
        raise TaskError("no star_tracker samples in the job window")
    if params.sensor is None:
        names = [n for n in configured if n in present]
        if len(names) != 1:
            raise TaskError(
                f"choose the star tracker with 'sensor': configured {sorted(configured)}, with data {present}"
            )
        name = names[0]
    else:
        name = params.sensor
    q_BS = spacecraft.star_tracker_mounting(name)
    st = inputs.star_tracker(name)
    keep = np.concatenate([[True], np.diff(st.time_tai_ns) > 0])
    if not np.all(np.isfinite(st.q_IS)):
        raise TaskError("star-tracker quaternions must be finite")
    return name, q_BS, st.time_tai_ns[keep], st.q_IS[keep]


def _gyro(inputs: TaskInputs, params: Params, notes: list[str]) -> tuple[str, NDArray[np.int64], NDArray[np.float64],
                                                                        NDArray[np.float64]]:
    have = {name for name in ("gyro_increments", "gyro") if inputs.sensors(name)}
    source = params.gyro_source
    if source == "auto":
        if not have:
            raise TaskError("no gyro_increments or gyro samples in the job window; one of them is needed")
        source = "gyro_increments" if "gyro_increments" in have else "gyro"
    sensors = inputs.sensors(source)
    if len(sensors) > 1:
        raise TaskError(f"the window holds several gyro sensors ({list(sensors)}); one gyro triad is expected")
    if source == "gyro_increments":
        inc = inputs.gyro_increments()
        _distinct(inc.time_tai_ns, source)
        return source, inc.time_tai_ns, inc.da_G_rad, inc.interval_s
    g = inputs.gyro()
    t = g.time_tai_ns
    _distinct(t, source)
    t_s = (t - t[0]).astype(np.float64) / NS_PER_S
    t_end, incr, interval = increments_from_rates(t_s, g.w_G_rad_s)
    notes.append(f"gyro rates ({t.size} samples) integrated to increments by the trapezoidal rule")
    return source, t[0] + np.round(t_end * NS_PER_S).astype(np.int64), incr, interval


def _distinct(t: NDArray[np.int64], source: str) -> None:
    if np.any(np.diff(t) <= 0):
        raise TaskError(f"{source} times must be distinct; {int(np.sum(np.diff(t) <= 0))} repeated time stamps")


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
class _Run:
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


def run(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    notes: list[str] = []
    progress(0.01, "loading star tracker and gyro")
    sensor, q_BS, st_ns, q_IS = _star_tracker(inputs, params)
    if not inputs.spacecraft.has_gyro:
        notes.append("no gyro.q_BG in the configuration: the gyro frame is taken as the body frame")
    q_BG = inputs.spacecraft.gyro_mounting()
    source, g_ns, incr, interval = _gyro(inputs, params, notes)
    q_GS_nom = rotations.quat_canonical(rotations.quat_multiply(rotations.quat_conjugate(q_BG), q_BS))
    t0 = int(min(st_ns[0], g_ns[0] - int(round(interval[0] * NS_PER_S))))

    def seconds(t_ns: NDArray[np.int64]) -> NDArray[np.float64]:
        return (t_ns - t0).astype(np.float64) / NS_PER_S

    try:
        cal = calibrate_gyro(
            seconds(g_ns), incr, interval, seconds(st_ns), q_IS, q_GS_nominal=q_GS_nom,
            settings=params.settings(), progress=lambda f, stage: progress(0.02 + 0.9 * f, stage),
        )
    except ValueError as exc:
        raise TaskError(str(exc)) from exc
    progress(0.95, "summary and tables")
    done = _Run(cal=cal, params=params, sensor=sensor, source=source, t0=t0, q_BS=q_BS, q_BG=q_BG,
                q_GS_nom=q_GS_nom, n_gyro=int(g_ns.size), n_st=int(st_ns.size),
                window_start_tai_ns=inputs.start_tai_ns, window_end_tai_ns=inputs.end_tai_ns)
    summary = _summary(done)
    # mean rates over the increments at their midpoints (what the plausibility check takes)
    t_mid = g_ns - np.round(0.5 * np.asarray(interval) * NS_PER_S).astype(np.int64)
    w_mid = incr / np.asarray(interval, dtype=np.float64)[:, None]
    summary["plausibility"], plausible = check_heads([HeadSamples(sensor, st_ns, q_IS, q_BS)], t_mid, w_mid, q_BG,
                                                     notes)
    head = summary["plausibility"].get(sensor, {})
    summary["time_offset_s"] = head.get("time_offset_s")
    summary["time_offset_sigma_s"] = head.get("time_offset_sigma_s")
    warnings = plausible + _observability_warnings(done)
    return TaskResult(summary=summary, tables=_tables(cal, done.ns), notes=notes + _notes(done), warnings=warnings)


def _notes(r: _Run) -> list[str]:
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


def _summary(r: _Run) -> dict[str, Any]:
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


def _alignment_summary(r: _Run) -> dict[str, Any]:
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


def _observability_summary(r: _Run) -> dict[str, Any]:
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


def _drift_summary(r: _Run) -> dict[str, Any]:
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


def _observability_warnings(r: _Run) -> list[ResultWarning]:
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


def _process_summary(r: _Run) -> dict[str, Any]:
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


def _calibration(r: _Run) -> dict[str, Any]:
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


def _tables(cal: GyroCalibration, ns: Any) -> dict[str, dict[str, NDArray[Any]]]:
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


# ---------------------------------------------------------------------------------------------------
# Figures in the spirit of 000 figs. 5-8 (drift, attitude errors, rate errors and a fragment).

_COLOURS = ("tab:blue", "tab:green", "tab:red")


def _shade_predicted(ax: Any, t: NDArray[np.float64], mode: NDArray[Any]) -> None:
    pred = mode == "predicted"
    if not np.any(pred):
        return
    edges = np.flatnonzero(np.diff(np.concatenate([[0], pred.astype(int), [0]])))
    for a, b in zip(edges[0::2], edges[1::2], strict=True):
        ax.axvspan(t[a], t[min(b, t.size - 1)], color="0.9", lw=0)


def _fig_drift(result: TaskResult) -> Figure:
    tab = result.tables["drift"]
    t0 = int(tab["time_tai_ns"][0])
    t = (np.asarray(tab["time_tai_ns"]) - t0) / NS_PER_S
    fig = Figure(figsize=(9, 4.5), label="Gyro drift estimate (000 fig. 5)")
    ax = fig.add_subplot()
    _shade_predicted(ax, t, np.asarray(tab["mode"]))
    for i, a in enumerate("xyz"):
        ax.plot(t, tab[f"drift_{a}_arcsec_s"], color=_COLOURS[i], lw=0.8, label=f"b_{a}")
        ax.plot(t, tab[f"model_{a}_arcsec_s"], color=_COLOURS[i], lw=1.5, ls="--")
    end = [v / RAD_PER_ARCSEC for v in result.summary["apparent_drift_rad_s"] if v is not None]
    lo = (min(end) if end else -1.0) - 0.5
    hi = (max(end) if end else 1.0) + 0.5
    ax.set_ylim(lo, hi)
    ax.set_xlabel("time since the first sample [s]")
    ax.set_ylabel("drift [arcsec/s] (gyro frame)")
    conv = result.summary.get("drift_convergence_s")
    if conv is not None:
        ax.axvline(conv, color="k", lw=0.8, ls=":")
    ax.set_title("Drift estimate b^ (solid), trend (dashed); grey: slews, drift predicted")
    ax.legend(loc="upper right", ncols=3, fontsize=8)
    ax.grid(alpha=0.3)
    return fig


def _fig_attitude(result: TaskResult) -> Figure:
    tab = result.tables["attitude_residuals"]
    t0 = int(tab["time_tai_ns"][0])
    t = (np.asarray(tab["time_tai_ns"]) - t0) / NS_PER_S
    mode = np.asarray(tab["mode"])
    fig = Figure(figsize=(9, 4.5), label="Attitude residuals against the star tracker (000 fig. 6)")
    ax = fig.add_subplot()
    _shade_predicted(ax, t, mode)
    corr = mode == "corrected"
    for i, a in enumerate("xyz"):
        y = np.where(corr, np.asarray(tab[f"prior_{a}_arcsec"], dtype=float), np.nan)
        ax.plot(t, y, color=_COLOURS[i], lw=0.6, label=f"axis {a}")
    resumed = mode == "resumed"
    if np.any(resumed):
        mag = np.sqrt(sum(np.asarray(tab[f"prior_{a}_arcsec"], dtype=float) ** 2 for a in "xyz"))
        ax.plot(t[resumed], mag[resumed], "k^", ms=4, label="|error| at slew end")
    ax.set_xlabel("time since the first sample [s]")
    ax.set_ylabel("star tracker - prediction [arcsec]")
    ax.set_title("Attitude residuals (star-tracker axes); grey: slews without correction")
    ax.legend(loc="upper right", ncols=4, fontsize=8)
    ax.grid(alpha=0.3)
    return fig


def _fig_rates(result: TaskResult) -> Figure:
    tab = result.tables["rate_residuals"]
    fig = Figure(figsize=(9, 6.5), label="Rate residuals gyro - star tracker (000 figs. 7-8)")
    if len(tab["time_tai_ns"]) == 0:
        return fig
    t0 = int(tab["time_tai_ns"][0])
    t = (np.asarray(tab["time_tai_ns"]) - t0) / NS_PER_S
    ax1, ax2 = fig.subplots(2, 1)
    for i, a in enumerate("xyz"):
        ax1.plot(t, tab[f"residual_{a}_arcsec_s"], ".", ms=1, color=_COLOURS[i], label=f"axis {a}")
    ax1.set_ylabel("w_g - w_a [arcsec/s]")
    ax1.set_title("Calibrated gyro rate minus star-tracker rate in the alignment windows (star-tracker axes)")
    ax1.legend(loc="upper right", ncols=3, fontsize=8, markerscale=6)
    ax1.grid(alpha=0.3)
    first = t <= t[0] + 60.0  # a fragment, like 000 fig. 8; lines broken between windows
    tf = t[first]
    gap = np.concatenate([np.diff(tf) > 1.0, [False]])
    for i, a in enumerate("xyz"):
        y = np.asarray(tab[f"residual_{a}_arcsec_s"], dtype=float)[first]
        ax2.plot(np.insert(tf, np.flatnonzero(gap) + 1, np.nan), np.insert(y, np.flatnonzero(gap) + 1, np.nan), "-",
                 lw=0.8, color=_COLOURS[i])
    ax2.set_xlabel("time since the first window sample [s]")
    ax2.set_ylabel("w_g - w_a [arcsec/s]")
    ax2.set_title("Fragment: the first minute")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def _fig_coverage(result: TaskResult) -> Figure:
    tab = result.tables["rate_coverage"]
    fig = Figure(figsize=(7, 5.5), label="Rate-direction coverage of the alignment windows")
    ax = fig.add_subplot()
    x, y, z = (np.asarray(tab[f"direction_{a}"], dtype=float) for a in "xyz")
    lon = np.degrees(np.arctan2(y, x))
    lat = np.degrees(np.arcsin(np.clip(z, -1.0, 1.0)))
    used = np.asarray(tab["used"], dtype=bool)
    sc = ax.scatter(lon[used], lat[used], c=np.asarray(tab["mean_rate_deg_s"], dtype=float)[used], cmap="viridis",
                    s=18)
    anti_lon = np.where(lon[used] > 0, lon[used] - 180.0, lon[used] + 180.0)  # -w: the same rotation axis
    ax.scatter(anti_lon, -lat[used], facecolors="none", edgecolors="0.6", s=18)
    if np.any(~used):
        ax.scatter(lon[~used], lat[~used], marker="x", color="tab:red", s=18, label="rejected (fit residual)")
        ax.legend(loc="lower right", fontsize=8)
    fig.colorbar(sc, ax=ax, label="mean |w| in the window [deg/s]")
    ax.set_xlim(-180, 180)
    ax.set_ylim(-90, 90)
    ax.set_xlabel("azimuth of w in star-tracker axes (atan2(y, x)) [deg]")
    ax.set_ylabel("elevation above the x-y plane [deg]")
    ev = result.summary["rate_spread_eigenvalues"]
    obs = result.summary["misalignment_observable"]
    ax.set_title(f"Rate directions; spread eigenvalues {', '.join(f'{v:.2f}' for v in ev)}; observable {obs}",
                 fontsize=9)
    ax.grid(alpha=0.3)
    return fig


def figures(result: TaskResult, params: Params) -> dict[str, Figure]:
    return {
        "drift": _fig_drift(result),
        "attitude_residuals": _fig_attitude(result),
        "rate_residuals": _fig_rates(result),
        "rate_coverage": _fig_coverage(result),
    }


JOB = JobType(
    name="alignment_calibration",
    title="In-flight gyro calibration and alignment against a star tracker",
    paper="000",
    params=Params,
    run=run,
    streams=("star_tracker",),
    optional_streams=("gyro_increments", "gyro"),
    figures=figures,
    produces_calibration="gyro",
    description=(
        "Gyro drift, gyro-to-star-tracker misalignment and scale-factor error from flight data (000): two-pass "
        "filtering of the gyro increments, a nonlinear Luenberger drift observer that is switched off during fast "
        "slews (drift predicted from its trend), QUEST alignment and scale factor from gyro vs star-tracker rates in "
        "12-18 s windows of slow motion, iterated until the change is below noise. What the rate history does not "
        "determine (information matrix of misalignment, scale factor and drift) is reported as null with a "
        "not_observable warning."
    ),
    headline=(Answer("misalignment_rad", "Gyro-to-star-tracker misalignment (rotation vector of q_GS)",
                     sigma="misalignment_sigma_rad", frame="gyro G relative to star tracker {sensor} (S)"),
              Answer("scale_factor_error", "Gyro scale-factor error m", sigma="scale_factor_error_sigma", unit="ppm",
                     scale=1e6),
              Answer("drift_rad_s", "Gyro drift b at the end of the window", sigma="drift_sigma_rad_s",
                     frame="gyro (G)")),
)
