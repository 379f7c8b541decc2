"""Job ``star_tracker_accuracy`` (paper 003 §1.3-1.5): accuracy of a star tracker from flight data.

Thin layer over :func:`processing.star_tracker.accuracy.analyze_star_tracker_accuracy`: picks the
sensor and its mounting from the configuration, the gyro stream when present, converts radians to
arcseconds at the edge and draws the report figures in the spirit of 003 figures 1-5. Its statements
about itself (issue 17) are warnings: ``outliers_removed``, ``correlated_residuals``, ``implausible_input``
(a gyro line the star tracker does not see), and those of the star-tracker-against-gyro plausibility
check (app.jobs.plausibility.check_heads) when gyro data are used.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from app.jobs import multi_head
from app.jobs.partitions import map_partitions
from app.jobs.plausibility import check_heads
from app.jobs.registry import JobType
from app.jobs.types.star_tracker_accuracy_figures import figure_names, figures
from app.reports.headline import Answer
from processing.star_tracker.accuracy import (
    StarTrackerAccuracy,
    StarTrackerAccuracyError,
    analyze_star_tracker_accuracy,
)
from processing.star_tracker.gyro_coverage import GYRO_MIN_RATE_RATIO, GYRO_SAMPLES_PER_PARAMETER
from processing.star_tracker.multi_head import HeadSeries, MultiHeadSettings
from processing.tasks import Progress, ResultWarning, TaskError, TaskInputs, TaskResult
from processing.units import ARCSEC_PER_RAD

MAX_GYRO_TABLE_ROWS = 20_000
"""The gyro comparison table is decimated (every k-th sample) to at most this many rows."""
SUMMARY_OUTLIERS = 5
"""The summary lists at most this many outliers (the largest); the ``outliers`` table has them all."""
SUMMARY_GYRO_SEGMENTS = 5
"""gyro_coverage.not_used lists at most this many segments without gyro (n_failed counts them all)."""


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    sensor: str | None = Field(
        None, description="star tracker name; default: the only one configured, else the only one in the data")
    harmonics: Literal["auto"] | Annotated[int, Field(ge=0)] = Field(
        "auto", description="sine harmonics M of the 003 §1.3 smoother, or 'auto' (2 x the GCV choice)")
    use_gyro: bool = Field(True, description="use gyro rates (comparison, lines, removal of real motion)")
    heads: list[str] = Field(default_factory=list, max_length=16, description=(
        "multi-head mode: two or more star-tracker heads (or ['all'] for every head in the window) compared "
        "through their relative attitude: per-head, per-axis noise without a motion model, inter-boresight angle"))
    identical_heads: bool = Field(False, description=(
        "multi-head mode: the heads have the same per-axis noise (two heads determine it only so; tested by "
        "chi-square)"))
    max_interpolation_s: float = Field(0.0, ge=0.0, le=60.0, description=(
        "multi-head mode: a head is interpolated to the other's sample times across gaps up to this long "
        "(0: simultaneous samples only)"))


def _as_list(values: Any, scale: float = 1.0) -> list[float | None]:
    return [float(v) * scale if np.isfinite(v) else None for v in np.asarray(values, dtype=float).ravel()]


def _pick_sensor(inputs: TaskInputs, requested: str | None) -> tuple[str, np.ndarray]:
    configured = inputs.spacecraft.star_tracker_names
    present = inputs.sensors("star_tracker")
    if not present:
        raise TaskError("no star_tracker samples in the job window")
    if requested is not None:
        sensor = requested
    elif len(configured) == 1:
        sensor = configured[0]
    elif len(present) == 1:
        sensor = present[0]
    else:
        raise TaskError(
            f"params.sensor is required: the star tracker is ambiguous (configured: {sorted(configured) or 'none'}, "
            f"in the data: {list(present)})"
        )
    return sensor, inputs.spacecraft.star_tracker_mounting(sensor)


def _gyro(inputs: TaskInputs, notes: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    sensors = inputs.sensors("gyro")
    if not sensors:
        notes.append("no gyro samples in the window: real motion not separated from sensor noise")
        return None
    if len(sensors) > 1:
        notes.append(f"several gyro sensors {list(sensors)}: used {sensors[0]!r}")
    g = inputs.gyro(sensors[0])
    keep = np.concatenate([[True], np.diff(g.time_tai_ns) > 0])
    if np.all(keep):  # the usual case: no copy of a long window's rates
        return g.time_tai_ns, g.w_G_rad_s, inputs.spacecraft.gyro_mounting()
    return g.time_tai_ns[keep], g.w_G_rad_s[keep], inputs.spacecraft.gyro_mounting()


def _line_entry(line: Any) -> dict[str, Any]:
    return {
        "source": line.source,
        "axis": line.axis,
        "freq_hz": float(line.freq_hz),
        "amplitude_arcsec_s": None if line.amplitude_rad_s is None else float(line.amplitude_rad_s * ARCSEC_PER_RAD),
        "attitude_amplitude_arcsec": float(line.attitude_amplitude_rad * ARCSEC_PER_RAD),
        "attitude_rms_arcsec": float(line.attitude_rms_rad * ARCSEC_PER_RAD),
        "aliased_freq_hz": float(line.aliased_freq_hz),
        "removed": bool(line.removed),
    }


def _summary(r: StarTrackerAccuracy, sensor: str, params: Params, gyro_used: bool) -> dict[str, Any]:
    harmonics = r.harmonics
    used = int(np.count_nonzero(r.segment >= 0))
    summary: dict[str, Any] = {
        "sensor": sensor,
        "sigma_arcsec": _as_list(r.sigma_rad, ARCSEC_PER_RAD),
        "sigma_smoothing_arcsec": _as_list(r.sigma_smoothing_rad, ARCSEC_PER_RAD),
        "sigma_robust_arcsec": _as_list(r.sigma_robust_rad, ARCSEC_PER_RAD),
        "sigma_smoothing_robust_arcsec": _as_list(r.sigma_smoothing_robust_rad, ARCSEC_PER_RAD),
        "sigma_eq2_arcsec": _as_list(r.sigma_eq2_rad, ARCSEC_PER_RAD),
        "motion_rms_arcsec": _as_list(r.motion_rms_rad, ARCSEC_PER_RAD),
        "axes": ["x1", "x2", "x3"],
        "harmonics": int(round(float(np.median(harmonics)))),
        "harmonics_per_segment": [int(m) for m in harmonics],
        "harmonics_mode": "auto" if params.harmonics == "auto" else "manual",
        "cutoff_hz": float(max(s.cutoff_hz for s in r.segments)),
        "n_samples": used,
        "n_segments": len(r.segments),
        "sample_period_s": float(r.sample_period_s),
        "gyro_used": gyro_used,
        "spectral_lines": [_line_entry(line) for line in r.lines],
    }
    summary.update(_robustness_summary(r))
    if r.gyro_coverage:
        summary["gyro_coverage"] = _coverage_summary(r)
    if r.gyro is not None:
        g = r.gyro
        summary.update(
            gyro_rate_rms_diff_arcsec_s=_as_list(g.rms_diff_rad_s, ARCSEC_PER_RAD),
            gyro_rate_rms_diff_expected_arcsec_s=_as_list(g.expected_rms_diff_rad_s, ARCSEC_PER_RAD),
            gyro_offset_arcsec_s=_as_list(g.offset_rad_s, ARCSEC_PER_RAD),
            gyro_noise_sigma_arcsec_s=_as_list(g.noise_sigma_rad_s, ARCSEC_PER_RAD),
            gyro_smoothing_sigma_arcsec_s=_as_list(g.smoothing_sigma_rad_s, ARCSEC_PER_RAD),
            gyro_axes=["y1", "y2", "y3"],
        )
    return summary


def _coverage_summary(r: StarTrackerAccuracy) -> dict[str, Any]:
    """Segments with and without gyro, the failed criteria counted, their thresholds, the first few
    segments without gyro with the measured value (processing.star_tracker.gyro_coverage)."""
    cov = r.gyro_coverage
    unused = [c for c in cov if not c.used]
    return {
        "n_segments": len(cov),
        "n_used": len(cov) - len(unused),
        "n_failed": {k: sum(c.criterion == k for c in unused) for k in ("rate", "samples")},
        "thresholds": {"min_rate_ratio": GYRO_MIN_RATE_RATIO, "samples_per_parameter": GYRO_SAMPLES_PER_PARAMETER},
        "longest_gyro_gap_s": max(c.longest_gap_s for c in cov),
        "not_used": [{"rows": [c.start, c.stop - 1], "criterion": c.criterion, "value": c.value,
                      "threshold": c.threshold, "longest_gap_s": c.longest_gap_s, "reason": c.reason}
                     for c in unused[:SUMMARY_GYRO_SEGMENTS]],
    }


def _outlier_rows(r: StarTrackerAccuracy) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows of the outliers, their residuals (n, 3) and sizes (n,) in arcsec (raw residuals)."""
    idx = np.flatnonzero(r.outlier)
    e = r.residuals_smoothing_rad[idx] * ARCSEC_PER_RAD
    return idx, e, np.linalg.norm(e, axis=1)


