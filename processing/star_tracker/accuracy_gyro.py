"""The gyro side of the star-tracker accuracy analysis (003 §1.4-1.5): steps 5 and 7 of
processing.star_tracker.accuracy.

5. Gyro (003 §1.4): body rates w_B smoothed per star-tracker segment by the sine series with the same
   cutoff frequency (:func:`fit_gyro_segment`), compared with the star-tracker rates after matching the
   means (:func:`gyro_comparison`; expected difference from the star-tracker noise propagated through
   the fit's derivative, :func:`rate_noise_factor`, and the gyro noise).
7. Real motion (003 §1.5): lines above the smoother's cutoff in the gyro smoothing residuals
   (:func:`find_gyro_lines`), fitted per segment and integrated into the attitude oscillation about the
   sensor axes (:func:`segment_line_motions`) that the accuracy analysis removes from the measurements,
   but only the lines the star tracker sees (:func:`line_coherence`): a line in the gyro output alone
   (a vibration of the gyro or its mounting, an electronic tone) is not attitude motion, and removing
   it would add its oscillation to the star-tracker residuals (~40 % more sigma in the issue-17 case).
   Each line's predicted oscillation theta_j(t_n), minus its own sine-series smoothing (the part the
   fit would absorb anyway), is regressed jointly on the raw star-tracker residuals, the axes weighted
   by the robust noise scale: e = sum_j beta_j theta_j + noise. Real motion has beta = 1. A line is
   removed when it is coherent (beta / sigma_beta > LINE_Z) and the removal reduces the residuals
   (|e - theta|^2 < |e|^2, i.e. beta > 1/2); it is flagged ``gyro_only`` when it is not removed and
   beta is significantly below 1 ((1 - beta) / sigma_beta > LINE_Z). sigma_beta from the regression's own
   residual scatter. Lines too weak in the star tracker to tell (neither) are not removed either: their
   effect on the sigma is then within its noise.

The per-segment gyro fit is computed once (with the harmonic count of the raw star-tracker fit) and
reused by the comparison whenever the final star-tracker fit implies the same gyro harmonic count.
Times int64 TAI ns or float seconds as named; rates rad/s, angles rad.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from processing.estimation.chi2 import chi2_isf
from processing.signal.sine_series import SineSeriesSolver, fit_sine_series
from processing.signal.sine_series_fit import SineSeriesFit
from processing.signal.spectral import alias_frequency
from processing.signal.spectral_lines import SinusoidFit, find_lines, fit_sinusoids, separable_frequencies
from processing.star_tracker.gyro_coverage import enough_gyro_samples
from processing.star_tracker.smoothing import SegmentSmoothing, rate_from_mrp, seconds_since, sensor_axis_residuals
from processing.tasks import Mapper, serial_map

__all__ = [
    "GyroAnalysis",
    "GyroComparison",
    "GyroLines",
    "GyroSegmentFit",
    "LINE_Z",
    "LineCoherence",
    "SpectralLine",
    "analyze_gyro",
    "find_gyro_lines",
    "fit_gyro_segment",
    "gyro_comparison",
    "gyro_harmonics",
    "line_coherence",
    "rate_noise_factor",
    "segment_line_fits",
    "segment_line_motions",
    "segment_lines",
    "segment_motion",
]

LINE_Z = float(np.sqrt(chi2_isf(1e-3, 1)))
"""|z| of a two-sided 0.1 % test (3.29): the significance of a line's coherence with the star tracker."""


@dataclass(frozen=True)
class GyroComparison:
    """003 §1.4 comparison, body frame, at the gyro samples inside the star-tracker segments.

    time_tai_ns (K,); w_B_gyro_rad_s (K, 3) smoothed gyro with its offset removed;
    w_B_star_tracker_rad_s (K, 3) from z(t); offset_rad_s (3,) mean smoothed gyro minus mean
    star-tracker rate (sample-weighted over segments; a bias estimate of w_meas = w_true + b);
    rms_diff_rad_s (3,); expected_rms_diff_rad_s (3,) from the star-tracker sigma propagated through
    the fit derivative plus the gyro noise through the gyro smoothing; smoothing_sigma_rad_s (3,)
    residual std of the gyro smoothing (003 §1.4's 4.2/2.6/5.0 "/s, lines included);
    noise_sigma_rad_s (3,) the same after removing the detected lines (the gyro's white noise).
    """

    time_tai_ns: NDArray
    w_B_gyro_rad_s: NDArray
    w_B_star_tracker_rad_s: NDArray
    offset_rad_s: NDArray
    rms_diff_rad_s: NDArray
    expected_rms_diff_rad_s: NDArray
    smoothing_sigma_rad_s: NDArray
    noise_sigma_rad_s: NDArray


