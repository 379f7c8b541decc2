"""Star-tracker accuracy from flight data: Rodrigues-parameter smoothing and spectra (003 §1.3-1.5).

Method (003 = Avanesov et al., Keldysh Institute preprint 74, 2010):

1. Segments of at most ``segment_max_s`` (003: under 20 min), split at gaps longer than
   ``max_gap_s``. In each, the mean quaternion q_c = Q/|Q|, Q = sum q_n (003 §1.3, after putting
   every q_n in the hemisphere of its predecessor) and the residual Rodrigues parameters (MRPs)
   z^(n) of q_c^-1 o q_n.
2. Each z_i is smoothed by the sine series plus linear trend of 003 §1.3 (processing.signal.sine_series:
   DST route without gaps, QR least squares with gaps).
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
4. Angular velocity of the sensor from the smoothed z(t) and its analytic derivative (003 §1.3):
   w_S = 4/(1 + z.z)^2 [(1 - z.z) z' - 2 z x z' + 2 (z.z') z], and w_B = dcm_BS w_S (003 §1.1).
5. Gyro (003 §1.4): body rates w_B = dcm_BG w_G smoothed by the same series with the same cutoff
   frequency (harmonics M over the same interval), constant offsets removed by matching the mean of
   the smoothed gyro to the mean of the star-tracker rates, rms difference per axis; the
   difference expected from the star-tracker noise (propagated through the fit's derivative) and
   the gyro noise is reported beside it.
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
and lines.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.signal.sine_series import SineSeriesFit, SineSeriesSolver, fit_sine_series
from processing.signal.spectral import (
    SinusoidFit,
    Spectrum,
    alias_frequency,
    amplitude_spectrum_of_samples,
    find_lines,
    fit_sinusoids,
    separable_frequencies,
)
from processing.tasks import Progress
from processing.units import NS_PER_S

__all__ = [
    "GyroComparison",
    "SegmentFit",
    "SpectralLine",
    "StarTrackerAccuracy",
    "StarTrackerAccuracyError",
    "analyze_star_tracker_accuracy",
    "auto_harmonics",
    "mean_quaternion",
    "rate_from_mrp",
    "residual_mrps",
    "sensor_axis_residuals",
    "split_segments",
]

MAD_TO_SIGMA = 1.482602218505602
"""1 / Phi^-1(3/4): MAD of a normal sample times this is its standard deviation."""
MIN_SEGMENT_SAMPLES = 12
GCV_FACTOR = 2
"""Automatic M = GCV_FACTOR x the GCV minimiser (module docstring, item 8)."""




class StarTrackerAccuracyError(ValueError):
    """Inputs that do not allow the 003 §1 analysis: shapes, too few samples, bad harmonics."""


def _noop(fraction: float, stage: str) -> None:
    return None


# ---------------------------------------------------------------------------------------------
# Building blocks (003 §1.3)


def mean_quaternion(q: ArrayLike) -> NDArray:
    """q_c = Q / |Q|, Q = sum_n q_n (003 §1.3), after sign-aligning each q_n with its predecessor.

    q: (N, 4) unit quaternions along a continuous motion. Returns (4,) canonical.
    """
    qq = rotations.quat_normalize(np.asarray(q, dtype=np.float64))
    flips = np.concatenate([[1.0], np.sign(np.sum(qq[1:] * qq[:-1], axis=-1))])
    flips[flips == 0] = 1.0
    return rotations.quat_canonical(rotations.quat_normalize(np.sum(qq * np.cumprod(flips)[:, None], axis=0)))


def residual_mrps(q: ArrayLike, q_c: ArrayLike) -> NDArray:
    """Rodrigues parameters z^(n) (N, 3) of q_c^-1 o q_n (003 §1.3; z = vector / (1 + scalar))."""
    return rotations.quat_to_mrp(rotations.quat_multiply(rotations.quat_conjugate(q_c), q))


def rate_from_mrp(z: ArrayLike, z_dot: ArrayLike) -> NDArray:
    """Angular velocity from MRPs and their rate (003 §1.3, last formula; 000 eq. for w):

    w = 4/(1 + z.z)^2 [(1 - z.z) z' - 2 z x z' + 2 (z.z') z], in the rotating frame (for
    q = q_c o s(z): q' = 1/2 q o w). z, z_dot: (..., 3) [1, 1/s]. Returns (..., 3) rad/s.
    """
    z = np.asarray(z, dtype=np.float64)
    zd = np.asarray(z_dot, dtype=np.float64)
    zz = np.sum(z * z, axis=-1, keepdims=True)
    zzd = np.sum(z * zd, axis=-1, keepdims=True)
    return 4.0 / (1.0 + zz) ** 2 * ((1.0 - zz) * zd - 2.0 * np.cross(z, zd) + 2.0 * zzd * z)


def sensor_axis_residuals(z: ArrayLike, z_fit: ArrayLike) -> NDArray:
    """Rotation vector (N, 3) rad of s(z_fit)^-1 o s(z): the measurement error about the sensor axes.

    To first order in z this is 003 eq. 2, e = 4 (z - z_fit) (module docstring, item 3).
    """
    return rotations.quat_to_rotvec(
        rotations.quat_multiply(rotations.quat_conjugate(rotations.mrp_to_quat(z_fit)), rotations.mrp_to_quat(z))
    )


def _auto(solver: SineSeriesSolver, z: NDArray) -> int:
    path = solver.path(z)
    return int(min(GCV_FACTOR * path.select("gcv"), path.harmonics[-1]))


def auto_harmonics(t_s: ArrayLike, z: ArrayLike, *, max_harmonics: int | None = None) -> int:
    """Automatic harmonic count: min(GCV_FACTOR x argmin GCV, cap), cap = (N - 2) // 4 by default
    (and at most the last harmonic the samples determine).

    t_s (N,) [s], z (N, K) jointly (module docstring, item 8).
    """
    n = np.asarray(t_s).size
    cap = (n - 2) // 4 if max_harmonics is None else min(max_harmonics, n - 2)
    return _auto(SineSeriesSolver(t_s, cap), np.asarray(z, dtype=np.float64))


def split_segments(time_tai_ns: ArrayLike, segment_max_s: float, max_gap_s: float) -> list[slice]:
    """Index slices of segments: split at gaps > max_gap_s, then each run into equal-duration
    pieces of at most segment_max_s (003 §1.3: segments under 20 min). time_tai_ns sorted (N,)."""
    t = np.asarray(time_tai_ns, dtype=np.int64)
    cuts = np.flatnonzero(np.diff(t) > max_gap_s * NS_PER_S) + 1
    bounds = np.concatenate([[0], cuts, [t.size]])
    out = []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        span_s = (t[b - 1] - t[a]) / NS_PER_S
        pieces = max(1, int(np.ceil(span_s / segment_max_s - 1e-9)))
        edges = t[a] + np.round(np.arange(1, pieces) * (t[b - 1] - t[a]) / pieces).astype(np.int64)
        inner = a + np.searchsorted(t[a:b], edges, side="left")
        idx = np.concatenate([[a], inner, [b]])
        out += [slice(int(i), int(j)) for i, j in zip(idx[:-1], idx[1:], strict=True) if j > i]
    return out


# ---------------------------------------------------------------------------------------------
# Results


@dataclass(frozen=True)
class SegmentFit:
    """One smoothed segment: rows [start, stop) of the star-tracker samples, its harmonics and
    cutoff M/(2T) [Hz], fit route, span [s], dof = N - M - 2, residual sums of squares [rad^2]
    about x1 x2 x3 raw (rss_smoothing) and after removing real motion (rss), and the mean
    quaternion q_c of 003 §1.3."""

    start: int
    stop: int
    harmonics: int
    cutoff_hz: float
    method: str
    span_s: float
    dof: int
    rss_smoothing_rad2: NDArray
    rss_rad2: NDArray
    q_c: NDArray


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
class StarTrackerAccuracy:
    """Result of :func:`analyze_star_tracker_accuracy`. Angles rad, rates rad/s, times TAI ns.

    Per star-tracker sample (N rows): time_tai_ns, segment (index into segments), z and z_fit
    (003 §1.3, raw data), residuals_smoothing_rad (about x1 x2 x3, raw: the paper's e_i with the
    real motion in), residuals_eq2_rad (003 eq. 2 literally), residuals_rad (after removing the
    real motion the gyros see; = raw without gyro), motion_rad (the removed attitude oscillation
    about x1 x2 x3), w_S_rad_s / w_B_rad_s (rates from the final smoothing).
    Per axis (3,): sigma_rad (sensor noise), sigma_smoothing_rad (003's figure),
    sigma_robust_rad (MAD, of residuals_rad), sigma_smoothing_robust_rad, sigma_eq2_rad,
    motion_rms_rad (rms of motion_rad). harmonics: M of each segment. gyro: comparison or None.
    lines, spectra ("gyro", "star_tracker_rate", "star_tracker_residuals"), notes.
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
    segments: tuple[SegmentFit, ...]
    sample_period_s: float
    gyro: GyroComparison | None
    lines: tuple[SpectralLine, ...]
    spectra: dict[str, Spectrum]
    notes: tuple[str, ...] = field(default=())

    @property
    def harmonics(self) -> list[int]:
        """Harmonic count M of each segment."""
        return [s.harmonics for s in self.segments]


# ---------------------------------------------------------------------------------------------
# Helpers


def _pooled(rss: NDArray, dof: int) -> NDArray:
    return np.sqrt(rss / dof) if dof > 0 else np.full(3, np.nan)


def _robust(resid: NDArray, n: int, dof: int) -> NDArray:
    if dof <= 0:
        return np.full(3, np.nan)
    mad = np.median(np.abs(resid - np.median(resid, axis=0)), axis=0)
    return MAD_TO_SIGMA * mad * np.sqrt(n / dof)


def _seconds(t_ns: NDArray, t0_ns: int) -> NDArray:
    return (t_ns - np.int64(t0_ns)).astype(np.float64) / NS_PER_S


@dataclass
class _Segment:
    sl: slice
    t_s: NDArray  # seconds since the segment's first sample
    t0_ns: int
    q: NDArray
    q_c: NDArray
    z: NDArray
    solver: SineSeriesSolver  # one factorisation for the raw and the corrected fits
    auto: bool
    fit_raw: SineSeriesFit
    fit: SineSeriesFit | None = None
    z_corr: NDArray | None = None
    motion_S: NDArray | None = None
    gyro_idx: NDArray | None = None

    def smooth(self, z: NDArray) -> SineSeriesFit:
        return _smooth(self.solver, z, self.auto)


def _smooth(solver: SineSeriesSolver, z: NDArray, auto: bool) -> SineSeriesFit:
    return solver.fit(z, _auto(solver, z) if auto else solver.max_harmonics)


def _segment(
    sl: slice, t_s: NDArray, t0_ns: int, q: NDArray, harmonics: int | None, method: str
) -> _Segment:
    n = t_s.size
    if harmonics is not None and harmonics > n - 2:
        raise StarTrackerAccuracyError(
            f"harmonics must be <= N - 2 = {n - 2} for a segment of {n} samples, got {harmonics}"
        )
    q_c = mean_quaternion(q)
    z = residual_mrps(q, q_c)
    top = (n - 2) // 4 if harmonics is None else harmonics
    solver = SineSeriesSolver(t_s, top, method=method)  # type: ignore[arg-type]
    return _Segment(sl, t_s, t0_ns, q, q_c, z, solver, harmonics is None, _smooth(solver, z, harmonics is None))


def _segment_lines(line_fits: list[SinusoidFit], t_s: NDArray) -> NDArray:
    """Frequencies of the lines that a stretch of times t_s (s) can separate (strongest first)."""
    if not line_fits:
        return np.zeros(0)
    weights = [float(np.sum(lf.amplitude**2)) for lf in line_fits]
    return separable_frequencies([lf.freq_hz for lf in line_fits], weights, 1.0 / float(t_s[-1] - t_s[0]))


def _rate_noise_factor(seg: _Segment) -> float:
    """Time average of v(t) = d(t)^T (A^T A)^-1 d(t) over the segment, so that the fitted rates have
    mean variance sigma_i^2 v (A: the design at the samples, d: the time derivative of the basis).

    For times spread uniformly over the span, the average of d d^T is diag(0, 1/T^2, (pi m/T)^2/2)
    (the cosines are orthogonal on [0, T]), hence v = G_11/T^2 + sum_m G_mm (pi m/T)^2/2 with
    G = (A^T A)^-1 (:meth:`SineSeriesSolver.covariance_diag`).
    """
    fit = seg.fit
    assert fit is not None
    g_diag = seg.solver.covariance_diag(fit.harmonics)
    m = np.arange(1, fit.harmonics + 1, dtype=np.float64)
    weights = np.concatenate([[0.0, 1.0], 0.5 * (np.pi * m) ** 2]) / fit.span_s**2
    return float(np.sum(g_diag * weights))


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
    method: str = "auto",
    line_false_alarm: float = 1e-3,
    progress: Progress | None = None,
) -> StarTrackerAccuracy:
    """Accuracy of a star tracker from its own quaternions, with gyro rates when given (003 §1.3-1.5).

    time_tai_ns (N,) int64 increasing; q_IS (N, 4) sensor -> inertial, scalar first; q_BS (4,) the
    mounting (v_B = q_BS o v_S o q_BS^-1). Optional gyro: gyro_time_tai_ns (K,), w_G_rad_s (K, 3) in
    the gyro frame, q_BG (4,). harmonics: M for every segment, or None for the automatic choice.
    segment_max_s, max_gap_s [s]: segmentation; method: "auto" | "dst" | "lstsq" for the smoother;
    line_false_alarm: false-alarm probability of the line detector per spectrum and axis.
    See the module docstring for every step. Returns :class:`StarTrackerAccuracy`.
    """
    report = progress or _noop
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
    notes: list[str] = []
    sample_period_s = float(np.median(np.diff(t_ns))) / NS_PER_S if t_ns.size > 1 else float("nan")

    # 1-2. Segments, mean quaternion, residual MRPs, raw smoothing.
    segments: list[_Segment] = []
    for sl in split_segments(t_ns, segment_max_s, max_gap_s):
        n = sl.stop - sl.start
        if n < MIN_SEGMENT_SAMPLES:
            notes.append(f"skipped {n} samples from row {sl.start}: a segment needs {MIN_SEGMENT_SAMPLES}")
            continue
        tt = _seconds(t_ns[sl], int(t_ns[sl.start]))
        seg = _segment(sl, tt, int(t_ns[sl.start]), q[sl], harmonics, method)
        if np.max(np.linalg.norm(seg.z, axis=-1)) > 0.5:
            notes.append(
                f"segment from row {sl.start} turns by more than 4 atan(0.5) ~ 106 deg from its mean: "
                "the small-z approximation of 003 §1.3 is poor; shorten segment_max_s"
            )
        segments.append(seg)
    if not segments:
        raise StarTrackerAccuracyError(
            f"no segment with at least {MIN_SEGMENT_SAMPLES} star-tracker samples (got {t_ns.size} samples)"
        )
    report(0.3, "smoothing")

    # 5-7. Gyro: body rates, smoothing, lines above the cutoff, attitude oscillation removal.
    have_gyro = gyro_time_tai_ns is not None and w_G_rad_s is not None
    g_ns = np.zeros(0, dtype=np.int64)
    w_B_gyro = np.zeros((0, 3))
    if have_gyro:
        g_ns = np.asarray(gyro_time_tai_ns).astype(np.int64)
        w_G = np.asarray(w_G_rad_s, dtype=np.float64)
        if w_G.shape != (g_ns.size, 3):
            raise StarTrackerAccuracyError(f"w_G_rad_s must have shape ({g_ns.size}, 3), got {w_G.shape}")
        if np.any(np.diff(g_ns) <= 0):
            raise StarTrackerAccuracyError("gyro_time_tai_ns must be strictly increasing")
        w_B_gyro = rotations.quat_rotate(rotations.quat_normalize(np.asarray(q_BG, dtype=np.float64)), w_G)
        for seg in segments:
            lo = np.searchsorted(g_ns, t_ns[seg.sl.start], side="left")
            hi = np.searchsorted(g_ns, t_ns[seg.sl.stop - 1], side="right")
            if hi - lo >= 4 * (seg.fit_raw.harmonics + 2):
                seg.gyro_idx = np.arange(lo, hi)
        if not any(seg.gyro_idx is not None for seg in segments):
            notes.append("gyro data do not cover the star-tracker segments densely enough: not used")
            have_gyro = False

    lines: list[SpectralLine] = []
    line_fits: list[SinusoidFit] = []
    gyro_resid_parts: list[tuple[NDArray, NDArray]] = []
    cutoff_hz = max(seg.fit_raw.cutoff_hz for seg in segments)
    if have_gyro:
        for seg in segments:
            if seg.gyro_idx is None:
                continue
            tg = _seconds(g_ns[seg.gyro_idx], seg.t0_ns)
            m_g = int(round(seg.fit_raw.harmonics * (tg[-1] - tg[0]) / seg.fit_raw.span_s))
            gfit = fit_sine_series(tg, w_B_gyro[seg.gyro_idx], m_g)
            gyro_resid_parts.append((g_ns[seg.gyro_idx], gfit.residuals(w_B_gyro[seg.gyro_idx])))
        g_res_ns = np.concatenate([p[0] for p in gyro_resid_parts])
        g_res = np.concatenate([p[1] for p in gyro_resid_parts])
        g_res_t = _seconds(g_res_ns, int(g_res_ns[0]))
        found, _ = find_lines(g_res_t, g_res, min_freq_hz=cutoff_hz, false_alarm=line_false_alarm)
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
        # Per segment: amplitude and phase of the lines (frequencies fixed, fitted jointly), oscillation
        # removed. Lines closer than the segment's resolution are one line there (e.g. the sidelobes a
        # long record resolves beside a strong line): fitted apart, each would absorb the same motion.
        for seg in segments:
            seg.motion_S = np.zeros((seg.sl.stop - seg.sl.start, 3))
            if seg.gyro_idx is None or not line_fits:
                continue
            mask = (g_res_ns >= g_ns[seg.gyro_idx[0]]) & (g_res_ns <= g_ns[seg.gyro_idx[-1]])
            tg = _seconds(g_res_ns[mask], seg.t0_ns)
            theta_B = sum(fs.integral(seg.t_s) for fs in fit_sinusoids(tg, g_res[mask], _segment_lines(line_fits, tg)))
            seg.motion_S = theta_B @ dcm_BS  # rows: dcm_SB theta_B = dcm_BS^T theta_B
    report(0.5, "gyro lines")

    # Final smoothing of the corrected quaternions.
    for seg in segments:
        if seg.motion_S is not None and np.any(seg.motion_S):
            q_corr = rotations.quat_multiply(seg.q, rotations.rotvec_to_quat(-seg.motion_S))
            seg.z_corr = residual_mrps(q_corr, seg.q_c)
            seg.fit = seg.smooth(seg.z_corr)
        else:
            seg.z_corr = seg.z
            seg.fit = seg.fit_raw
    report(0.6, "corrected smoothing")

    # 3-4. Residuals, sigmas, rates.
    n_all = t_ns.size
    rows = np.concatenate([np.arange(s.sl.start, s.sl.stop) for s in segments])
    z_all = np.full((n_all, 3), np.nan)
    z_fit_all = np.full((n_all, 3), np.nan)
    e_raw = np.full((n_all, 3), np.nan)
    e_eq2 = np.full((n_all, 3), np.nan)
    e_cor = np.full((n_all, 3), np.nan)
    motion = np.zeros((n_all, 3))
    w_S = np.full((n_all, 3), np.nan)
    seg_index = np.full(n_all, -1, dtype=np.int64)
    seg_out = []
    dof_raw = dof_cor = 0
    for i, seg in enumerate(segments):
        sl = seg.sl
        assert seg.fit is not None and seg.z_corr is not None
        z_all[sl] = seg.z
        z_fit_all[sl] = seg.fit_raw.fitted
        e_raw[sl] = sensor_axis_residuals(seg.z, seg.fit_raw.fitted)
        e_eq2[sl] = 4.0 * (seg.z - seg.fit_raw.fitted)
        e_cor[sl] = sensor_axis_residuals(seg.z_corr, seg.fit.fitted)
        if seg.motion_S is not None:
            motion[sl] = seg.motion_S
        w_S[sl] = rate_from_mrp(seg.fit.fitted, seg.solver.derivative_at_samples(seg.fit))
        seg_index[sl] = i
        dof_raw += seg.fit_raw.dof
        dof_cor += seg.fit.dof
        seg_out.append(SegmentFit(
            sl.start, sl.stop, seg.fit.harmonics, seg.fit.cutoff_hz, seg.fit.method, seg.fit.span_s, seg.fit.dof,
            np.sum(e_raw[sl] ** 2, axis=0), np.sum(e_cor[sl] ** 2, axis=0), seg.q_c,
        ))
    if dof_cor <= 0:
        raise StarTrackerAccuracyError("no residual degrees of freedom: fewer harmonics are needed")
    rss_raw = np.sum([s.rss_smoothing_rad2 for s in seg_out], axis=0)
    rss_cor = np.sum([s.rss_rad2 for s in seg_out], axis=0)
    sigma = _pooled(rss_cor, dof_cor)
    if have_gyro:  # white part dof-corrected, removed motion (not absorbed by the fit) per sample
        sigma_smoothing = np.sqrt(sigma**2 + np.maximum(rss_raw - rss_cor, 0.0) / rows.size)
    else:
        sigma_smoothing = _pooled(rss_raw, dof_raw)
    sigma_eq2 = _pooled(np.nansum(e_eq2**2, axis=0), dof_raw)
    sigma_robust = _robust(e_cor[rows], rows.size, dof_cor)
    sigma_smoothing_robust = _robust(e_raw[rows], rows.size, dof_raw)
    w_B = w_S @ dcm_BS.T
    motion_rms = np.sqrt(np.mean(motion[rows] ** 2, axis=0))
    if not have_gyro:
        notes.append("no gyro data: the residual std includes any real motion the series cannot follow")
    report(0.7, "residuals")

    # 5. Gyro comparison (003 §1.4).
    gyro_cmp = None
    if have_gyro:
        gyro_cmp = _gyro_comparison(segments, g_ns, w_B_gyro, dcm_BS, sigma, line_fits)

    # 6. Spectra and star-tracker residual lines.
    spectra: dict[str, Spectrum] = {}
    t_rows = _seconds(t_ns[rows], int(t_ns[rows[0]]))
    spectra["star_tracker_residuals"] = amplitude_spectrum_of_samples(t_rows, e_raw[rows], oversample=2)
    if have_gyro:
        spectra["gyro"] = amplitude_spectrum_of_samples(_seconds(g_ns, int(g_ns[0])), w_B_gyro)
        assert gyro_cmp is not None
        spectra["star_tracker_rate"] = amplitude_spectrum_of_samples(
            _seconds(gyro_cmp.time_tai_ns, int(gyro_cmp.time_tai_ns[0])), gyro_cmp.w_B_star_tracker_rad_s
        )
    else:
        spectra["star_tracker_rate"] = amplitude_spectrum_of_samples(t_rows, w_B[rows])
    gyro_aliases = [float(alias_frequency(lf.freq_hz, sample_period_s)) for lf in line_fits]
    st_res = spectra["star_tracker_residuals"].resolution_hz
    found, _ = find_lines(t_rows, e_raw[rows], min_freq_hz=cutoff_hz, false_alarm=line_false_alarm)
    for line in found:
        sf = line.fit
        removed = any(abs(sf.freq_hz - a) <= 2 * st_res for a in gyro_aliases)
        for k in line.components:
            amp = float(sf.amplitude[k])
            lines.append(SpectralLine(
                "star_tracker", f"x{k + 1}", sf.freq_hz, None, amp, amp / np.sqrt(2.0), sf.freq_hz, removed,
            ))
    report(0.9, "spectra")

    return StarTrackerAccuracy(
        time_tai_ns=t_ns,
        segment=seg_index,
        z=z_all,
        z_fit=z_fit_all,
        residuals_smoothing_rad=e_raw,
        residuals_eq2_rad=e_eq2,
        residuals_rad=e_cor,
        motion_rad=motion,
        w_S_rad_s=w_S,
        w_B_rad_s=w_B,
        sigma_rad=sigma,
        sigma_smoothing_rad=sigma_smoothing,
        sigma_robust_rad=sigma_robust,
        sigma_smoothing_robust_rad=sigma_smoothing_robust,
        sigma_eq2_rad=sigma_eq2,
        motion_rms_rad=motion_rms,
        segments=tuple(seg_out),
        sample_period_s=sample_period_s,
        gyro=gyro_cmp,
        lines=tuple(lines),
        spectra=spectra,
        notes=tuple(notes),
    )


def _gyro_comparison(
    segments: list[_Segment],
    g_ns: NDArray,
    w_B_gyro: NDArray,
    dcm_BS: NDArray,
    sigma_S: NDArray,
    line_fits: list[SinusoidFit],
) -> GyroComparison:
    """003 §1.4: smoothed gyro (same cutoff) against the star-tracker rates, offsets matched."""
    times, w_g, w_st, offsets, weights = [], [], [], [], []
    rss_s = np.zeros(3)
    rss_n = np.zeros(3)
    dof_s = dof_n = 0
    expected_var = []
    for seg in segments:
        if seg.gyro_idx is None:
            continue
        fit = seg.fit
        assert fit is not None
        g_idx = seg.gyro_idx
        tg = _seconds(g_ns[g_idx], seg.t0_ns)
        m_g = int(round(fit.harmonics * (tg[-1] - tg[0]) / fit.span_s))
        gfit = fit_sine_series(tg, w_B_gyro[g_idx], m_g)
        resid = gfit.residuals(w_B_gyro[g_idx])
        rss_s += np.sum(resid**2, axis=0)
        dof_s += gfit.dof
        seg_lines = _segment_lines(line_fits, tg)
        if seg_lines.size:
            resid = resid - sum(fs.evaluate(tg) for fs in fit_sinusoids(tg, resid, seg_lines))
        rss_n += np.sum(resid**2, axis=0)
        dof_n += gfit.dof - 2 * seg_lines.size
        inside = (tg >= 0.0) & (tg <= fit.span_s)
        tg_in = tg[inside]
        g_sm = gfit.fitted[inside]
        st = rate_from_mrp(fit.evaluate(tg_in), fit.derivative(tg_in)) @ dcm_BS.T
        off = np.mean(g_sm - st, axis=0)
        times.append(g_ns[g_idx][inside])
        w_g.append(g_sm - off)
        w_st.append(st)
        offsets.append(off)
        weights.append(tg_in.size)
        var_st_B = _rate_noise_factor(seg) * (dcm_BS**2 @ sigma_S**2)
        expected_var.append((var_st_B, tg_in.size, m_g + 2, tg.size))
    smoothing_sigma = np.sqrt(rss_s / max(dof_s, 1))
    noise_sigma = np.sqrt(rss_n / max(dof_n, 1))
    total = sum(k for _, k, _, _ in expected_var)
    exp_var = sum((var + noise_sigma**2 * p / kk) * k for var, k, p, kk in expected_var) / total
    diff = np.concatenate(w_g) - np.concatenate(w_st)
    return GyroComparison(
        time_tai_ns=np.concatenate(times),
        w_B_gyro_rad_s=np.concatenate(w_g),
        w_B_star_tracker_rad_s=np.concatenate(w_st),
        offset_rad_s=np.average(np.array(offsets), axis=0, weights=np.array(weights, dtype=float)),
        rms_diff_rad_s=np.sqrt(np.mean(diff**2, axis=0)),
        expected_rms_diff_rad_s=np.sqrt(exp_var),
        smoothing_sigma_rad_s=smoothing_sigma,
        noise_sigma_rad_s=noise_sigma,
    )