def _robustness_summary(r: StarTrackerAccuracy) -> dict[str, Any]:
    """Outliers, whiteness, sigma above the cutoff, its lower bound and interval, gyro-line coherence."""
    a = ARCSEC_PER_RAD
    idx, e, size = _outlier_rows(r)
    largest = np.argsort(-size, kind="stable")[:SUMMARY_OUTLIERS]
    w = r.whiteness
    return {
        "n_outliers": int(idx.size),
        "outlier_threshold_sigma": float(r.outlier_threshold) if np.isfinite(r.outlier_threshold) else None,
        "outlier_scale_arcsec": _as_list(r.outlier_scale_rad, a),
        "outliers": [{"time_tai_ns": int(r.time_tai_ns[idx[k]]), "residual_arcsec": _as_list(e[k]),
                      "size_arcsec": float(size[k])} for k in largest],
        "sigma_ci95_arcsec": [_as_list(row, a) for row in r.sigma_ci95_rad],
        "sigma_dof": _as_list(r.sigma_dof),
        "sigma_above_cutoff_arcsec": _as_list(r.sigma_above_cutoff_rad, a),
        "sigma_lower_bound_arcsec": _as_list(r.sigma_lower_bound_rad, a),
        "whiteness_p_value": _as_list(w.p_value),
        "whiteness_power_ratio": _as_list(w.ratio),
        "residuals_white": (not w.correlated) if w.tested else None,
        "gyro_lines": [{"freq_hz": c.freq_hz, "beta": c.beta, "beta_sigma": c.beta_sigma, "removed": c.removed,
                        "gyro_only": c.gyro_only, "predicted_rms_arcsec": _as_list(c.predicted_rms_rad, a)}
                       for c in r.line_coherence],
    }