@dataclass(frozen=True)
class SpectralLine:
    """A spectral line (003 §1.5). source "gyro" (axis "y1".."y3", body) or "star_tracker" (axis
    "x1".."x3", residuals about the sensor axes). freq_hz: as measured (for star_tracker: the
    apparent frequency in its samples). amplitude_rad_s: rate amplitude (gyro; None for
    star_tracker, whose true frequency is ambiguous). attitude_amplitude_rad: A/(2 pi f) for gyro,
    the residual amplitude for star_tracker; attitude_rms_rad = amplitude/sqrt 2. aliased_freq_hz:
    where it appears in the star-tracker samples. removed: for gyro lines, used to correct the star
    tracker; for star_tracker lines, at the alias of such a gyro line (so explained by real motion)."""

    source: str
    axis: str
    freq_hz: float
    amplitude_rad_s: float | None
    attitude_amplitude_rad: float
    attitude_rms_rad: float
    aliased_freq_hz: float
    removed: bool


@dataclass(frozen=True)
class GyroSegmentFit:
    """Step 5 on one segment: the gyro samples idx (K,) inside it, their times t_s (K,) [s] since the
    segment's first star-tracker sample, the harmonic count of the gyro series, its fit of w_B and the
    residuals (K, 3) rad/s."""

    idx: NDArray
    t_s: NDArray
    harmonics: int
    fit: SineSeriesFit
    residuals: NDArray


@dataclass(frozen=True)
class GyroLines:
    """Step 7: the gyro lines above the cutoff (their joint fits, strongest first by frequency order of
    the finder) and the three :class:`SpectralLine` rows (y1..y3) of each."""

    fits: tuple[SinusoidFit, ...]
    lines: tuple[SpectralLine, ...]


def gyro_harmonics(star_tracker_harmonics: int, span_s: float, t_s: NDArray) -> int:
    """M of the gyro series with the cutoff M/(2T) of the star-tracker fit over the gyro span t_s."""
    return int(round(star_tracker_harmonics * (t_s[-1] - t_s[0]) / span_s))


def fit_gyro_segment(
    seg: SegmentSmoothing, idx: NDArray, g_ns: NDArray, w_B: NDArray, star_tracker_fit: SineSeriesFit
) -> GyroSegmentFit:
    """Step 5 (003 §1.4): the body rates w_B[idx] smoothed with the cutoff of ``star_tracker_fit``."""
    tg = seconds_since(g_ns[idx], seg.t0_ns)
    m_g = gyro_harmonics(star_tracker_fit.harmonics, star_tracker_fit.span_s, tg)
    gfit = fit_sine_series(tg, w_B[idx], m_g)
    return GyroSegmentFit(idx, tg, m_g, gfit, gfit.residuals(w_B[idx]))


def _gyro_part(part: tuple[NDArray, NDArray, int]) -> tuple[SineSeriesFit, NDArray]:
    """One segment's gyro smoothing (a part for the mapper): times [s], rates (K, 3), harmonics."""
    tg, w, m_g = part
    gfit = fit_sine_series(tg, w, m_g)
    return gfit, gfit.residuals(w)


def _fit_gyro_segments(segments: Sequence[SegmentSmoothing], index: Sequence[NDArray | None], g_ns: NDArray,
                       w_B: NDArray, mapper: Mapper) -> tuple[GyroSegmentFit | None, ...]:
    """:func:`fit_gyro_segment` of every covered segment, the smoothings through ``mapper`` (same results)."""
    parts, meta = [], []
    for seg, idx in zip(segments, index, strict=True):
        if idx is None:
            continue
        tg = seconds_since(g_ns[idx], seg.t0_ns)
        m_g = gyro_harmonics(seg.fit_raw.harmonics, seg.fit_raw.span_s, tg)
        parts.append((tg, w_B[idx], m_g))
        meta.append((idx, tg, m_g))
    done = iter(zip(meta, mapper(_gyro_part, parts), strict=True))
    out: list[GyroSegmentFit | None] = []
    for idx in index:
        if idx is None:
            out.append(None)
            continue
        (i, tg, m_g), (gfit, resid) = next(done)
        out.append(GyroSegmentFit(i, tg, m_g, gfit, resid))
    return tuple(out)


