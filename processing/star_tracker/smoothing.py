"""The 003 §1.3 smoother of star-tracker quaternions: building blocks and one smoothed segment.

Method (003 = Avanesov et al., Keldysh Institute preprint 74, 2010, §1.3; the steps are numbered as in
processing.star_tracker.accuracy):

1. Segments of at most ``segment_max_s`` (003: under 20 min), split at gaps (:func:`split_segments`).
   In each, the mean quaternion q_c = Q/|Q|, Q = sum q_n (:func:`mean_quaternion`) and the residual
   Rodrigues parameters (MRPs) z^(n) of q_c^-1 o q_n (:func:`residual_mrps`).
2. Each z_i smoothed by the sine series plus linear trend (processing.signal.sine_series), the
   harmonic count M by 2 x GCV unless given (:func:`auto_harmonics`, :func:`smooth_segment`).
3. Residuals about the sensor axes as exact small rotations (:func:`sensor_axis_residuals`).
4. Angular velocity from z(t) and its analytic derivative (:func:`rate_from_mrp`).

Times int64 TAI ns or float seconds as named; quaternions scalar first; angles rad, rates rad/s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.signal.sine_series import Method, SineSeriesSolver
from processing.signal.sine_series_fit import SineSeriesFit
from processing.units import NS_PER_S

__all__ = [
    "GCV_FACTOR",
    "SegmentSmoothing",
    "auto_harmonics",
    "mean_quaternion",
    "rate_from_mrp",
    "residual_mrps",
    "seconds_since",
    "sensor_axis_residuals",
    "smooth_segment",
    "solver_auto_harmonics",
    "split_segments",
]

GCV_FACTOR = 2
"""Automatic M = GCV_FACTOR x the GCV minimiser (processing.star_tracker.accuracy docstring, item 8)."""


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
    return 4.0 / (1.0 + zz) ** 2 * ((1.0 - zz) * zd - 2.0 * _cross(z, zd) + 2.0 * zzd * z)


def _cross(a: NDArray, b: NDArray) -> NDArray:
    """a x b over the last axis (..., 3): np.cross's products and differences (the same values) without its
    per-call axis handling, which took most of the time on the segments' (N, 3) arrays."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def sensor_axis_residuals(z: ArrayLike, z_fit: ArrayLike) -> NDArray:
    """Rotation vector (N, 3) rad of s(z_fit)^-1 o s(z): the measurement error about the sensor axes.

    To first order in z this is 003 eq. 2, e = 4 (z - z_fit) (processing.star_tracker.accuracy, item 3).
    """
    return rotations.quat_to_rotvec(
        rotations.quat_multiply(rotations.quat_conjugate(rotations.mrp_to_quat(z_fit)), rotations.mrp_to_quat(z))
    )


def solver_auto_harmonics(solver: SineSeriesSolver, z: NDArray) -> int:
    """min(GCV_FACTOR x argmin GCV, the solver's largest M) for the columns z (N, K) jointly."""
    path = solver.path(z)
    return int(min(GCV_FACTOR * path.select("gcv"), path.harmonics[-1]))


def auto_harmonics(t_s: ArrayLike, z: ArrayLike, *, max_harmonics: int | None = None) -> int:
    """Automatic harmonic count: min(GCV_FACTOR x argmin GCV, cap), cap = (N - 2) // 4 by default
    (and at most the last harmonic the samples determine).

    t_s (N,) [s], z (N, K) jointly (processing.star_tracker.accuracy docstring, item 8).
    """
    n = np.asarray(t_s).size
    cap = (n - 2) // 4 if max_harmonics is None else min(max_harmonics, n - 2)
    return solver_auto_harmonics(SineSeriesSolver(t_s, cap), np.asarray(z, dtype=np.float64))


def seconds_since(t_ns: NDArray, t0_ns: int) -> NDArray:
    """Float seconds of int64 TAI ns times t_ns after t0_ns (exact difference first)."""
    return (t_ns - np.int64(t0_ns)).astype(np.float64) / NS_PER_S


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


@dataclass(frozen=True)
class SegmentSmoothing:
    """Steps 1-2 on one segment: rows ``sl`` of the samples, times t_s (N,) [s] since its first sample
    t0_ns, quaternions q (N, 4), mean q_c (4,), MRPs z (N, 3), the solver (one factorisation for every
    fit at these times), whether M is automatic, the fit of z (``fit_raw``) and the samples the fits use
    (``accepted`` (N,) bool: False for rejected outliers, which have zero weight in the solver)."""

    sl: slice
    t_s: NDArray
    t0_ns: int
    q: NDArray
    q_c: NDArray
    z: NDArray
    solver: SineSeriesSolver
    auto: bool
    fit_raw: SineSeriesFit
    accepted: NDArray

    def smooth(self, z: NDArray) -> SineSeriesFit:
        """Fit other MRPs z (N, 3) at the same times, M chosen the same way (e.g. corrected data)."""
        return _smooth(self.solver, z, self.auto)


def _smooth(solver: SineSeriesSolver, z: NDArray, auto: bool) -> SineSeriesFit:
    return solver.fit(z, solver_auto_harmonics(solver, z) if auto else solver.max_harmonics)


def smooth_segment(
    sl: slice, t_s: NDArray, t0_ns: int, q: NDArray, harmonics: int | None, method: Method,
    accepted: NDArray | None = None,
) -> SegmentSmoothing:
    """Steps 1-2 (003 §1.3) on the samples q (N, 4) at t_s (N,) [s] of one segment: mean quaternion,
    MRPs, and their sine-series fit with M = ``harmonics`` or automatic (None, capped at (N - 2) // 4).
    The caller checks harmonics <= N - 2. ``accepted`` (N,) bool: the samples to fit (None: all); the
    others get zero weight (general least-squares route: the DST needs every sample)."""
    n = t_s.size
    ok = np.ones(n, dtype=bool) if accepted is None else np.asarray(accepted, dtype=bool)
    q_c = mean_quaternion(q[ok])
    z = residual_mrps(q, q_c)
    top = (n - 2) // 4 if harmonics is None else harmonics
    if np.all(ok):
        solver = SineSeriesSolver(t_s, top, method=method)
    else:
        solver = SineSeriesSolver(t_s, top, weights=ok.astype(np.float64), method="lstsq")
    return SegmentSmoothing(sl, t_s, t0_ns, q, q_c, z, solver, harmonics is None,
                            _smooth(solver, z, harmonics is None), ok)
