"""Job ``gyro_bias_fit``: gyro offsets and attitude by Gauss-Newton with variational equations (003 §2).

Wraps :func:`processing.gyro_calibration.bias_fit.fit_gyro_bias`: loads the star-tracker and gyro samples of the
window, works in the reference star tracker's frame (003 §2.4), fits the whole segment and its
sub-intervals, and reports the offsets in the sensor frame (the paper's Delta, arcsec/s) and in the body
frame as a gyro bias (w_meas = w_true + b, rad/s), each with the honest sigma (gyro noise included) and
the paper's sigma_w² C^-1 figure (``*_sigma_paper``). Figures follow 003 figs. 13-16.

Before the fit every tracker's quaternions are checked against the gyro
(:func:`processing.star_tracker.plausibility.check_star_tracker_gyro`: the quaternion convention and the
time-tag offset); ``fit_time_offset`` corrects the gyro times by the reference tracker's offset. After it the
constancy of the offsets across the finest split of ``subintervals`` is tested
(:func:`processing.gyro_calibration.subintervals.offset_constancy`) and, when it fails, the reported sigma
carries the offsets' variation within the window (``bias_not_constant``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Annotated, Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, PositiveFloat

from app.jobs.registry import JobType
from app.jobs.types.gyro_bias_fit_figures import figures
from app.reports.headline import Answer
from app.services.times import iso
from processing.attitude import rotations
from processing.gyro_calibration.bias_fit import (
    RESIDUAL_CONSISTENCY_MAX,
    GyroBiasFit,
    GyroBiasFitError,
    estimate_gyro_arw,
    fit_gyro_bias,
)
from processing.gyro_calibration.subintervals import (
    ConstancyTest,
    fit_subintervals,
    offset_constancy,
    subinterval_edges,
)
from processing.signal.sine_series import SineSeriesError, fit_sine_series, select_harmonics
from processing.star_tracker.plausibility import PlausibilityError, PlausibilityResult, check_star_tracker_gyro
from processing.tasks import Progress, ResultWarning, TaskError, TaskInputs, TaskResult
from processing.units import ARCSEC_PER_RAD, NS_PER_S, RAD_PER_ARCSEC, RAD_PER_DEG

RATES_TABLE_MAX_ROWS = 20_000
"""The "rates" table (figure 13a) keeps every k-th gyro sample so that it has at most this many rows."""
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


# ---------------------------------------------------------------------------------------------------


def _floats(x: Any) -> list[float]:
    return [float(v) for v in np.asarray(x, dtype=np.float64).reshape(-1)]




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


def _bias_body(fit: GyroBiasFit, q_BG: NDArray[np.float64], cov: NDArray[np.float64]) -> tuple[Any, Any]:
    """Body-frame bias b_B = -R(q_BR) Delta (w_meas = w_true + b) and its sigma from cov (3x3 of Delta)."""
    r_br = rotations.quat_to_dcm(rotations.quat_multiply(q_BG, rotations.quat_conjugate(fit.q_RG)))
    b = -r_br @ fit.delta_R_rad_s
    return b, np.sqrt(np.diag(r_br @ cov @ r_br.T))


@dataclass(frozen=True)
class _Window:
    """The window as the fit sees it: gyro rates on their grid and the star-tracker samples within
    the gyro span, times in s from ``epoch`` (the first gyro time), mountings relative to the
    reference tracker R (003 §2.4)."""

    names: list[str]
    q_BG: NDArray[np.float64]
    epoch: int
    t_g_ns: NDArray[np.int64]
    w_G: NDArray[np.float64]
    t_st_ns: NDArray[np.int64]
    q_IS: NDArray[np.float64]
    sensor_of: NDArray[Any]
    sensor_index: NDArray[np.int64]
    q_RS: NDArray[np.float64]
    q_RG: NDArray[np.float64]
    q_BS: dict[str, NDArray[np.float64]]

    @property
    def t_g(self) -> NDArray[np.float64]:
        return (self.t_g_ns - self.epoch).astype(np.float64) / NS_PER_S

    @property
    def t_st(self) -> NDArray[np.float64]:
        return (self.t_st_ns - self.epoch).astype(np.float64) / NS_PER_S


@dataclass(frozen=True)
class _Outcome:
    """Everything the report needs: the window, the fits (whole segment and sub-intervals with their
    edges, s from the epoch, and kinds), the gyro noise used and the rates fitted."""

    window: _Window
    params: Params
    fit: GyroBiasFit
    subs: list[GyroBiasFit | None]
    edges: NDArray[np.float64]
    kinds: list[tuple[str, int, int]]
    arw: NDArray[np.float64]
    arw_source: str
    w_ap: NDArray[np.float64] | None
    harmonics: int | None
    plausibility: dict[str, PlausibilityResult | str]
    time_offset_applied_s: float | None
    constancy: ConstancyTest | None

    @property
    def delta_covariance(self) -> NDArray[np.float64]:
        """Covariance of Delta to report (R axes): the fit's, plus the offsets' variation when they drift."""
        c = self.constancy
        return self.fit.covariance[3:6, 3:6] if c is None or c.constant else c.covariance


def _window(inputs: TaskInputs, params: Params, notes: list[str]) -> _Window:
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
    return _Window(names=names, q_BG=q_BG, epoch=int(t_g_ns[0]), t_g_ns=t_g_ns, w_G=w_G, t_st_ns=t_st_ns,
                   q_IS=q_IS, sensor_of=sensor_of, sensor_index=sensor_index, q_RS=q_RS,
                   q_RG=rotations.quat_multiply(q_SB_ref, q_BG), q_BS=q_BS)


def _plausibility(win: _Window, params: Params, notes: list[str]) -> dict[str, PlausibilityResult | str]:
    """Each tracker's quaternions against the gyro (convention, time offset); a message when it cannot run."""
    out: dict[str, PlausibilityResult | str] = {}
    for name in win.names:
        sel = win.sensor_of == name
        try:
            out[name] = check_star_tracker_gyro(win.t_st_ns[sel], win.q_IS[sel], win.q_BS[name], win.t_g_ns, win.w_G,
                                                win.q_BG, sensor=name, max_time_offset_s=params.max_time_offset_s)
        except PlausibilityError as exc:
            out[name] = str(exc)
            notes.append(f"{name}: star tracker not checked against the gyro: {exc}")
    return out