def find_gyro_lines(
    fits: Sequence[GyroSegmentFit], g_ns: NDArray, cutoff_hz: float, sample_period_s: float, false_alarm: float
) -> GyroLines:
    """Step 7 (003 §1.5): lines above cutoff_hz in the gyro smoothing residuals of all segments."""
    res_ns = np.concatenate([g_ns[f.idx] for f in fits])
    res = np.concatenate([f.residuals for f in fits])
    found, _ = find_lines(seconds_since(res_ns, int(res_ns[0])), res, min_freq_hz=cutoff_hz, false_alarm=false_alarm)
    line_fits: list[SinusoidFit] = []
    lines: list[SpectralLine] = []
    for line in found:
        lf = line.fit
        line_fits.append(lf)
        w = 2.0 * np.pi * lf.freq_hz
        alias = float(alias_frequency(lf.freq_hz, sample_period_s))
        for k in range(3):
            lines.append(SpectralLine(
                "gyro", f"y{k + 1}", lf.freq_hz, float(lf.amplitude[k]), float(lf.amplitude[k] / w),
                float(lf.amplitude[k] / w / np.sqrt(2.0)), alias, True,
            ))
    return GyroLines(tuple(line_fits), tuple(lines))


def segment_lines(line_fits: Sequence[SinusoidFit], t_s: NDArray) -> NDArray:
    """Frequencies of the lines that a stretch of times t_s (s) can separate (strongest first)."""
    if not line_fits:
        return np.zeros(0)
    weights = [float(np.sum(lf.amplitude**2)) for lf in line_fits]
    return separable_frequencies([lf.freq_hz for lf in line_fits], weights, 1.0 / float(t_s[-1] - t_s[0]))


def segment_motion(
    seg: SegmentSmoothing, gyro_fit: GyroSegmentFit | None, line_fits: Sequence[SinusoidFit], dcm_BS: NDArray
) -> NDArray:
    """Step 7 on one segment: the attitude oscillation theta_S (N, 3) rad about the sensor axes at the
    star-tracker samples (zeros without gyro samples or lines).

    Amplitude and phase of the lines are fitted per segment (frequencies fixed, jointly) to the gyro
    residuals and integrated. Lines closer than the segment's resolution are one line there (e.g. the
    sidelobes a long record resolves beside a strong line): fitted apart, each would absorb the same
    motion.
    """
    if gyro_fit is None or not line_fits:
        return np.zeros((seg.sl.stop - seg.sl.start, 3))
    tg = gyro_fit.t_s
    sines = fit_sinusoids(tg, gyro_fit.residuals, segment_lines(line_fits, tg))
    theta_B = sum(fs.integral(seg.t_s) for fs in sines)
    return theta_B @ dcm_BS  # rows: dcm_SB theta_B = dcm_BS^T theta_B


def rate_noise_factor(solver: SineSeriesSolver, fit: SineSeriesFit) -> float:
    """Time average of v(t) = d(t)^T (A^T A)^-1 d(t) over the segment, so that the fitted rates have
    mean variance sigma_i^2 v (A: the design at the samples, d: the time derivative of the basis).

    For times spread uniformly over the span, the average of d d^T is diag(0, 1/T^2, (pi m/T)^2/2)
    (the cosines are orthogonal on [0, T]), hence v = G_11/T^2 + sum_m G_mm (pi m/T)^2/2 with
    G = (A^T A)^-1 (:meth:`SineSeriesSolver.covariance_diag`).
    """
    g_diag = solver.covariance_diag(fit.harmonics)
    m = np.arange(1, fit.harmonics + 1, dtype=np.float64)
    weights = np.concatenate([[0.0, 1.0], 0.5 * (np.pi * m) ** 2]) / fit.span_s**2
    return float(np.sum(g_diag * weights))


def segment_line_fits(gyro_fit: GyroSegmentFit | None, line_fits: Sequence[SinusoidFit]) -> tuple[SinusoidFit, ...]:
    """The lines fitted jointly to one segment's gyro residuals at the frequencies it separates
    (:func:`segment_lines`); none without gyro samples or lines."""
    if gyro_fit is None or not line_fits:
        return ()
    return tuple(fit_sinusoids(gyro_fit.t_s, gyro_fit.residuals, segment_lines(line_fits, gyro_fit.t_s)))


