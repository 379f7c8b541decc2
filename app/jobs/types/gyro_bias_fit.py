"""Job ``gyro_bias_fit``: gyro offsets and attitude by Gauss-Newton with variational equations (003 §2).

Wraps :func:`processing.gyro_calibration.bias_fit.fit_gyro_bias`: loads the star-tracker and gyro samples of the
window, works in the reference star tracker's frame (003 §2.4), fits the whole segment and its
sub-intervals, and reports the offsets in the sensor frame (the paper's Delta, arcsec/s) and in the body
frame as a gyro bias (w_meas = w_true + b, rad/s), each with the honest sigma (gyro noise included) and
the paper's sigma_w² C^-1 figure (``*_sigma_paper``). Figures follow 003 figs. 13-16.

Before the fit every tracker's quaternions are checked against the gyro
(:func:`processing.star_tracker.plausibility.check_star_tracker_gyro`, through :func:`app.jobs.plausibility.checked`
which shares the result with star_tracker_accuracy on equal inputs: the quaternion convention and the time-tag
offset); ``fit_time_offset`` corrects the gyro times by the reference tracker's offset. After it the
constancy of the offsets across the finest split of ``subintervals`` is tested
(:func:`processing.gyro_calibration.subintervals.offset_constancy`) and, when it fails, the reported sigma
carries the offsets' variation within the window (``bias_not_constant``).

This module runs the fit; its summary, warnings and tables are made in
:mod:`app.jobs.types.gyro_bias_fit_summary`, its figures in :mod:`app.jobs.types.gyro_bias_fit_figures`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Annotated, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, PositiveFloat

from app.jobs.plausibility import checked
from app.jobs.registry import JobType, always
from app.jobs.types.gyro_bias_fit_figures import figures
from app.jobs.types.gyro_bias_fit_summary import (
    Outcome,
    Window,
    combine_segments,
    fit_summary,
    fit_warnings,
    series_tables,
    subinterval_rows,
    subinterval_table,
)
from app.reports.headline import Answer
from app.services.times import iso
from processing.attitude import rotations
from processing.gyro_calibration.bias_fit import (
    GyroBiasFit,
    GyroBiasFitError,
    estimate_gyro_arw,
    fit_gyro_bias,
)
from processing.gyro_calibration.subintervals import (
    fit_subintervals,
    offset_constancy,
    subinterval_edges,
)
from processing.signal.sine_series import SineSeriesError, fit_sine_series, select_harmonics
from processing.star_tracker.plausibility import PlausibilityError, PlausibilityResult
from processing.tasks import Progress, TaskError, TaskInputs, TaskResult
from processing.units import NS_PER_S, RAD_PER_ARCSEC

MAX_SMOOTHING_HARMONICS = 400
"""Upper end of the harmonic-count search when use_smoothed_rates and smoothing_harmonics is None."""


MAX_SLIDING_WINDOWS = 2000  # sub-interval fits of sliding windows per job


class Params(BaseModel):
    """Parameters of ``gyro_bias_fit`` (003 §2.1-2.4)."""

    model_config = ConfigDict(extra="forbid")

    sensor: str | list[str] | None = Field(
        None,
        description="Star tracker(s). One name: that tracker; a list: fitted jointly, the first is the "
        "reference frame; None: every configured tracker with data, jointly.",
    )
    scheme: Literal[1, 2] = Field(2, description="003 §2.3 difference scheme: 1 trapezoid, 2 midpoint (|q| = 1).")
    use_smoothed_rates: bool = Field(
        False,
        description="Integrate the sine-series approximation omega_ap of the rates (003 §2.1), not the samples.",
    )
    smoothing_harmonics: int | None = Field(
        None, ge=0, description="Harmonics M of omega_ap; None: chosen by generalised cross-validation."
    )
    weights: tuple[PositiveFloat, PositiveFloat, PositiveFloat] = Field(
        (1.0, 1.0, 0.2), description="Weights w1, w2, w3 of 003 eq. 6 (sensor axes; x3 = boresight)."
    )
    estimate_mounting: bool = Field(False, description="Also estimate the gyro-to-star-tracker mounting (3 angles).")
    mounting_sigma_max_arcsec: PositiveFloat = Field(
        60.0, description="The mounting is reported only when every component's sigma is below this."
    )
    subintervals: list[Annotated[int, Field(ge=1, le=64)]] = Field(
        [2, 4], max_length=8,
        description="Each n cuts the segment into n equal parts fitted separately (003 §2.4: 2, 4).")
    sliding_window_s: PositiveFloat | None = Field(None, description="Also fit sliding windows of this length.")
    sliding_step_s: PositiveFloat | None = Field(None, description="Step of the sliding windows (default: half).")
    gyro_arw_rad_sqrt_s: float | tuple[float, float, float] | None = Field(
        None, description="Gyro angle random walk per gyro axis, rad/sqrt(s); None: estimated from the rates."
    )
    max_gyro_gap_s: PositiveFloat = Field(5.0, description="Longest gyro gap bridged by interpolation.")
    split_at_gyro_gaps: bool = Field(
        True, description="At longer gyro gaps split the arc and fit each segment on its own; report the segments "
        "and their combined (inverse-variance) offsets. False: such a gap is an error.")
    min_segment_s: PositiveFloat = Field(60.0, description="Segments shorter than this (between gaps) are skipped.")
    max_iterations: int = Field(20, ge=1, le=200)
    fit_time_offset: bool = Field(
        False,
        description="Correct the gyro times by the star-tracker time-tag offset estimated against the gyro "
        "(the reference tracker's time_offset_s) before the fit; only when the offset is determined.",
    )
    max_time_offset_s: float = Field(1.0, gt=0, le=10, description="The time offset is searched within ±this.")


def _choose_sensors(inputs: TaskInputs, params: Params) -> tuple[list[str], dict[str, NDArray[np.float64]]]:
    spacecraft = inputs.spacecraft
    configured = spacecraft.star_tracker_names
    present = list(inputs.sensors("star_tracker"))
    if not present:
        raise TaskError("no star_tracker samples in the job window")
    if params.sensor is None:
        names = [name for name in configured if name in present]
        if not names:
            raise TaskError(
                f"no configured star tracker has data in the window (configured: {sorted(configured)}, "
                f"present: {present})"
            )
    else:
        names = [params.sensor] if isinstance(params.sensor, str) else list(params.sensor)
        if not names or len(set(names)) != len(names):
            raise TaskError(f"sensor must name distinct star trackers, got {params.sensor!r}")
        for name in names:
            spacecraft.star_tracker_mounting(name)  # MissingMountingError naming it
            if name not in present:
                raise TaskError(f"no star_tracker samples of sensor {name!r} in the window (present: {present})")
    return names, {name: spacecraft.star_tracker_mounting(name) for name in names}


def _gyro(inputs: TaskInputs, params: Params, notes: list[str]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    names = inputs.sensors("gyro")
    if len(names) > 1:
        raise TaskError(f"the window holds several gyro sensors ({list(names)}); one gyro triad is expected")
    g = inputs.gyro()
    t, w = g.time_tai_ns, g.w_G_rad_s
    if t.size < 8:
        raise TaskError(f"need at least 8 gyro samples, got {t.size}")
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise TaskError(f"gyro times must be distinct; {int(np.sum(dt <= 0))} repeated time stamps")
    if not np.all(np.isfinite(w)):
        raise TaskError("gyro rates must be finite")
    step = float(np.median(dt)) / NS_PER_S
    gaps = dt / NS_PER_S > 2.5 * step
    if np.any(gaps):
        longest = float(dt.max()) / NS_PER_S
        if longest > params.max_gyro_gap_s:
            raise TaskError(
                f"gyro gap of {longest:.3g} s exceeds max_gyro_gap_s = {params.max_gyro_gap_s} s; "
                "split the window at the gap (split_at_gyro_gaps does it)"
            )
        notes.append(f"{int(np.sum(gaps))} gyro gaps (longest {longest:.3g} s) bridged by linear interpolation")
    return t, w


def _window(inputs: TaskInputs, params: Params, notes: list[str]) -> Window:
    names, q_BS = _choose_sensors(inputs, params)
    q_BG = inputs.spacecraft.gyro_mounting()
    t_g_ns, w_G = _gyro(inputs, params, notes)
    views = [inputs.star_tracker(name) for name in sorted(names)]  # stored order: (sensor, time)
    t_all = np.concatenate([v.time_tai_ns for v in views])
    keep = (t_all >= t_g_ns[0]) & (t_all <= t_g_ns[-1])
    if int(np.count_nonzero(~keep)):
        notes.append(f"{int(np.count_nonzero(~keep))} star-tracker samples outside the gyro time span were not used")
    t_st_ns = t_all[keep]
    q_IS = np.concatenate([v.q_IS for v in views])[keep]
    sensor_of = np.concatenate([np.full(len(v), v.sensor, dtype=object) for v in views])[keep]
    sensor_index = np.zeros(sensor_of.size, dtype=np.int64)
    for j, name in enumerate(names):
        sensor_index[sensor_of == name] = j
    if t_st_ns.size < 4:
        raise TaskError(f"need at least 4 star-tracker samples within the gyro span, got {t_st_ns.size}")
    q_SB_ref = rotations.quat_conjugate(q_BS[names[0]])
    q_RS = np.stack([rotations.quat_multiply(q_SB_ref, q_BS[s]) for s in names])[sensor_index]
    return Window(names=names, q_BG=q_BG, epoch=int(t_g_ns[0]), t_g_ns=t_g_ns, w_G=w_G, t_st_ns=t_st_ns,
                   q_IS=q_IS, sensor_of=sensor_of, sensor_index=sensor_index, q_RS=q_RS,
                   q_RG=rotations.quat_multiply(q_SB_ref, q_BG), q_BS=q_BS)


def _plausibility(win: Window, params: Params, notes: list[str]) -> dict[str, PlausibilityResult | str]:
    """Each tracker's quaternions against the gyro (convention, time offset); a message when it cannot run."""
    out: dict[str, PlausibilityResult | str] = {}
    for name in win.names:
        sel = win.sensor_of == name
        try:
            out[name] = checked(win.t_st_ns[sel], win.q_IS[sel], win.q_BS[name], win.t_g_ns, win.w_G, win.q_BG,
                                sensor=name, max_time_offset_s=params.max_time_offset_s)
        except PlausibilityError as exc:
            out[name] = str(exc)
            notes.append(f"{name}: star tracker not checked against the gyro: {exc}")
    return out