def _warnings(r: StarTrackerAccuracy, summary: dict[str, Any]) -> list[ResultWarning]:
    """outliers_removed, correlated_residuals and implausible_input (gyro-only lines)."""
    out: list[ResultWarning] = []
    a = ARCSEC_PER_RAD
    n = summary["n_outliers"]
    if n:
        idx, _, size = _outlier_rows(r)
        out.append(ResultWarning(
            "outliers_removed",
            f"{n} of {summary['n_samples']} star-tracker samples rejected as outliers (residual beyond "
            f"{r.outlier_threshold:.1f} robust sigma, largest {float(size.max()):.1f}\"): left out of every fit, "
            "sigma and spectrum; the 'outliers' table lists them. Check the sensor's validity flags for them.",
            {"n_outliers": n, "n_samples": summary["n_samples"],
             "threshold_sigma": float(r.outlier_threshold), "largest_arcsec": float(size.max()),
             "first_time_tai_ns": int(r.time_tai_ns[idx[0]])},
        ))
    w = r.whiteness
    if w.correlated:
        axes = [f"x{i + 1}" for i in range(3) if w.p_value[i] < w.alpha / 3.0]
        sig = summary["sigma_arcsec"]
        above = summary["sigma_above_cutoff_arcsec"]
        lower = summary["sigma_lower_bound_arcsec"]
        out.append(ResultWarning(
            "correlated_residuals",
            f"the star-tracker residuals are not white about {', '.join(axes)}: above the smoother cutoff "
            f"({summary['cutoff_hz']:.4f} Hz) their power rises towards the cutoff (lower/upper half-band ratio "
            f"{', '.join(f'{x:.2f}' for x in w.ratio)}; white noise gives 1). Time-correlated noise below the "
            "cutoff is absorbed by the harmonics together with the motion, so sigma_arcsec "
            f"({', '.join(f'{x:.2f}' for x in sig)}\") is a lower bound: the noise above the cutoff alone is "
            f"{', '.join(f'{x:.2f}' for x in above)}\", the lower band's level continued below the cutoff gives "
            f"at least {', '.join(f'{x:.2f}' for x in lower)}\", and the true sigma may be several times larger "
            "(these data cannot tell: fewer harmonics, a longer arc with known motion or the sensor's noise "
            "model would). The intervals use the effective degrees of freedom.",
            {"p_value": _as_list(w.p_value), "power_ratio": _as_list(w.ratio), "alpha": w.alpha,
             "band_hz": list(w.band_hz), "sigma_above_cutoff_arcsec": above, "sigma_lower_bound_arcsec": lower,
             "dof_effective": _as_list(r.sigma_dof)},
        ))
    for c in r.line_coherence:
        if c.gyro_only:
            out.append(ResultWarning(
                "implausible_input",
                f"the gyro line at {c.freq_hz:.4f} Hz is not in the star-tracker measurements (coherence beta = "
                f"{c.beta:.2f} +- {c.beta_sigma:.2f}; real attitude motion gives 1; predicted oscillation "
                f"{', '.join(f'{x * a:.2f}' for x in c.predicted_rms_rad)}\" rms about x1 x2 x3): it is in the gyro "
                "only (a vibration of the gyro or its mounting, or an electronic tone) and was not removed from "
                "the star tracker.",
                {"freq_hz": c.freq_hz, "beta": c.beta, "beta_sigma": c.beta_sigma,
                 "predicted_rms_arcsec": _as_list(c.predicted_rms_rad, a)},
            ))
    return out