def segment_line_motions(
    seg: SegmentSmoothing, gyro_fit: GyroSegmentFit | None, line_fits: Sequence[SinusoidFit], dcm_BS: NDArray,
    sines: Sequence[SinusoidFit] | None = None,
) -> NDArray:
    """Step 7 on one segment, per line: theta_S of each of the J lines (J, N, 3) rad about the sensor
    axes (their sum is :func:`segment_motion`). A line merged into a stronger one at this segment's
    resolution carries no motion of its own here (zeros); the stronger one carries both. ``sines``: the
    segment's :func:`segment_line_fits` when already computed."""
    n = seg.sl.stop - seg.sl.start
    out = np.zeros((len(line_fits), n, 3))
    if gyro_fit is None or not line_fits:
        return out
    freqs = np.array([lf.freq_hz for lf in line_fits])
    for fs in segment_line_fits(gyro_fit, line_fits) if sines is None else sines:
        j = int(np.argmin(np.abs(freqs - fs.freq_hz)))
        out[j] += fs.integral(seg.t_s) @ dcm_BS  # rows: dcm_SB theta_B = dcm_BS^T theta_B
    return out


@dataclass(frozen=True)
class LineCoherence:
    """A gyro line against the star tracker (:func:`line_coherence`): frequency [Hz], beta (1 for real
    attitude motion, 0 for a line the star tracker does not see) and its sigma, whether it was removed
    from the star-tracker measurements, whether it is significantly in the gyro only, and the rms of its
    predicted oscillation about x1 x2 x3 (3,) rad."""

    freq_hz: float
    beta: float
    beta_sigma: float
    removed: bool
    gyro_only: bool
    predicted_rms_rad: NDArray


def line_coherence(
    segments: Sequence[SegmentSmoothing], motions: Sequence[NDArray], line_fits: Sequence[SinusoidFit],
    scale_S: NDArray,
) -> tuple[LineCoherence, ...]:
    """The joint regression of the module docstring (step 7): per segment the raw residuals of the
    accepted samples, the lines' oscillations motions[seg] (J, N, 3) minus their smoothing with the
    segment's harmonics, axes weighted by 1 / scale_S (3,) rad."""
    n_lines = len(line_fits)
    if n_lines == 0:
        return ()
    ata = np.zeros((n_lines, n_lines))
    atb = np.zeros(n_lines)
    btb = 0.0
    n_obs = 0
    sq = np.zeros((n_lines, 3))
    n_rows = 0
    w = 1.0 / np.asarray(scale_S, dtype=np.float64)
    for seg, m in zip(segments, motions, strict=True):
        ok = seg.accepted
        e = sensor_axis_residuals(seg.z, seg.fit_raw.fitted)[ok] * w
        flat = np.moveaxis(m, 0, 1).reshape(m.shape[1], 3 * n_lines)  # (N, J*3)
        perp = flat - seg.solver.fit(flat, seg.fit_raw.harmonics).fitted
        a = perp[ok].reshape(-1, n_lines, 3) * w  # (n, J, 3)
        ata += np.einsum("nji,nki->jk", a, a)
        atb += np.einsum("nji,ni->j", a, e)
        btb += float(np.sum(e * e))
        n_obs += e.size
        sq += np.sum(m[:, ok] ** 2, axis=1)
        n_rows += int(np.count_nonzero(ok))
    try:
        cov = np.linalg.inv(ata)
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(ata)
    beta = cov @ atb
    s2 = max((btb - float(beta @ atb)) / max(n_obs - n_lines, 1), 0.0)
    sig = np.sqrt(np.maximum(np.diag(cov), 0.0) * s2)
    out = []
    for j, lf in enumerate(line_fits):
        b, sb = float(beta[j]), float(sig[j])
        coherent = sb > 0 and b / sb > LINE_Z
        removed = bool(coherent and b > 0.5)
        gyro_only = bool(not removed and sb > 0 and (1.0 - b) / sb > LINE_Z)
        out.append(LineCoherence(float(lf.freq_hz), b, sb, removed, gyro_only, np.sqrt(sq[j] / max(n_rows, 1))))
    return tuple(out)