def _shift_gyro(win: Window, params: Params, plaus: dict[str, PlausibilityResult | str],
                notes: list[str]) -> tuple[Window, float | None]:
    """With fit_time_offset, the gyro times moved by the reference tracker's offset (tag + tau = gyro time):
    t_gyro -= tau, so that each star-tracker tag meets the gyro sample of its true time."""
    ref = plaus.get(win.names[0])
    if not params.fit_time_offset:
        return win, None
    if not isinstance(ref, PlausibilityResult) or ref.time_offset_s is None:
        notes.append("fit_time_offset: the time offset is not determined by these data; gyro times not corrected")
        return win, None
    if ref.convention != "as_given":
        notes.append(f"fit_time_offset: the quaternions fit the gyro only as {ref.convention}; gyro times not "
                     "corrected (re-upload them first)")
        return win, None
    tau = ref.time_offset_s
    t_g_ns = win.t_g_ns - int(round(tau * NS_PER_S))
    keep = (win.t_st_ns >= t_g_ns[0]) & (win.t_st_ns <= t_g_ns[-1])
    if np.count_nonzero(keep) < 4:
        raise TaskError("fit_time_offset: fewer than 4 star-tracker samples lie within the shifted gyro span")
    notes.append(f"gyro times corrected by the star-tracker time offset {1e3 * tau:.2f} ms (fit_time_offset)")
    shifted = replace(win, epoch=int(t_g_ns[0]), t_g_ns=t_g_ns, t_st_ns=win.t_st_ns[keep], q_IS=win.q_IS[keep],
                      sensor_of=win.sensor_of[keep], sensor_index=win.sensor_index[keep], q_RS=win.q_RS[keep])
    return shifted, tau