def _shift_gyro(win: _Window, params: Params, plaus: dict[str, PlausibilityResult | str],
                notes: list[str]) -> tuple[_Window, float | None]:
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


def _arw(win: _Window, params: Params) -> tuple[NDArray[np.float64], str]:
    if params.gyro_arw_rad_sqrt_s is None:
        return estimate_gyro_arw(win.t_g, win.w_G), "estimated from the second differences of the gyro rates"
    arw = np.broadcast_to(np.asarray(params.gyro_arw_rad_sqrt_s, dtype=np.float64), (3,)).copy()
    if np.any(arw < 0):
        raise TaskError(f"gyro_arw_rad_sqrt_s must be >= 0, got {params.gyro_arw_rad_sqrt_s!r}")
    return arw, "given"


def _rates_to_fit(win: _Window, params: Params, notes: list[str],
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


def _fit(win: _Window, params: Params, w_fit: NDArray[np.float64], arw: NDArray[np.float64], notes: list[str],
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
        t = np.unique(inputs.gyro().time_tai_ns)
    except TaskError:
        return []
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
    from processing.estimation.chi2 import chi2_sf

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
    bias = np.array([r.summary["gyro_bias_rad_s"] for _, r in results], dtype=float)
    sig = np.array([r.summary["gyro_bias_sigma_rad_s"] for _, r in results], dtype=float)
    w = 1.0 / sig ** 2
    comb = np.sum(w * bias, axis=0) / np.sum(w, axis=0)
    comb_sig = 1.0 / np.sqrt(np.sum(w, axis=0))
    dof = 3 * (len(results) - 1)
    chi2 = float(np.sum((bias - comb) ** 2 * w))
    p = float(chi2_sf(chi2, dof)) if dof else 1.0
    consistent = p >= 0.01
    inflation = 1.0 if consistent else float(np.sqrt(chi2 / dof))
    longest = max(range(len(results)), key=lambda i: results[i][0][1] - results[i][0][0])
    base = results[longest][1]
    rows = [{"index": i, "start": iso(a), "end": iso(e), "start_tai_ns": a, "end_tai_ns": e,
             "duration_s": (e - a) / NS_PER_S, "n_star_tracker_samples": r.summary["n_star_tracker_samples"],
             "n_gyro_samples": r.summary["n_gyro_samples"], "gyro_bias_rad_s": r.summary["gyro_bias_rad_s"],
             "gyro_bias_sigma_rad_s": r.summary["gyro_bias_sigma_rad_s"], "converged": r.summary["converged"],
             "residual_rms_arcsec": r.summary["residual_rms_arcsec"]} for i, ((a, e), r) in enumerate(results)]
    summary = dict(base.summary)
    summary.update(
        gyro_bias_rad_s=_floats(comb), gyro_bias_sigma_rad_s=_floats(comb_sig * inflation),
        delta_body_arcsec_s=_floats(-comb * ARCSEC_PER_RAD),
        delta_body_sigma_arcsec_s=_floats(comb_sig * inflation * ARCSEC_PER_RAD),
        segments=rows,
        combined={"n_segments": len(results), "chi2": chi2, "dof": dof, "p_value": p, "consistent": consistent,
                  "inflation": inflation, "gyro_bias_rad_s": _floats(comb),
                  "gyro_bias_sigma_rad_s": _floats(comb_sig * inflation),
                  "detail_segment": longest,
                  "note": "gyro_bias_* are combined over the segments; the other figures (attitude, residuals, "
                          "sub-intervals, tables) are those of the longest segment, detail_segment"},
        converged=all(r.summary["converged"] for _, r in results),
    )
    warnings: list[ResultWarning] = []
    seen: set[tuple[str, str]] = set()
    for i, (_, r) in enumerate(results):
        for wng in r.warnings:
            key = (wng.code, wng.message)
            if key not in seen:
                seen.add(key)
                warnings.append(ResultWarning(wng.code, f"segment {i}: {wng.message}", {**wng.evidence, "segment": i}))
    if not consistent:
        warnings.append(ResultWarning(
            "bias_not_constant",
            f"the gyro offsets of the {len(results)} segments between the gyro gaps differ beyond their sigmas "
            f"(chi² {chi2:.1f} with {dof} degrees of freedom, p = {p:.2g}): the combined sigma is inflated by "
            f"{inflation:.2f}; see the segments' own offsets",
            {"chi2": chi2, "dof": dof, "p_value": p, "inflation": inflation}))
    notes.insert(0, f"the window was split at {len(segments) - 1} gyro gap(s) longer than max_gyro_gap_s = "
                    f"{params.max_gyro_gap_s:g} s into {len(segments)} segments; {len(results)} fitted, offsets "
                    "combined by inverse variance")
    tables = dict(base.tables)
    tables["segments"] = {
        "time_tai_ns": np.array([r["start_tai_ns"] for r in rows], dtype=np.int64),
        "end_tai_ns": np.array([r["end_tai_ns"] for r in rows], dtype=np.int64),
        **{f"gyro_bias{i + 1}_rad_s": bias[:, i] for i in range(3)},
        **{f"gyro_bias{i + 1}_sigma_rad_s": sig[:, i] for i in range(3)}}
    return TaskResult(summary=summary, tables=tables, notes=notes + list(base.notes), files=dict(base.files),
                      warnings=warnings)


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
    outcome = _Outcome(window=win, params=params, fit=fit, subs=subs, edges=edges, kinds=kinds, arw=arw,
                       arw_source=arw_source, w_ap=w_fit if params.use_smoothed_rates else None, harmonics=harmonics,
                       plausibility=plaus, time_offset_applied_s=applied, constancy=constancy)
    sub_rows = _subinterval_rows(outcome)
    warnings = _warnings(outcome)
    summary = _summary(outcome, sub_rows, warnings)
    tables = {**_series_tables(outcome), "subintervals": _subinterval_table(sub_rows)}
    progress(1.0, "done")
    return TaskResult(summary=summary, tables=tables, notes=notes, warnings=warnings)


CAUSES = ("quaternion_convention", "implausible_input", "time_offset", "bias_not_constant")
"""Warnings that explain residuals beyond the noise."""


def _causes(warnings: list[ResultWarning]) -> list[str]:
    return sorted({w.code for w in warnings if w.code in CAUSES})


def _warnings(r: _Outcome) -> list[ResultWarning]:
    """The plausibility findings of every tracker, the undetermined time offset, drifting offsets, and a fit
    whose residuals the noise does not explain (named after its likely cause when another warning has none)."""
    out: list[ResultWarning] = []
    ref = r.plausibility.get(r.window.names[0])
    for name, res in r.plausibility.items():
        if not isinstance(res, PlausibilityResult):
            continue
        for w in res.warnings:
            if w.code == "time_offset" and name == r.window.names[0] and r.time_offset_applied_s is not None:
                tau = r.time_offset_applied_s
                w = ResultWarning(w.code, f"{name}: the star-tracker samples were taken {1e3 * abs(tau):.1f} ± "
                                  f"{1e3 * (res.time_offset_sigma_s or 0.0):.1f} ms {'after' if tau > 0 else 'before'} "
                                  "their time tags, on the gyro's clock; the gyro times were corrected by it before "
                                  "the fit (fit_time_offset): correct the time tags at the source",
                                  {**w.evidence, "corrected": True})
            out.append(w)
    if isinstance(ref, PlausibilityResult):
        nw = ref.not_observable_warning()
        if nw is not None:
            out.append(ResultWarning(nw.code, f"{r.window.names[0]}: {nw.message}", nw.evidence))
    else:
        out.append(ResultWarning("not_observable", f"{r.window.names[0]}: the star tracker could not be checked "
                                 f"against the gyro ({ref}): time_offset_s is null", {"parameters": ["time_offset_s"]}))
    c = r.constancy
    if c is not None and not c.constant:
        a = ARCSEC_PER_RAD
        out.append(ResultWarning(
            "bias_not_constant",
            f"the gyro offsets differ between the {c.parts} sub-intervals beyond their sigmas (chi² {c.chi2:.1f} "
            f"with {c.dof} degrees of freedom, p = {c.p_value:.2g}): the offsets drift within the window; the "
            f"reported sigma includes their spread (x {np.round(c.inflation, 1).tolist()}); fit shorter windows "
            "(sliding_window_s) to follow the drift",
            {"parts": c.parts, "chi2": c.chi2, "dof": c.dof, "p_value": c.p_value, "alpha": c.alpha,
             "inflation": [float(x) for x in c.inflation],
             "between_sigma_sensor_arcsec_s": [float(x) for x in c.between_sigma_rad_s * a],
             "subinterval_delta_sensor_arcsec_s": [[float(x) for x in row] for row in c.estimates * a],
             "subinterval_delta_sigma_sensor_arcsec_s": [[float(x) for x in row] for row in c.sigmas * a]},
        ))
    fit = r.fit
    if float(np.max(fit.residual_consistency)) > RESIDUAL_CONSISTENCY_MAX and not _causes(out):
        rms = fit.residual_rms_rad * ARCSEC_PER_RAD
        out.append(ResultWarning(
            "implausible_input",
            f"the fit's residuals {np.round(rms[0], 1).tolist()} arcsec rms are "
            f"{np.round(np.sqrt(fit.residual_consistency[0]), 1).tolist()} times what the star-tracker and gyro "
            "noise explain, and neither the convention check, the time offset nor the offsets' constancy names a "
            "cause: check the mountings and the gyro data",
            {"residual_rms_arcsec": [[float(x) for x in row] for row in rms],
             "residual_consistency": [[float(x) for x in row] for row in fit.residual_consistency],
             "consistency_max": RESIDUAL_CONSISTENCY_MAX},
        ))
    return out


# ---------------------------------------------------------------------------------------------------
# Report: summary and tables.


def _subinterval_rows(r: _Outcome) -> list[dict[str, Any]]:
    epoch, q_BG, arcsec = r.window.epoch, r.window.q_BG, ARCSEC_PER_RAD
    rows = []
    for (a, e), fit_k, (kind, parts, index) in zip(r.edges, r.subs, r.kinds, strict=True):
        start_ns, end_ns = epoch + int(round(a * NS_PER_S)), epoch + int(round(e * NS_PER_S))
        row: dict[str, Any] = {
            "kind": kind, "parts": parts, "index": index,
            "start": iso(start_ns), "end": iso(end_ns), "start_tai_ns": start_ns, "end_tai_ns": end_ns,
        }
        if fit_k is None:
            row.update(n_samples=0, gyro_bias_rad_s=None, gyro_bias_sigma_rad_s=None)
        else:
            bk, bk_sig = _bias_body(fit_k, q_BG, fit_k.covariance[3:6, 3:6])
            _, bk_sig_p = _bias_body(fit_k, q_BG, fit_k.covariance_paper[3:6, 3:6])
            row.update(
                n_samples=int(fit_k.n_samples.sum()),
                gyro_bias_rad_s=_floats(bk),
                gyro_bias_sigma_rad_s=_floats(bk_sig),
                gyro_bias_sigma_paper_rad_s=_floats(bk_sig_p),
                delta_sensor_arcsec_s=_floats(fit_k.delta_R_rad_s * arcsec),
                delta_sensor_sigma_arcsec_s=_floats(fit_k.sigma[3:6] * arcsec),
                delta_sensor_sigma_paper_arcsec_s=_floats(fit_k.sigma_paper[3:6] * arcsec),
                residual_rms_arcsec=_floats(fit_k.residual_rms_rad[0] * arcsec),
                converged=bool(fit_k.converged),
            )
        rows.append(row)
    return rows


def _mounting(fit: GyroBiasFit, q_BR: NDArray[np.float64]) -> dict[str, Any] | None:
    if fit.mounting is None:
        return None
    m = fit.mounting
    return {
        "determinable": bool(m.determinable),
        "reason": m.reason,
        "misalignment_sensor_rad": None if m.rotvec_R_rad is None else _floats(m.rotvec_R_rad),
        "misalignment_sigma_sensor_rad": _floats(m.sigma_rad),
        "misalignment_sigma_paper_sensor_rad": _floats(m.sigma_paper_rad),
        "q_BS": None if m.rotvec_R_rad is None else _floats(rotations.quat_canonical(q_BR)),
        "condition_number": float(m.condition_number),
        "max_abs_correlation": float(m.max_abs_correlation),
        "correlation": [_floats(r) for r in m.correlation],
    }


def _summary(r: _Outcome, sub_rows: list[dict[str, Any]], warnings: list[ResultWarning]) -> dict[str, Any]:
    fit, win, params, arcsec = r.fit, r.window, r.params, ARCSEC_PER_RAD
    cov_delta = r.delta_covariance
    b, b_sig = _bias_body(fit, win.q_BG, cov_delta)
    _, b_sig_constant = _bias_body(fit, win.q_BG, fit.covariance[3:6, 3:6])
    _, b_sig_paper = _bias_body(fit, win.q_BG, fit.covariance_paper[3:6, 3:6])
    covariance = fit.covariance.copy()
    covariance[3:6, 3:6] = cov_delta
    q_BR = rotations.quat_multiply(win.q_BG, rotations.quat_conjugate(fit.q_RG))
    q_IB0 = rotations.quat_canonical(rotations.quat_multiply(fit.q_IR0, rotations.quat_conjugate(q_BR)))
    t0_ns = win.epoch + int(round(fit.t0_s * NS_PER_S))
    status = fit.status
    if not fit.converged and float(np.max(fit.residual_consistency)) > RESIDUAL_CONSISTENCY_MAX and _causes(warnings):
        status += f"; likely cause: {', '.join(_causes(warnings))} (see the warnings)"
    found = r.plausibility.get(win.names[0])
    ref = found if isinstance(found, PlausibilityResult) else None
    sensors = {
        name: {
            "n_samples": int(fit.n_samples[j]),
            "residual_rms_arcsec": _floats(fit.residual_rms_rad[j] * arcsec),
            "residual_rms_gyro_arcsec": _floats(fit.residual_rms_gyro_rad[j] * arcsec),
            "star_tracker_sigma_arcsec": _floats(fit.star_tracker_sigma_rad[j] * arcsec),
            "residual_consistency": _floats(fit.residual_consistency[j]),
            "plausibility": (res.summary() if isinstance(res := r.plausibility.get(name), PlausibilityResult)
                             else {"error": res}),
        }
        for j, name in enumerate(win.names)
    }
    c = r.constancy
    return {
        "gyro_bias_rad_s": _floats(b),
        "gyro_bias_sigma_rad_s": _floats(b_sig),
        "gyro_bias_sigma_constant_rad_s": _floats(b_sig_constant),
        "gyro_bias_sigma_paper_rad_s": _floats(b_sig_paper),
        "delta_sensor_arcsec_s": _floats(fit.delta_R_rad_s * arcsec),
        "delta_sensor_sigma_arcsec_s": _floats(np.sqrt(np.diag(cov_delta)) * arcsec),
        "delta_sensor_sigma_paper_arcsec_s": _floats(fit.sigma_paper[3:6] * arcsec),
        "delta_body_arcsec_s": _floats(-b * arcsec),
        "delta_body_sigma_arcsec_s": _floats(b_sig * arcsec),
        "offset_constancy": None if c is None else {
            "parts": c.parts, "chi2": float(c.chi2), "dof": c.dof, "p_value": float(c.p_value), "alpha": c.alpha,
            "constant": bool(c.constant), "inflation": _floats(c.inflation),
            "between_sigma_sensor_arcsec_s": _floats(c.between_sigma_rad_s * arcsec)},
        "time_offset_s": None if ref is None else ref.time_offset_s,
        "time_offset_sigma_s": None if ref is None else ref.time_offset_sigma_s,
        "time_offset_observable": False if ref is None else bool(ref.time_offset_observable),
        "time_offset_corrected_s": r.time_offset_applied_s,
        "quaternion_convention": None if ref is None else ref.convention,
        "initial_mrp": _floats(fit.initial_mrp),
        "initial_mrp_sigma": _floats(fit.sigma[:3]),
        "initial_mrp_sigma_paper": _floats(fit.sigma_paper[:3]),
        "initial_time": iso(t0_ns),
        "initial_time_tai_ns": t0_ns,
        "initial_q_IS": _floats(fit.q_IR0),
        "initial_q_IB": _floats(q_IB0),
        "sigma_unit_weight": float(fit.sigma_unit_weight),
        "residual_rms_arcsec": _floats(fit.residual_rms_rad[0] * arcsec),
        "residual_rms_gyro_arcsec": _floats(fit.residual_rms_gyro_rad[0] * arcsec),
        "residual_consistency": _floats(fit.residual_consistency[0]),
        "star_tracker_sigma_arcsec": _floats(fit.star_tracker_sigma_rad[0] * arcsec),
        "iterations": int(fit.iterations),
        "converged": bool(fit.converged),
        "status": status,
        "scheme": int(params.scheme),
        "use_smoothed_rates": bool(params.use_smoothed_rates),
        "smoothing_harmonics": r.harmonics,
        "weights": _floats(params.weights),
        "gyro_arw_rad_sqrt_s": _floats(r.arw),
        "gyro_arw_source": r.arw_source,
        "reference_sensor": win.names[0],
        "sensors": sensors,
        "n_star_tracker_samples": int(fit.n_samples.sum()),
        "n_gyro_samples": int(win.t_g_ns.size),
        "parameter_names": list(fit.parameter_names),
        "covariance": [_floats(row) for row in covariance],
        "covariance_paper": [_floats(row) for row in fit.covariance_paper],
        "condition_number": float(fit.condition_number),
        "mounting": _mounting(fit, q_BR),
        "subintervals": sub_rows,
    }


def _series_tables(r: _Outcome) -> dict[str, dict[str, NDArray[Any]]]:
    """Residual rotations per star-tracker sample and the body rates (every k-th gyro sample)."""
    fit, win, arcsec = r.fit, r.window, ARCSEC_PER_RAD
    b, _ = _bias_body(fit, win.q_BG, fit.covariance[3:6, 3:6])
    residuals = {
        "time_tai_ns": win.t_st_ns,
        "sensor": np.asarray(win.sensor_of, dtype=object),
        **{f"e{i + 1}_arcsec": fit.residuals_rad[:, i] * arcsec for i in range(3)},
    }
    stride = max(1, -(-win.t_g_ns.size // RATES_TABLE_MAX_ROWS))
    r_bg = rotations.quat_to_dcm(win.q_BG)
    w_B = (win.w_G[::stride] @ r_bg.T - b) / RAD_PER_DEG
    rates: dict[str, NDArray[Any]] = {"time_tai_ns": win.t_g_ns[::stride]}
    rates.update({f"w{i + 1}_B_deg_s": w_B[:, i] for i in range(3)})
    if r.w_ap is not None:
        w_ap_B = (r.w_ap[::stride] @ r_bg.T - b) / RAD_PER_DEG
        rates.update({f"w{i + 1}_B_ap_deg_s": w_ap_B[:, i] for i in range(3)})
    return {"residuals": residuals, "rates": rates}


def _subinterval_table(sub_rows: list[dict[str, Any]]) -> dict[str, NDArray[Any]]:
    table: dict[str, NDArray[Any]] = {
        "kind": np.array([r["kind"] for r in sub_rows], dtype=object),
        "parts": np.array([r["parts"] for r in sub_rows], dtype=np.int64),
        "index": np.array([r["index"] for r in sub_rows], dtype=np.int64),
        "start_tai_ns": np.array([r["start_tai_ns"] for r in sub_rows], dtype=np.int64),
        "end_tai_ns": np.array([r["end_tai_ns"] for r in sub_rows], dtype=np.int64),
        "n_samples": np.array([r["n_samples"] for r in sub_rows], dtype=np.int64),
    }
    for key, col in (
        ("delta_sensor_arcsec_s", "delta{}_sensor_arcsec_s"),
        ("delta_sensor_sigma_arcsec_s", "delta{}_sensor_sigma_arcsec_s"),
        ("gyro_bias_rad_s", "gyro_bias{}_rad_s"),
        ("gyro_bias_sigma_rad_s", "gyro_bias{}_sigma_rad_s"),
        ("residual_rms_arcsec", "residual_rms{}_arcsec"),
    ):
        vals = np.array([r.get(key) or [np.nan] * 3 for r in sub_rows], dtype=np.float64).reshape(-1, 3)
        table.update({col.format(i + 1): vals[:, i] for i in range(3)})
    return table


JOB = JobType(
    name="gyro_bias_fit",
    title="Gyro offsets and attitude from star tracker + gyro (Gauss-Newton)",
    paper="003 §2",
    params=Params,
    run=run,
    streams=("star_tracker", "gyro"),
    figures=figures,
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
