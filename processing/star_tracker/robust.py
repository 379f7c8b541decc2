"""Outlier rejection for the star-tracker smoothing (processing.star_tracker.accuracy, step 2b).

A star tracker occasionally reports a quaternion far off (a mis-identified star, a double exposure):
one such sample of 300" among noise of a few arcseconds dominates the least-squares sigma (1 % of
samples 300" off turn a true 2.5/5/15" into 21/20/20"). The smoothing of 003 §1.3 is therefore made
robust by hard rejection iterated to a fixed point:

1. fit every segment (all samples), residuals e_n about the sensor axes x1 x2 x3;
2. robust scale per axis, pooled over segments: s_i = 1.4826 MAD(e_i) sqrt(n / dof) over the accepted
   samples (the dof factor as for the least-squares sigma);
3. the normalised squared distance d_n^2 = sum_i (e_ni / s_i)^2 / (1 -+ h_n) (h_n the leverage of the
   sample in the fit: an accepted residual has variance s^2 (1 - h), a rejected one, predicted by the
   fit through the others, s^2 (1 + h); at a gap edge or segment end h approaches 1 and the fit follows
   the sample) is chi-square with 3 dof for Gaussian noise; a sample is beyond the threshold when
   d_n^2 > chi2_isf(alpha / n, 3): with ``alpha`` = 1 % a clean data set loses a sample in about 1 % of
   the cases whatever its length (Bonferroni over the n samples). A sample beyond it is rejected when
   it is the largest d of the accepted samples within the fit's resolution (+-N/(M + 2) samples) or
   was rejected before: a 300" spike pulls the fit by tens of arcseconds at its neighbours, which must
   not go with it (they would leave a hole in which the high harmonics are free and the fit wild, and
   then never come back);
4. refit the segments whose accepted set changed with zero weight on the rejected samples (general
   least-squares route; the harmonic count is chosen again), and repeat 2-4 until the accepted set no
   longer changes (a rejected sample comes back when its residual against the fit through the others
   is within the threshold; a burst of adjacent outliers goes one per iteration; at most
   ``max_iterations``).

The rejected samples stay out of every later step (the fits, the sigmas, the spectra, the whiteness
test); their residuals are still computed (against the fit through the accepted samples) and reported.
Hard rejection rather than Huber weights: the sigma is then a plain least-squares figure over the
accepted samples, with the usual degrees of freedom and chi-square interval.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.estimation.chi2 import chi2_isf
from processing.signal.sine_series import Method
from processing.star_tracker.smoothing import SegmentSmoothing, sensor_axis_residuals, smooth_segment

__all__ = ["MAD_TO_SIGMA", "OUTLIER_ALPHA", "OutlierRejection", "reject_outliers", "robust_scale"]

MAD_TO_SIGMA = 1.482602218505602
"""1 / Phi^-1(3/4): MAD of a normal sample times this is its standard deviation."""
OUTLIER_ALPHA = 0.01
"""Probability that a clean (Gaussian) data set loses any sample to the rejection."""
MAX_ITERATIONS = 20


@dataclass(frozen=True)
class OutlierRejection:
    """The segments fitted without their outliers, per segment the accepted mask (in the segments),
    the residuals (per segment, (N_seg, 3) rad, against the final fits), the robust scale s (3,) rad,
    the rejection radius sqrt(chi2_isf(alpha / n, 3)) (in units of s), and the iterations used
    (``converged``: False when max_iterations ended the loop)."""

    segments: tuple[SegmentSmoothing, ...]
    residuals: tuple[NDArray, ...]
    scale_rad: NDArray
    threshold: float
    iterations: int
    converged: bool

    @property
    def n_rejected(self) -> int:
        return int(sum(np.count_nonzero(~s.accepted) for s in self.segments))


def robust_scale(residuals: Sequence[NDArray], accepted: Sequence[NDArray], dof: int) -> NDArray:
    """1.4826 MAD sqrt(n / dof) per axis (3,) of the accepted rows of the residuals (pooled)."""
    e = np.concatenate([r[a] for r, a in zip(residuals, accepted, strict=True)])
    n = e.shape[0]
    if dof <= 0 or n == 0:
        return np.full(3, np.nan)
    mad = np.median(np.abs(e - np.median(e, axis=0)), axis=0)
    return MAD_TO_SIGMA * mad * np.sqrt(n / dof)


def _accepted(seg: SegmentSmoothing, resid: NDArray, scale: NDArray, threshold: float,
              cache: dict[int, NDArray], key: int) -> NDArray:
    """Step 3 on one segment: the new accepted mask (N,) from residuals (N, 3), the scale (3,) and the
    current mask; cache[key]: the segment's leverage (computed when first needed)."""
    accepted = seg.accepted
    d2 = np.sum((resid / scale) ** 2, axis=1)
    if not np.any(d2 > threshold**2):
        return np.ones(d2.size, dtype=bool)
    if key not in cache:
        cache[key] = np.clip(seg.solver.leverage(seg.fit_raw.harmonics), 0.0, 1.0 - 1e-9)
    h = cache[key]
    d2 = d2 / np.where(accepted, 1.0 - h, 1.0 + h)
    beyond = d2 > threshold**2
    harmonics = seg.fit_raw.harmonics
    w = max(1, int(np.ceil(d2.size / (harmonics + 2))))
    padded = np.pad(np.where(accepted, d2, -np.inf), w, constant_values=-np.inf)  # among the accepted
    local_max = d2 >= np.lib.stride_tricks.sliding_window_view(padded, 2 * w + 1).max(axis=1)
    return ~(beyond & (local_max | ~accepted))