def _plausibility(sensor: str, t: np.ndarray, q: np.ndarray, q_BS: np.ndarray,
                  gyro: tuple[np.ndarray, np.ndarray, np.ndarray], notes: list[str]) -> tuple[dict[str, Any],
                                                                                            list[ResultWarning]]:
    """The star tracker checked against the gyro (app.jobs.plausibility.check_heads)."""
    return check_heads([HeadSeries(sensor, t, q, np.asarray(q_BS, dtype=np.float64))], gyro[0], gyro[1],
                       np.asarray(gyro[2], dtype=np.float64), notes)


def _tables(r: StarTrackerAccuracy) -> dict[str, dict[str, np.ndarray]]:
    rows = r.segment >= 0
    a = ARCSEC_PER_RAD
    res: dict[str, np.ndarray] = {"time_tai_ns": r.time_tai_ns[rows], "segment": r.segment[rows]}
    for i in range(3):
        res[f"e{i + 1}_arcsec"] = r.residuals_smoothing_rad[rows, i] * a
    for i in range(3):
        res[f"e{i + 1}_corrected_arcsec"] = r.residuals_rad[rows, i] * a
        res[f"e{i + 1}_eq2_arcsec"] = r.residuals_eq2_rad[rows, i] * a
        res[f"motion{i + 1}_arcsec"] = r.motion_rad[rows, i] * a
    for i in range(3):
        res[f"z{i + 1}"] = r.z[rows, i]
        res[f"z{i + 1}_fit"] = r.z_fit[rows, i]
    rates: dict[str, np.ndarray] = {"time_tai_ns": r.time_tai_ns[rows]}
    for i in range(3):
        rates[f"w{i + 1}_B_arcsec_s"] = r.w_B_rad_s[rows, i] * a
    for i in range(3):
        rates[f"w{i + 1}_S_arcsec_s"] = r.w_S_rad_s[rows, i] * a
    tables = {"residuals": res, "rates": rates}
    idx, e_out, size = _outlier_rows(r)
    tables["outliers"] = {"time_tai_ns": r.time_tai_ns[idx], **{f"e{i + 1}_arcsec": e_out[:, i] for i in range(3)},
                          "size_arcsec": size}
    if r.gyro is not None:
        step = max(1, int(np.ceil(r.gyro.time_tai_ns.size / MAX_GYRO_TABLE_ROWS)))
        g = {"time_tai_ns": r.gyro.time_tai_ns[::step]}
        for i in range(3):
            g[f"w{i + 1}_B_star_tracker_arcsec_s"] = r.gyro.w_B_star_tracker_rad_s[::step, i] * a
            g[f"w{i + 1}_B_gyro_arcsec_s"] = r.gyro.w_B_gyro_rad_s[::step, i] * a
        tables["gyro_comparison"] = g
    names = {"gyro": "arcsec_s", "star_tracker_rate": "arcsec_s", "star_tracker_residuals": "arcsec"}
    for name, spec in r.spectra.items():
        amp = spec.amplitude.reshape(spec.freq_hz.size, -1) * a
        tables[f"spectrum_{name}"] = {
            "freq_hz": spec.freq_hz, **{f"a{i + 1}_{names[name]}": amp[:, i] for i in range(amp.shape[1])}
        }
    seg = r.segments
    tables["segments"] = {
        "time_tai_ns": np.array([r.time_tai_ns[s.start] for s in seg], dtype=np.int64),
        "end_tai_ns": np.array([r.time_tai_ns[s.stop - 1] for s in seg], dtype=np.int64),
        "n_samples": np.array([s.stop - s.start for s in seg], dtype=np.int64),
        "harmonics": np.array([s.harmonics for s in seg], dtype=np.int64),
        "cutoff_hz": np.array([s.cutoff_hz for s in seg]),
        "dof": np.array([s.dof for s in seg], dtype=np.int64),
        **{f"sigma{i + 1}_arcsec": np.array([np.sqrt(s.rss_rad2[i] / s.dof) * a if s.dof > 0 else np.nan
                                              for s in seg]) for i in range(3)},
    }
    return tables