def _arw(win: Window, params: Params) -> tuple[NDArray[np.float64], str]:
    if params.gyro_arw_rad_sqrt_s is None:
        return estimate_gyro_arw(win.t_g, win.w_G), "estimated from the second differences of the gyro rates"
    arw = np.broadcast_to(np.asarray(params.gyro_arw_rad_sqrt_s, dtype=np.float64), (3,)).copy()
    if np.any(arw < 0):
        raise TaskError(f"gyro_arw_rad_sqrt_s must be >= 0, got {params.gyro_arw_rad_sqrt_s!r}")
    return arw, "given"


def _rates_to_fit(win: Window, params: Params, notes: list[str],
                  progress: Progress) -> tuple[NDArray[np.float64], int | None]:
    """The gyro samples, or with use_smoothed_rates their sine-series approximation omega_ap (003 §2.1)."""
    if not params.use_smoothed_rates:
        return win.w_G, None
    progress(0.05, "smoothing gyro rates (omega_ap)")
    t_g = win.t_g
    try:
        if params.smoothing_harmonics is None:
            harmonics, _ = select_harmonics(t_g, win.w_G, MAX_SMOOTHING_HARMONICS)
        else:
            harmonics = params.smoothing_harmonics
        w_fit = fit_sine_series(t_g, win.w_G, harmonics).evaluate(t_g)
    except SineSeriesError as exc:
        raise TaskError(f"smoothing the gyro rates failed: {exc}") from exc
    notes.append(
        f"rates smoothed by a sine series with M = {harmonics} harmonics (003 §2.1 omega_ap); the honest "
        "covariance treats the remaining low-frequency gyro noise as a random walk (approximate)"
    )
    return w_fit, harmonics