@dataclass(frozen=True)
class GyroAnalysis:
    """Steps 5 and 7 together: gyro times (K,) and body rates (K, 3), per star-tracker segment the gyro
    smoothing (None without enough gyro samples) and the attitude oscillation motion_S (N_seg, 3) to
    remove (the coherent lines only), the gyro lines (``removed`` set per line) and their coherence
    with the star tracker; line_sines: per segment the lines fitted to its gyro residuals
    (:func:`segment_line_fits`, reused by the comparison when its gyro fit is the same)."""

    time_tai_ns: NDArray
    w_B_rad_s: NDArray
    fits: tuple[GyroSegmentFit | None, ...]
    motion_S: tuple[NDArray, ...]
    lines: GyroLines
    coherence: tuple[LineCoherence, ...] = ()
    line_sines: tuple[tuple[SinusoidFit, ...], ...] = ()

    @property
    def removed_fits(self) -> tuple[SinusoidFit, ...]:
        """The line fits removed from the star tracker (coherent with it)."""
        return tuple(lf for lf, c in zip(self.lines.fits, self.coherence, strict=True) if c.removed)


def analyze_gyro(
    segments: Sequence[SegmentSmoothing], index: Sequence[NDArray | None], g_ns: NDArray, w_B: NDArray,
    dcm_BS: NDArray, cutoff_hz: float, sample_period_s: float, false_alarm: float, scale_S: NDArray | None = None,
    mapper: Mapper = serial_map,
) -> GyroAnalysis | None:
    """Steps 5 and 7 for the star-tracker segments and gyro rates w_B (K, 3) at g_ns (K,): smoothing per
    segment, lines above cutoff_hz, the attitude oscillation per segment of the lines coherent with the
    star tracker (scale_S (3,) rad: its noise scale per sensor axis for the coherence regression; None:
    every line removed, no test). index: per segment the gyro samples to use, None where the gyro does not
    cover it (processing.star_tracker.gyro_coverage). None when it covers no segment. ``mapper``: how the
    per-segment gyro smoothings are run (processing.tasks.Mapper)."""
    if all(idx is None for idx in index):
        return None
    fits = _fit_gyro_segments(segments, index, g_ns, w_B, mapper)
    lines = find_gyro_lines([f for f in fits if f is not None], g_ns, cutoff_hz, sample_period_s, false_alarm)
    sines = tuple(segment_line_fits(f, lines.fits) for f in fits)
    per_line = [segment_line_motions(seg, f, lines.fits, dcm_BS, sn)
                for seg, f, sn in zip(segments, fits, sines, strict=True)]
    if scale_S is None:
        coherence = tuple(LineCoherence(lf.freq_hz, 1.0, 0.0, True, False, np.zeros(3)) for lf in lines.fits)
    else:
        coherence = line_coherence(segments, per_line, lines.fits, scale_S)
    keep = np.array([c.removed for c in coherence], dtype=bool)
    motion = tuple(np.sum(m[keep], axis=0) if keep.any() else np.zeros(m.shape[1:]) for m in per_line)
    flagged = tuple(replace(line, removed=bool(keep[i // 3])) for i, line in enumerate(lines.lines))
    return GyroAnalysis(g_ns, w_B, fits, motion, GyroLines(lines.fits, flagged), coherence, sines)


@dataclass(frozen=True)
class _SegmentComparison:
    """One segment of the comparison: gyro samples inside the star-tracker span (times, smoothed gyro
    with its offset removed, star-tracker rates, offset), residual sums of the gyro smoothing with and
    without the lines and their dof, and the terms of the expected rms difference."""

    time_tai_ns: NDArray
    w_gyro: NDArray
    w_st: NDArray
    offset: NDArray
    rss_smoothing: NDArray
    dof_smoothing: int
    rss_noise: NDArray
    dof_noise: int
    var_st_B: NDArray
    n_inside: int
    n_parameters: int
    n_gyro: int


_ComparePart = tuple[SegmentSmoothing, SineSeriesFit, GyroSegmentFit, NDArray, "NDArray | None", NDArray, NDArray,
                     Sequence[SinusoidFit], "Sequence[SinusoidFit] | None"]


def _compare_segment(part: _ComparePart) -> _SegmentComparison:
    """One segment of the comparison (a part for the mapper): the segment, its final star-tracker fit, its gyro
    fit, the gyro times of that fit (K,), the gyro rates (K, 3) when the fit must be redone with the final
    fit's cutoff (else None), dcm_BS, the sensor sigma, the gyro lines and their fits to this gyro fit's
    residuals (:func:`segment_line_fits`; None: fitted here)."""
    seg, fit, gf, g_seg, w_seg, dcm_BS, sigma_S, line_fits, sines = part
    if w_seg is not None:
        gf = fit_gyro_segment(seg, np.arange(g_seg.size), g_seg, w_seg, fit)
    tg, gfit, resid = gf.t_s, gf.fit, gf.residuals
    rss_s = np.sum(resid**2, axis=0)
    seg_sines = segment_line_fits(gf, line_fits) if sines is None else sines
    if seg_sines:
        resid = resid - sum(fs.evaluate(tg) for fs in seg_sines)
    inside = (tg >= 0.0) & (tg <= fit.span_s)
    tg_in = tg[inside]
    g_sm = gfit.fitted[inside]
    st = rate_from_mrp(*fit.evaluate_with_derivative(tg_in)) @ dcm_BS.T
    off = np.mean(g_sm - st, axis=0)
    return _SegmentComparison(
        time_tai_ns=g_seg[inside], w_gyro=g_sm - off, w_st=st, offset=off, rss_smoothing=rss_s,
        dof_smoothing=gfit.dof, rss_noise=np.sum(resid**2, axis=0), dof_noise=gfit.dof - 2 * len(seg_sines),
        var_st_B=rate_noise_factor(seg.solver, fit) * (dcm_BS**2 @ sigma_S**2), n_inside=tg_in.size,
        n_parameters=gf.harmonics + 2, n_gyro=tg.size,
    )


def gyro_comparison(
    segments: Sequence[SegmentSmoothing],
    fits: Sequence[SineSeriesFit],
    gyro_fits: Sequence[GyroSegmentFit | None],
    g_ns: NDArray,
    w_B_gyro: NDArray,
    dcm_BS: NDArray,
    sigma_S: NDArray,
    line_fits: Sequence[SinusoidFit],
    mapper: Mapper = serial_map,
    line_sines: Sequence[Sequence[SinusoidFit]] | None = None,
) -> GyroComparison | None:
    """Step 5 (003 §1.4): smoothed gyro (the cutoff of each segment's final fit ``fits``) against the
    star-tracker rates, offsets matched. The gyro fits of step 7 are reused when the harmonic count is
    the same; segments without gyro samples (None) or with too few for the final harmonic count are left
    out (None when that leaves none). The segments go through ``mapper``. line_sines: per segment the lines
    fitted to the residuals of gyro_fits (GyroAnalysis.line_sines), reused where the gyro fit is; None:
    fitted again."""
    todo: list[_ComparePart] = []
    for i, (seg, fit, gf) in enumerate(zip(segments, fits, gyro_fits, strict=True)):
        if gf is None:
            continue
        harmonics = gyro_harmonics(fit.harmonics, fit.span_s, gf.t_s)
        refit = harmonics != gf.harmonics
        if refit and not enough_gyro_samples(gf.idx.size, harmonics):
            continue  # the final M needs more gyro samples than the segment has (criterion ``samples``)
        sines = None if refit or line_sines is None else line_sines[i]
        todo.append((seg, fit, gf, g_ns[gf.idx], w_B_gyro[gf.idx] if refit else None, dcm_BS, sigma_S, line_fits,
                     sines))
    if not todo:
        return None
    parts: list[_SegmentComparison] = mapper(_compare_segment, todo)
    rss_s, rss_n = np.zeros(3), np.zeros(3)
    for p in parts:
        rss_s += p.rss_smoothing
        rss_n += p.rss_noise
    smoothing_sigma = np.sqrt(rss_s / max(sum(p.dof_smoothing for p in parts), 1))
    noise_sigma = np.sqrt(rss_n / max(sum(p.dof_noise for p in parts), 1))
    total = sum(p.n_inside for p in parts)
    exp_var = sum((p.var_st_B + noise_sigma**2 * p.n_parameters / p.n_gyro) * p.n_inside for p in parts) / total
    w_g = np.concatenate([p.w_gyro for p in parts])
    w_st = np.concatenate([p.w_st for p in parts])
    diff = w_g - w_st
    return GyroComparison(
        time_tai_ns=np.concatenate([p.time_tai_ns for p in parts]),
        w_B_gyro_rad_s=w_g,
        w_B_star_tracker_rad_s=w_st,
        offset_rad_s=np.average(np.array([p.offset for p in parts]), axis=0,
                                weights=np.array([p.n_inside for p in parts], dtype=float)),
        rms_diff_rad_s=np.sqrt(np.mean(diff**2, axis=0)),
        expected_rms_diff_rad_s=np.sqrt(exp_var),
        smoothing_sigma_rad_s=smoothing_sigma,
        noise_sigma_rad_s=noise_sigma,
    )