def _residuals(seg: SegmentSmoothing) -> NDArray:
    return sensor_axis_residuals(seg.z, seg.fit_raw.fitted)


def reject_outliers(
    segments: Sequence[SegmentSmoothing], method: Method, *,
    alpha: float = OUTLIER_ALPHA, max_iterations: int = MAX_ITERATIONS,
) -> OutlierRejection:
    """Steps 1-4 of the module docstring on smoothed segments (their ``fit_raw``; refits keep each
    segment's harmonic mode, with ``method``). alpha in (0, 1); alpha = 0 disables the rejection."""
    segs = list(segments)
    resid = [_residuals(s) for s in segs]
    n = int(sum(s.t_s.size for s in segs))
    threshold = float(np.sqrt(chi2_isf(alpha / n, 3))) if alpha > 0 else float("inf")
    scale = np.full(3, np.nan)
    iterations, converged = 0, True
    frozen: set[int] = set()  # segments that would keep too few samples: left as they are
    lev: dict[int, NDArray] = {}  # leverage per segment of its current fit
    while True:
        accepted = [s.accepted for s in segs]
        dof = int(sum(s.fit_raw.dof for s in segs))
        scale = robust_scale(resid, accepted, dof)
        if not np.isfinite(threshold) or not np.all(scale > 0):
            break
        new = [_accepted(s, r, scale, threshold, lev, i) for i, (r, s) in enumerate(zip(resid, segs, strict=True))]
        changed = [i for i, (a, b) in enumerate(zip(accepted, new, strict=True))
                   if i not in frozen and not np.array_equal(a, b)]
        if not changed:
            break
        if iterations == max_iterations:
            converged = False
            break
        iterations += 1
        for i in changed:
            s = segs[i]
            if np.count_nonzero(new[i]) < max(12, 2 * (s.fit_raw.harmonics + 2)):
                frozen.add(i)
                continue
            segs[i] = smooth_segment(s.sl, s.t_s, s.t0_ns, s.q, None if s.auto else s.solver.max_harmonics,
                                     method, accepted=new[i])
            resid[i] = _residuals(segs[i])
            lev.pop(i, None)
    return OutlierRejection(tuple(segs), tuple(resid), scale, threshold, iterations, converged)