def _fit(win: Window, params: Params, w_fit: NDArray[np.float64], arw: NDArray[np.float64], notes: list[str],
         progress: Progress) -> tuple[GyroBiasFit, list[GyroBiasFit | None], NDArray[np.float64],
                                      list[tuple[str, int, int]]]:
    """The whole segment (003 §2.2), then its sub-intervals and sliding windows (003 §2.4)."""
    t_g, t_st = win.t_g, win.t_st
    if params.sliding_window_s is not None:  # bounded work: a tiny step over a long window is millions of fits
        span_s = float(t_st.max() - t_st.min())
        step_s = params.sliding_step_s or params.sliding_window_s / 2.0
        n_windows = max(0.0, (span_s - params.sliding_window_s) / step_s + 1.0)
        if n_windows > MAX_SLIDING_WINDOWS:
            raise TaskError(f"sliding windows of {params.sliding_window_s:g} s every {step_s:g} s make "
                            f"{n_windows:.0f} fits over {span_s:.0f} s; at most {MAX_SLIDING_WINDOWS}: "
                            "give a longer sliding_step_s")
    progress(0.1, "fitting the whole segment")
    try:
        fit = fit_gyro_bias(
            t_g, w_fit, t_st, win.q_IS, q_RS=win.q_RS, sensor_index=win.sensor_index, q_RG=win.q_RG,
            weights=params.weights, scheme=params.scheme, gyro_arw_rad_sqrt_s=arw,
            max_iterations=params.max_iterations, estimate_mounting=params.estimate_mounting,
            mounting_sigma_max_rad=params.mounting_sigma_max_arcsec * RAD_PER_ARCSEC,
        )
    except GyroBiasFitError as exc:
        raise TaskError(str(exc)) from exc
    if not fit.converged:
        notes.append(fit.status if fit.status.startswith("not converged") else f"Gauss-Newton {fit.status}")
    progress(0.5, "sub-intervals")
    try:
        edges = subinterval_edges(
            float(t_st.min()), float(t_st.max()), splits=params.subintervals,
            window_s=params.sliding_window_s, step_s=params.sliding_step_s,
        )
        subs = fit_subintervals(
            t_g, w_fit, t_st, win.q_IS, edges, q_RS=win.q_RS, sensor_index=win.sensor_index, q_RG=fit.q_RG,
            weights=params.weights, scheme=params.scheme, gyro_arw_rad_sqrt_s=arw,
            max_iterations=params.max_iterations,
        )
    except GyroBiasFitError as exc:
        raise TaskError(f"sub-interval fits: {exc}") from exc
    kinds = [("split", n, i) for n in params.subintervals for i in range(int(n))]
    kinds += [("window", 0, i) for i in range(edges.shape[0] - len(kinds))]
    skipped = sum(s is None for s in subs)
    if skipped:
        notes.append(f"{skipped} sub-intervals with fewer than 10 star-tracker samples were skipped")
    return fit, subs, edges, kinds


