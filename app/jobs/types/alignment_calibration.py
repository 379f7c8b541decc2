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

This module runs the calibration; the summary, warnings and tables are made in
:mod:`app.jobs.types.alignment_calibration_summary`, the figures in :mod:`app.jobs.types.alignment_calibration_figures`.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, model_validator

from app.jobs.plausibility import check_heads
from app.jobs.registry import JobType, always
from app.jobs.types.alignment_calibration_figures import figures
from app.jobs.types.alignment_calibration_summary import (
    CalibrationRun,
    calibration_notes,
    calibration_summary,
    calibration_tables,
    observability_warnings,
)
from app.reports.headline import Answer
from processing.attitude import rotations
from processing.gyro_calibration.calibration import CalibrationSettings, calibrate_gyro
from processing.signal.two_pass_filter import increments_from_rates
from processing.star_tracker.multi_head import HeadSeries
from processing.tasks import Progress, TaskError, TaskInputs, TaskResult
from processing.units import NS_PER_S, RAD_PER_ARCSEC, RAD_PER_DEG


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
    done = CalibrationRun(cal=cal, params=params, sensor=sensor, source=source, t0=t0, q_BS=q_BS, q_BG=q_BG,
                q_GS_nom=q_GS_nom, n_gyro=int(g_ns.size), n_st=int(st_ns.size),
                window_start_tai_ns=inputs.start_tai_ns, window_end_tai_ns=inputs.end_tai_ns)
    summary = calibration_summary(done)
    # mean rates over the increments at their midpoints (what the plausibility check takes)
    t_mid = g_ns - np.round(0.5 * np.asarray(interval) * NS_PER_S).astype(np.int64)
    w_mid = incr / np.asarray(interval, dtype=np.float64)[:, None]
    summary["plausibility"], plausible = check_heads([HeadSeries(sensor, st_ns, q_IS, q_BS)], t_mid, w_mid, q_BG,
                                                     notes)
    head = summary["plausibility"].get(sensor, {})
    summary["time_offset_s"] = head.get("time_offset_s")
    summary["time_offset_sigma_s"] = head.get("time_offset_sigma_s")
    warnings = plausible + observability_warnings(done)
    return TaskResult(summary=summary, tables=calibration_tables(cal, done.ns), notes=notes + calibration_notes(done),
                      warnings=warnings)


JOB = JobType(
    name="alignment_calibration",
    title="In-flight gyro calibration and alignment against a star tracker",
    paper="000",
    params=Params,
    run=run,
    streams=("star_tracker",),
    optional_streams=("gyro_increments", "gyro"),
    figures=figures, figure_names=always("drift", "attitude_residuals", "rate_residuals", "rate_coverage"),
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