def segment_map(func: Callable[[Any], Any], parts: Sequence[Any]) -> list[Any]:
    """The per-segment smoothings split across the executor's workers (app.jobs.partitions)."""
    return map_partitions(func, parts, stage="segments")


def input_streams(params: Params) -> tuple[str, ...]:
    """The streams a run reads: the gyro only with use_gyro (the runner does not load it otherwise)."""
    return ("star_tracker", "gyro") if params.use_gyro else ("star_tracker",)


def run(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    progress(0.02, "loading")
    heads = multi_head.head_names(inputs, params.heads) if params.heads else []
    sensor, q_BS = _pick_sensor(inputs, params.sensor if params.sensor or not heads else heads[0])
    st = inputs.star_tracker(sensor)
    t, q = st.time_tai_ns, st.q_IS
    keep = np.concatenate([[True], np.diff(t) > 0])
    notes: list[str] = []
    if not np.all(keep):
        notes.append(f"{int(np.sum(~keep))} star-tracker samples with repeated times dropped")
    gyro = _gyro(inputs, notes) if params.use_gyro else None
    if not params.use_gyro:
        notes.append("use_gyro = false: real motion not separated from sensor noise")
    try:
        result = analyze_star_tracker_accuracy(
            t[keep], q[keep], q_BS,
            gyro_time_tai_ns=None if gyro is None else gyro[0],
            w_G_rad_s=None if gyro is None else gyro[1],
            q_BG=(1.0, 0.0, 0.0, 0.0) if gyro is None else gyro[2],
            harmonics=None if params.harmonics == "auto" else int(params.harmonics),
            progress=lambda f, stage: progress(0.05 + 0.85 * f, stage),
            mapper=segment_map,
        )
    except StarTrackerAccuracyError as exc:
        raise TaskError(str(exc)) from exc
    progress(0.95, "summary")
    notes += list(result.notes)
    notes.append(
        "sigma_arcsec: residual std about the sensor axes (outliers left out) after removing the attitude "
        "oscillation of the gyro lines above the smoother cutoff that the star tracker also sees; "
        "sigma_smoothing_arcsec: the 003 §1.4 figure with that motion in; residuals are exact small rotations "
        "about x1 x2 x3 (sigma_eq2_arcsec: 003 eq. 2 literally)"
    )
    summary = _summary(result, sensor, params, result.gyro is not None)
    warnings: list[ResultWarning] = []
    if gyro is not None:
        summary["plausibility"], warnings = _plausibility(sensor, t[keep], q[keep], q_BS, gyro, notes)
    tables = _tables(result)
    if heads:
        progress(0.96, "multi-head comparison")
        mh = multi_head.run_multi_head(inputs, heads, MultiHeadSettings(
            identical_heads=params.identical_heads, max_interpolation_s=params.max_interpolation_s))
        summary["multi_head"] = mh.summary
        tables.update(mh.tables)
        warnings += mh.warnings
        notes.append(f"multi-head mode: heads {heads} compared through their relative attitude (summary.multi_head); "
                     f"the single-head 003 analysis above is of {sensor}")
    return TaskResult(
        summary=summary,
        tables=tables,
        notes=notes,
        warnings=warnings + _warnings(result, summary),
    )


JOB = JobType(
    applies_calibration="gyro",
    name="star_tracker_accuracy",
    title="Star-tracker accuracy from flight data",
    paper="003 §1",
    params=Params,
    run=run,
    streams=("star_tracker",),
    optional_streams=("gyro",),
    input_streams=input_streams,
    figures=figures, figure_names=figure_names,
    description=(
        "Per-axis accuracy of a star tracker from its quaternions (003 §1.3-1.5): mean quaternion, Rodrigues "
        "parameters smoothed by a sine series plus linear trend, residual std about the sensor axes; with gyro "
        "data the real high-frequency motion (spectral lines) is removed, the rates are compared and the spectra "
        "show where lines alias into the star-tracker samples."
    ),
    headline=(Answer("sigma_arcsec", "Star-tracker accuracy: 1σ noise per sensor axis (003 §1)", components="axes",
                     frame="star tracker {sensor} (S)"),),
)
