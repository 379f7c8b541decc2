"""Star-tracker accuracy from flight data: Rodrigues-parameter smoothing and spectra (003 §1.3-1.5).

Method (003 = Avanesov et al., Keldysh Institute preprint 74, 2010):

1. Segments of at most ``segment_max_s`` (003: under 20 min), split at gaps longer than
   ``max_gap_s``. In each, the mean quaternion q_c = Q/|Q|, Q = sum q_n (003 §1.3, after putting
   every q_n in the hemisphere of its predecessor) and the residual Rodrigues parameters (MRPs)
   z^(n) of q_c^-1 o q_n.
2. Each z_i is smoothed by the sine series plus linear trend of 003 §1.3 (processing.signal.sine_series:
   DST route without gaps, QR least squares with gaps). 2b: outliers (samples far off, e.g. a
   mis-identified star) are rejected and the segments refitted without them, iterated to a fixed
   point (processing.star_tracker.robust: chi-square test of the three residuals against a robust MAD
   scale, 1 % false-alarm probability per data set); rejected samples stay out of every later step.
3. Residuals about the sensor axes x1, x2, x3. 003 eq. 2 takes e_i = 4 (z_i^(n) - z_i(t_n)), which is
   the rotation angle about x_i only while |z| << 1. In orbital orientation a 20-min segment turns
   by ~70 deg about nearly the boresight, |z| reaches 0.16 and eq. 2 mixes the axes
   (e_1 = (1 - z^2) th_1 - 2 z_3 th_2 + ...), inflating the x1 figure by ~6 % with the 003 noise
   levels. We therefore take the exact small rotation q_sm(t_n)^-1 o q_n (q_sm = q_c o s(z(t)))
   as the rotation vector about the sensor axes (equal to eq. 2 to first order in z) and keep the
   literal eq. 2 residuals beside it (``residuals_eq2_rad``, ``sigma_eq2_rad``).
   sigma_i = sqrt(sum e_i^2 / (N - M - 2)) (least-squares degrees of freedom; 003 divides by N),
   pooled over segments; robust sigma = 1.4826 MAD with the same dof factor. The dof factor is
   right for white noise only: real motion above the cutoff is not absorbed by the fit, so the
   raw figure ``sigma_smoothing`` (003 §1.4, motion included) is, with gyro data,
   sqrt(sigma^2 + sum(e_raw^2 - e^2)/N) (noise dof-corrected, removed motion per sample), and
   without gyro data sqrt(sum e_raw^2 / (N - M - 2)).
   3b (processing.star_tracker.whiteness): a spectral test of the residuals above the cutoff (flat for
   white noise, falling for time-correlated noise that the harmonics partly absorb), the sigma above
   the cutoff sqrt(sum e^2 / N) beside sigma, a lower bound of sigma for red noise, and a chi-square
   95 % interval of each sigma with the least-squares dof (the effective dof from the residual
   autocorrelation when the test fails).
4. Angular velocity of the sensor from the smoothed z(t) and its analytic derivative (003 §1.3):
   w_S = 4/(1 + z.z)^2 [(1 - z.z) z' - 2 z x z' + 2 (z.z') z], and w_B = dcm_BS w_S (003 §1.1).
5. Gyro (003 §1.4): body rates w_B = dcm_BG w_G smoothed by the same series with the same cutoff
   frequency (harmonics M over the same interval), constant offsets removed by matching the mean of
   the smoothed gyro to the mean of the star-tracker rates, rms difference per axis; the
   difference expected from the star-tracker noise (propagated through the fit's derivative) and
   the gyro noise is reported beside it. A segment uses the gyro only when the gyro covers it at the
   star tracker's rate (processing.star_tracker.gyro_coverage: rate, samples per parameter); the
   notes name the failed criterion, its value and threshold for the others.
6. Spectra (003 §1.5, processing.signal.spectral): amplitude spectra of the gyro rates, of the
   star-tracker rates and of the star-tracker residuals; lines above the smoother's cutoff
   M/(2T) detected with a false-alarm threshold, with the attitude amplitude A/(2 pi f), its rms
   A/(2 pi f sqrt 2) and the frequency at which the line appears in the star-tracker samples
   (aliasing: 0.4 Hz at 3 s -> 0.0667 Hz).
7. Separating real motion from sensor noise (003 §1.5: the mirror vibration makes the estimate
   "somewhat overestimated"; the paper compares per-axis rms contributions by hand). With gyro
   data, each gyro line above the cutoff is fitted (common frequency, amplitude and phase per body
   axis) to the gyro smoothing residuals; its integral is the attitude oscillation theta_B(t), which
   is turned into sensor axes (theta_S = dcm_SB theta_B, with the phases, unlike 003's amplitude-
   only bookkeeping) and removed from the measurements, q_n' = q_n o exp(-theta_S(t_n)); the
   corrected quaternions are smoothed again and their residual std is ``sigma_rad``, the sensor's
   own noise. Without gyro data nothing is removed (a line in the star-tracker residuals could be
   the sensor's own periodic error), and ``sigma_rad`` equals ``sigma_smoothing_rad``. Only lines
   are removed: broadband real motion above the cutoff (none in the seed-003 model) would stay in.
   A gyro line is removed only when the star-tracker residuals contain it (coherence regression,
   processing.star_tracker.accuracy_gyro.line_coherence); a line in the gyro only is kept out.
8. Harmonic count M (003 §1.5 chose it by eye from the spectra): automatic as 2 x the minimiser of
   generalised cross-validation of the three z_i jointly, capped at (N - 2)/4 (half the
   star-tracker Nyquist frequency). Why twice: GCV balances truncation against noise for
   *prediction*; for the *noise estimate* the slow motion must be followed to well below the noise.
   The sine coefficients of a generic smooth motion decay as m^-3 (the odd extension of the
   detrended motion has a jump in its second derivative at the ends), so the part left beyond M
   carries ~M b_M^2/10 of variance; at the GCV optimum b_M is about the per-coefficient noise,
   which leaves a few % of sigma^2 (measured: +3 to +10 % on sigma_1 with the 003 noise), and
   doubling M divides that by ~2^5 while costing only M more degrees of freedom. With gyro data M
   is chosen on the corrected quaternions. ``harmonics=`` overrides it.

Inputs: times int64 TAI ns, quaternions scalar first (q_IS: sensor -> inertial), rates rad/s. SI
inside; arcseconds only in the job layer. Vectorised over samples; loops only over segments, axes
and lines. Layout: the 003 §1.3 building blocks are in processing.star_tracker.smoothing, steps 5 and
7 in processing.star_tracker.accuracy_gyro, the residuals and sigmas of steps 3-4 (and the final smoothing
of step 7) in processing.star_tracker.accuracy_residuals; here one function per step, each returning a frozen
record.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.signal.sine_series import Method
from processing.signal.spectral import Spectrum, alias_frequency, amplitude_spectrum_of_samples
from processing.signal.spectral_lines import find_lines
from processing.star_tracker.accuracy_gyro import (
    GyroAnalysis,
    GyroComparison,
    LineCoherence,
    SpectralLine,
    analyze_gyro,
    gyro_comparison,
)
from processing.star_tracker.accuracy_residuals import (
    Residuals,
    SegmentFit,
    correct_segment,
    pool_residuals,
    pooled_sigmas,
)
from processing.star_tracker.gyro_coverage import GyroCoverage, coverage_notes, segment_gyro_coverage
from processing.star_tracker.robust import OUTLIER_ALPHA, OutlierRejection, reject_outliers
from processing.star_tracker.smoothing import (
    SegmentSmoothing,
    seconds_since,
    smooth_segment,
    split_segments,
)
from processing.star_tracker.whiteness import ResidualSeries, Whiteness, sigma_interval, whiteness_test
from processing.tasks import Mapper, Progress, serial_map
from processing.units import NS_PER_S

__all__ = [
    "SegmentFit",
    "StarTrackerAccuracy",
    "StarTrackerAccuracyError",
    "analyze_star_tracker_accuracy",
]

MIN_SEGMENT_SAMPLES = 12


class StarTrackerAccuracyError(ValueError):
    """Inputs that do not allow the 003 §1 analysis: shapes, too few samples, bad harmonics."""


def _noop(fraction: float, stage: str) -> None:
    return None


# ---------------------------------------------------------------------------------------------
# Results


@dataclass(frozen=True)
class StarTrackerAccuracy:
    """Result of :func:`analyze_star_tracker_accuracy`. Angles rad, rates rad/s, times TAI ns.

    Per star-tracker sample (N rows): time_tai_ns, segment (index into segments), z and z_fit
    (003 §1.3, raw data), residuals_smoothing_rad (about x1 x2 x3, raw: the paper's e_i with the
    real motion in), residuals_eq2_rad (003 eq. 2 literally), residuals_rad (after removing the
    real motion the gyros see; = raw without gyro), motion_rad (the removed attitude oscillation
    about x1 x2 x3), w_S_rad_s / w_B_rad_s (rates from the final smoothing), outlier (bool: rejected,
    not used in any fit or sigma).
    Per axis (3,): sigma_rad (sensor noise), sigma_smoothing_rad (003's figure),
    sigma_robust_rad (MAD, of residuals_rad), sigma_smoothing_robust_rad, sigma_eq2_rad,
    motion_rms_rad (rms of motion_rad). harmonics: M of each segment. gyro: comparison or None.
    lines, spectra ("gyro", "star_tracker_rate", "star_tracker_residuals"), notes.
    Robustness (issue 17): outlier_threshold (rejection radius in robust sigmas), outlier_scale_rad (3,)
    the robust scale; whiteness (the spectral test); sigma_above_cutoff_rad (3,) sqrt(rss / n);
    sigma_lower_bound_rad (3,) (>= sigma_rad; above it only when the test finds red noise);
    sigma_dof (3,) the dof of the interval (effective when correlated), sigma_ci95_rad (3, 2);
    line_coherence: each gyro line against the star tracker (removed or not).
    gyro_coverage: per segment whether the gyro covers it and, if not, the failed criterion with its value
    and threshold (processing.star_tracker.gyro_coverage; empty without gyro data).
    """

    time_tai_ns: NDArray
    segment: NDArray
    z: NDArray
    z_fit: NDArray
    residuals_smoothing_rad: NDArray
    residuals_eq2_rad: NDArray
    residuals_rad: NDArray
    motion_rad: NDArray
    w_S_rad_s: NDArray
    w_B_rad_s: NDArray
    sigma_rad: NDArray
    sigma_smoothing_rad: NDArray
    sigma_robust_rad: NDArray
    sigma_smoothing_robust_rad: NDArray
    sigma_eq2_rad: NDArray
    motion_rms_rad: NDArray
    outlier: NDArray
    outlier_threshold: float
    outlier_scale_rad: NDArray
    whiteness: Whiteness
    sigma_above_cutoff_rad: NDArray
    sigma_lower_bound_rad: NDArray
    sigma_dof: NDArray
    sigma_ci95_rad: NDArray
    line_coherence: tuple[LineCoherence, ...]
    segments: tuple[SegmentFit, ...]
    sample_period_s: float
    gyro: GyroComparison | None
    lines: tuple[SpectralLine, ...]
    spectra: dict[str, Spectrum]
    notes: tuple[str, ...] = field(default=())
    gyro_coverage: tuple[GyroCoverage, ...] = field(default=())

    @property
    def n_outliers(self) -> int:
        return int(np.count_nonzero(self.outlier))

    @property
    def harmonics(self) -> list[int]:
        """Harmonic count M of each segment."""
        return [s.harmonics for s in self.segments]


# ---------------------------------------------------------------------------------------------
# The steps (module docstring), each returning a frozen record


@dataclass(frozen=True)
class _Inputs:
    """Checked star-tracker inputs: times (N,) int64, unit q_IS (N, 4), dcm_BS (3, 3), median period [s]."""

    t_ns: NDArray
    q: NDArray
    dcm_BS: NDArray
    sample_period_s: float


def _check_inputs(time_tai_ns: ArrayLike, q_IS: ArrayLike, q_BS: ArrayLike, harmonics: int | None) -> _Inputs:
    t_ns = np.asarray(time_tai_ns)
    if t_ns.ndim != 1 or not np.issubdtype(t_ns.dtype, np.integer):
        raise StarTrackerAccuracyError(f"time_tai_ns must be 1-D int64 nanoseconds, got {t_ns.dtype} {t_ns.shape}")
    t_ns = t_ns.astype(np.int64)
    q = np.asarray(q_IS, dtype=np.float64)
    if q.shape != (t_ns.size, 4):
        raise StarTrackerAccuracyError(f"q_IS must have shape ({t_ns.size}, 4) to match time_tai_ns, got {q.shape}")
    if np.any(np.diff(t_ns) <= 0):
        raise StarTrackerAccuracyError("time_tai_ns must be strictly increasing (sort and de-duplicate first)")
    if not np.all(np.isfinite(q)):
        raise StarTrackerAccuracyError("q_IS contains non-finite values")
    q = rotations.quat_normalize(q)
    dcm_BS = rotations.quat_to_dcm(rotations.quat_normalize(np.asarray(q_BS, dtype=np.float64)))
    if harmonics is not None and (isinstance(harmonics, bool) or int(harmonics) != harmonics or harmonics < 0):
        raise StarTrackerAccuracyError(f"harmonics must be None or an integer >= 0, got {harmonics!r}")
    sample_period_s = float(np.median(np.diff(t_ns))) / NS_PER_S if t_ns.size > 1 else float("nan")
    return _Inputs(t_ns, q, dcm_BS, sample_period_s)


@dataclass(frozen=True)
class _Segments:
    """Steps 1-2b: the smoothed segments (without their outliers), the rejection, and the notes about
    skipped or strongly turning ones."""

    segments: tuple[SegmentSmoothing, ...]
    notes: tuple[str, ...]
    rejection: OutlierRejection


def _smooth_part(part: tuple[slice, NDArray, int, NDArray, int | None, Method]) -> SegmentSmoothing:
    """One segment's steps 1-2 (a part for the mapper): :func:`smooth_segment` of its arguments."""
    return smooth_segment(*part)


def _smooth_segments(
    inp: _Inputs, harmonics: int | None, segment_max_s: float, max_gap_s: float, method: Method,
    outlier_alpha: float, mapper: Mapper = serial_map,
) -> _Segments:
    """Steps 1-2b: segments, mean quaternion, residual MRPs, raw smoothing (003 §1.3), outliers; the
    segments' smoothings through ``mapper`` (independent; same results on any mapper)."""
    t_ns = inp.t_ns
    parts: list[tuple[slice, NDArray, int, NDArray, int | None, Method]] = []
    notes: list[str] = []
    for sl in split_segments(t_ns, segment_max_s, max_gap_s):
        n = sl.stop - sl.start
        if n < MIN_SEGMENT_SAMPLES:
            notes.append(f"skipped {n} samples from row {sl.start}: a segment needs {MIN_SEGMENT_SAMPLES}")
            continue
        if harmonics is not None and harmonics > n - 2:
            raise StarTrackerAccuracyError(
                f"harmonics must be <= N - 2 = {n - 2} for a segment of {n} samples, got {harmonics}"
            )
        t0_ns = int(t_ns[sl.start])
        parts.append((sl, seconds_since(t_ns[sl], t0_ns), t0_ns, inp.q[sl], harmonics, method))
    segments: list[SegmentSmoothing] = mapper(_smooth_part, parts)
    for seg in segments:
        if np.max(np.linalg.norm(seg.z, axis=-1)) > 0.5:
            notes.append(
                f"segment from row {seg.sl.start} turns by more than 4 atan(0.5) ~ 106 deg from its mean: "
                "the small-z approximation of 003 §1.3 is poor; shorten segment_max_s"
            )
    if not segments:
        raise StarTrackerAccuracyError(
            f"no segment with at least {MIN_SEGMENT_SAMPLES} star-tracker samples (got {t_ns.size} samples)"
        )
    rejection = reject_outliers(segments, method, alpha=outlier_alpha)
    if not rejection.converged:
        notes.append(f"outlier rejection stopped after {rejection.iterations} iterations without a fixed point")
    return _Segments(rejection.segments, tuple(notes), rejection)


def _gyro_rates(gyro_time_tai_ns: ArrayLike, w_G_rad_s: ArrayLike, q_BG: ArrayLike) -> tuple[NDArray, NDArray]:
    """Checked gyro times (K,) int64 and the rates in the body frame (K, 3) rad/s."""
    g_ns = np.asarray(gyro_time_tai_ns).astype(np.int64)
    w_G = np.asarray(w_G_rad_s, dtype=np.float64)
    if w_G.shape != (g_ns.size, 3):
        raise StarTrackerAccuracyError(f"w_G_rad_s must have shape ({g_ns.size}, 3), got {w_G.shape}")
    if np.any(np.diff(g_ns) <= 0):
        raise StarTrackerAccuracyError("gyro_time_tai_ns must be strictly increasing")
    return g_ns, rotations.quat_rotate(rotations.quat_normalize(np.asarray(q_BG, dtype=np.float64)), w_G)



@dataclass(frozen=True)
class _Spectra:
    """Step 6: the amplitude spectra and the star-tracker residual lines."""

    spectra: dict[str, Spectrum]
    lines: tuple[SpectralLine, ...]


def _spectra(
    inp: _Inputs, res: Residuals, w_B: NDArray, gyro: GyroAnalysis | None, cmp: GyroComparison | None,
    cutoff_hz: float, line_false_alarm: float,
) -> _Spectra:
    """Step 6 (003 §1.5): spectra of the gyro rates, star-tracker rates and residuals; residual lines
    above the cutoff, marked as removed when at the alias of a gyro line removed from the star tracker.
    Accepted samples only."""
    t_ns, rows = inp.t_ns, res.ok
    spectra: dict[str, Spectrum] = {}
    t_rows = seconds_since(t_ns[rows], int(t_ns[rows[0]]))
    spectra["star_tracker_residuals"] = amplitude_spectrum_of_samples(t_rows, res.e_raw[rows], oversample=2)
    if gyro is not None and cmp is not None:
        spectra["gyro"] = amplitude_spectrum_of_samples(
            seconds_since(gyro.time_tai_ns, int(gyro.time_tai_ns[0])), gyro.w_B_rad_s)
        spectra["star_tracker_rate"] = amplitude_spectrum_of_samples(
            seconds_since(cmp.time_tai_ns, int(cmp.time_tai_ns[0])), cmp.w_B_star_tracker_rad_s
        )
    else:
        spectra["star_tracker_rate"] = amplitude_spectrum_of_samples(t_rows, w_B[rows])
    line_fits = gyro.removed_fits if gyro is not None else ()
    gyro_aliases = [float(alias_frequency(lf.freq_hz, inp.sample_period_s)) for lf in line_fits]
    st_res = spectra["star_tracker_residuals"].resolution_hz
    found, _ = find_lines(t_rows, res.e_raw[rows], min_freq_hz=cutoff_hz, false_alarm=line_false_alarm)
    lines = []
    for line in found:
        sf = line.fit
        removed = any(abs(sf.freq_hz - a) <= 2 * st_res for a in gyro_aliases)
        for k in line.components:
            amp = float(sf.amplitude[k])
            lines.append(SpectralLine(
                "star_tracker", f"x{k + 1}", sf.freq_hz, None, amp, amp / np.sqrt(2.0), sf.freq_hz, removed,
            ))
    return _Spectra(spectra, tuple(lines))


@dataclass(frozen=True)
class _Quality:
    """Step 3b per axis (3,): the whiteness test, sigma above the cutoff, the lower bound of sigma, the
    dof of its interval and the 95 % interval (3, 2) rad."""

    whiteness: Whiteness
    above: NDArray
    lower: NDArray
    dof: NDArray
    ci95: NDArray


def _quality(inp: _Inputs, res: Residuals, sigma: NDArray, lines: tuple[SpectralLine, ...]) -> _Quality:
    """Step 3b (processing.star_tracker.whiteness) on the corrected residuals of the accepted samples,
    star-tracker residual lines left out of the test band."""
    series = []
    for s in res.segments:
        sl = slice(s.start, s.stop)
        series.append(ResidualSeries(seconds_since(inp.t_ns[sl], int(inp.t_ns[s.start])), res.e_cor[sl],
                                     ~res.outlier[sl], s.cutoff_hz))
    wt = whiteness_test(series, inp.sample_period_s, [x.freq_hz for x in lines if x.source == "star_tracker"])
    rss = np.sum([s.rss_rad2 for s in res.segments], axis=0)
    above = np.sqrt(rss / res.ok.size)
    dof = np.full(3, float(res.dof_cor)) * (wt.dof_factor if wt.correlated else 1.0)
    lower = sigma.copy()
    if wt.correlated:
        n_low, n_high = wt.dof_low / 2.0, wt.dof_high / 2.0
        r = np.maximum(wt.ratio * (n_low + n_high) / (wt.ratio * n_low + n_high), 1.0)  # lower half / band level
        n_seg = np.array([s.stop - s.start for s in res.segments], dtype=float)
        f_c = float(np.average([s.cutoff_hz for s in res.segments], weights=n_seg))
        f_nyq = 0.5 / inp.sample_period_s
        lower = np.maximum(sigma, above * np.sqrt(1.0 + r * f_c / max(f_nyq - f_c, 1e-12)))
    return _Quality(wt, above, lower, dof, sigma_interval(sigma, dof))


# ---------------------------------------------------------------------------------------------
# The analysis


def analyze_star_tracker_accuracy(
    time_tai_ns: ArrayLike,
    q_IS: ArrayLike,
    q_BS: ArrayLike,
    *,
    gyro_time_tai_ns: ArrayLike | None = None,
    w_G_rad_s: ArrayLike | None = None,
    q_BG: ArrayLike = (1.0, 0.0, 0.0, 0.0),
    harmonics: int | None = None,
    segment_max_s: float = 1200.0,
    max_gap_s: float = 120.0,
    method: Method = "auto",
    line_false_alarm: float = 1e-3,
    outlier_alpha: float = OUTLIER_ALPHA,
    progress: Progress | None = None,
    mapper: Mapper = serial_map,
) -> StarTrackerAccuracy:
    """Accuracy of a star tracker from its own quaternions, with gyro rates when given (003 §1.3-1.5).

    time_tai_ns (N,) int64 increasing; q_IS (N, 4) sensor -> inertial, scalar first; q_BS (4,) the
    mounting (v_B = q_BS o v_S o q_BS^-1). Optional gyro: gyro_time_tai_ns (K,), w_G_rad_s (K, 3) in
    the gyro frame, q_BG (4,). harmonics: M for every segment, or None for the automatic choice.
    segment_max_s, max_gap_s [s]: segmentation; method: "auto" | "dst" | "lstsq" for the smoother;
    line_false_alarm: false-alarm probability of the line detector per spectrum and axis;
    outlier_alpha: probability that clean data lose a sample to the outlier rejection (0: none rejected).
    mapper: how the independent per-segment smoothings (star tracker, gyro) run (processing.tasks.Mapper;
    e.g. across a cluster's workers); the results do not depend on it.
    See the module docstring for every step. Returns :class:`StarTrackerAccuracy`.
    """
    report = progress or _noop
    inp = _check_inputs(time_tai_ns, q_IS, q_BS, harmonics)
    smoothed = _smooth_segments(inp, harmonics, segment_max_s, max_gap_s, method, outlier_alpha, mapper)  # 1-2b
    segments, notes = smoothed.segments, list(smoothed.notes)
    report(0.3, "smoothing")
    cutoff_hz = max(seg.fit_raw.cutoff_hz for seg in segments)
    gyro: GyroAnalysis | None = None
    coverage: tuple[GyroCoverage, ...] = ()
    if gyro_time_tai_ns is not None and w_G_rad_s is not None:  # 5, 7
        g_ns, w_B_gyro = _gyro_rates(gyro_time_tai_ns, w_G_rad_s, q_BG)
        coverage = tuple(segment_gyro_coverage(s.sl.start, s.sl.stop, inp.t_ns, g_ns, s.fit_raw.harmonics)
                         for s in segments)
        notes += coverage_notes(coverage)
        gyro = analyze_gyro(segments, [c.idx if c.used else None for c in coverage], g_ns, w_B_gyro, inp.dcm_BS,
                            cutoff_hz, inp.sample_period_s, line_false_alarm, smoothed.rejection.scale_rad, mapper)
    report(0.5, "gyro lines")
    motion = gyro.motion_S if gyro is not None else tuple(np.zeros((s.sl.stop - s.sl.start, 3)) for s in segments)
    corrected = tuple(correct_segment(seg, m) for seg, m in zip(segments, motion, strict=True))
    report(0.6, "corrected smoothing")
    res = pool_residuals(inp.t_ns.size, corrected)  # 3-4
    if res.dof_cor <= 0:
        raise StarTrackerAccuracyError("no residual degrees of freedom: fewer harmonics are needed")
    sig = pooled_sigmas(res, gyro is not None)
    w_B = res.w_S @ inp.dcm_BS.T
    if gyro is None:
        notes.append(f"{'without the gyro' if coverage else 'no gyro data'}: the residual std includes any real motion "
                     "the series cannot follow")
    report(0.7, "residuals")
    cmp = None if gyro is None else gyro_comparison(  # 5
        segments, [c.fit for c in corrected], gyro.fits, gyro.time_tai_ns, gyro.w_B_rad_s, inp.dcm_BS, sig.sigma,
        gyro.lines.fits, mapper, gyro.line_sines,
    )
    if gyro is not None and cmp is None:
        notes.append("gyro comparison left out: the final harmonic count needs more gyro samples than any segment has")
    spec = _spectra(inp, res, w_B, gyro, cmp, cutoff_hz, line_false_alarm)  # 6
    quality = _quality(inp, res, sig.sigma, spec.lines)  # 3b
    report(0.9, "spectra")
    return StarTrackerAccuracy(
        time_tai_ns=inp.t_ns, segment=res.segment, z=res.z, z_fit=res.z_fit, residuals_smoothing_rad=res.e_raw,
        residuals_eq2_rad=res.e_eq2, residuals_rad=res.e_cor, motion_rad=res.motion, w_S_rad_s=res.w_S,
        w_B_rad_s=w_B, sigma_rad=sig.sigma, sigma_smoothing_rad=sig.smoothing, sigma_robust_rad=sig.robust,
        sigma_smoothing_robust_rad=sig.smoothing_robust, sigma_eq2_rad=sig.eq2, motion_rms_rad=sig.motion_rms,
        outlier=res.outlier, outlier_threshold=smoothed.rejection.threshold,
        outlier_scale_rad=smoothed.rejection.scale_rad, whiteness=quality.whiteness,
        sigma_above_cutoff_rad=quality.above, sigma_lower_bound_rad=quality.lower, sigma_dof=quality.dof,
        sigma_ci95_rad=quality.ci95, line_coherence=gyro.coherence if gyro is not None else (),
        segments=res.segments, sample_period_s=inp.sample_period_s, gyro=cmp, gyro_coverage=coverage,
        lines=(gyro.lines.lines if gyro is not None else ()) + spec.lines, spectra=spec.spectra, notes=tuple(notes),
    )