def run(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    """Fit gyro offsets and the initial attitude to star-tracker quaternions (003 §2.1-2.4); with gyro gaps
    beyond max_gyro_gap_s and split_at_gyro_gaps, per segment and combined (:func:`_run_segments`)."""
    segments = _gyro_segments(inputs, params) if params.split_at_gyro_gaps else []
    if len(segments) > 1:
        return _run_segments(inputs, params, progress, segments)
    return _run_one(inputs, params, progress)


def _gyro_segments(inputs: TaskInputs, params: Params) -> list[tuple[int, int]]:
    """[first, last] gyro times (tai_ns) of the runs between gyro gaps longer than max_gyro_gap_s (empty when
    there is no such gap or the gyro cannot be read: the single fit then reports the problem)."""
    try:
        names = inputs.sensors("gyro")
        if len(names) != 1:
            return []
        t = inputs.gyro().time_tai_ns
    except TaskError:
        return []
    if not np.all(t[1:] > t[:-1]):  # stored in time order: the sort of np.unique only when it is not
        t = np.unique(t)
    if t.size < 2:
        return []
    cut = np.flatnonzero(np.diff(t) > params.max_gyro_gap_s * NS_PER_S)
    if cut.size == 0:
        return []
    starts = np.concatenate([[0], cut + 1])
    ends = np.concatenate([cut, [t.size - 1]])
    return [(int(t[a]), int(t[b])) for a, b in zip(starts, ends, strict=True)]


def _restricted(inputs: TaskInputs, start_ns: int, end_ns: int) -> TaskInputs:
    streams = {}
    for name, cols in inputs.streams.items():
        tt = np.asarray(cols["time_tai_ns"], dtype=np.int64)
        m = (tt >= start_ns) & (tt <= end_ns)
        streams[name] = {k: np.asarray(v)[m] for k, v in cols.items()}
    return replace(inputs, streams=streams, start_tai_ns=start_ns, end_tai_ns=end_ns)


def _run_segments(inputs: TaskInputs, params: Params, progress: Progress,
                  segments: list[tuple[int, int]]) -> TaskResult:
    """The arc split at its gyro gaps: each segment fitted on its own (the whole job, sub-intervals included), the
    offsets combined by inverse variance per body axis, their agreement tested (chi-square over the segments;
    beyond p = 0.01 the combined sigma is inflated by sqrt(chi2 / dof) and ``bias_not_constant`` says so). The
    summary is that of the longest segment (attitude, residuals, tables, figures) with the combined offsets in
    gyro_bias_rad_s / gyro_bias_sigma_rad_s, ``segments`` (each one's offsets) and ``combined``."""

    notes: list[str] = []
    results: list[tuple[tuple[int, int], TaskResult]] = []
    one = params.model_copy(update={"split_at_gyro_gaps": False})
    for k, (a, b) in enumerate(segments):
        if (b - a) / NS_PER_S < params.min_segment_s:
            notes.append(f"gyro segment {k + 1} ({iso(a)} to {iso(b)}, {(b - a) / NS_PER_S:.3g} s) is shorter than "
                         f"min_segment_s = {params.min_segment_s:g} s: skipped")
            continue
        def seg_progress(f: float, st: str, k: int = k) -> None:
            progress((k + f) / len(segments), f"segment {k + 1}: {st}")

        try:
            res = _run_one(_restricted(inputs, a, b), one, seg_progress)
        except TaskError as exc:
            notes.append(f"gyro segment {k + 1} ({iso(a)} to {iso(b)}) not fitted: {exc}")
            continue
        results.append(((a, b), res))
    if not results:
        raise TaskError(f"the gyro gaps beyond max_gyro_gap_s = {params.max_gyro_gap_s:g} s leave no segment that "
                        "can be fitted: " + "; ".join(notes))
    return combine_segments(params, segments, results, notes)


def _run_one(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    """Fit gyro offsets and the initial attitude to star-tracker quaternions (003 §2.1-2.4)."""
    notes: list[str] = []
    progress(0.0, "loading")
    win = _window(inputs, params, notes)
    progress(0.02, "checking the star trackers against the gyro")
    plaus = _plausibility(win, params, notes)
    win, applied = _shift_gyro(win, params, plaus, notes)
    arw, arw_source = _arw(win, params)
    w_fit, harmonics = _rates_to_fit(win, params, notes, progress)
    fit, subs, edges, kinds = _fit(win, params, w_fit, arw, notes, progress)
    progress(0.9, "report")
    finest = max((int(n) for n in params.subintervals if int(n) >= 2), default=None)
    constancy = None if finest is None else offset_constancy(
        fit, [f for f, (kind, parts, _) in zip(subs, kinds, strict=True) if kind == "split" and parts == finest])
    outcome = Outcome(window=win, params=params, fit=fit, subs=subs, edges=edges, kinds=kinds, arw=arw,
                       arw_source=arw_source, w_ap=w_fit if params.use_smoothed_rates else None, harmonics=harmonics,
                       plausibility=plaus, time_offset_applied_s=applied, constancy=constancy)
    sub_rows = subinterval_rows(outcome)
    warnings = fit_warnings(outcome)
    summary = fit_summary(outcome, sub_rows, warnings)
    tables = {**series_tables(outcome), "subintervals": subinterval_table(sub_rows)}
    progress(1.0, "done")
    return TaskResult(summary=summary, tables=tables, notes=notes, warnings=warnings)


JOB = JobType(
    name="gyro_bias_fit",
    title="Gyro offsets and attitude from star tracker + gyro (Gauss-Newton)",
    paper="003 §2",
    params=Params,
    run=run,
    streams=("star_tracker", "gyro"),
    figures=figures, figure_names=always("rates", "residuals", "subintervals"),
    description=(
        "Integrates the gyro rates on their own grid (003 §2.3 schemes), fits the initial attitude and "
        "constant gyro offsets to the star-tracker quaternions by Gauss-Newton with the variational "
        "equations (003 §2.2, eqs. 5-7), and reports offsets in sensor and body frames with honest "
        "(gyro-noise) and paper sigmas, residuals per sensor axis, sub-interval offsets and, optionally, "
        "the mounting with an observability check."
    ),
    headline=(Answer("gyro_bias_rad_s", "Gyro bias b (w_meas = w + b)", sigma="gyro_bias_sigma_rad_s",
                     frame="body (B)"),
              Answer("star_tracker_sigma_arcsec", "Star-tracker noise 1σ", frame="star tracker {reference_sensor} (S)"),
              Answer("residual_rms_arcsec", "Fit residual rms", frame="star tracker {reference_sensor} (S)")),
)
