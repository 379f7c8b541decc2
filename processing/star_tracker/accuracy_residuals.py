"""Residuals and sigmas of the star-tracker accuracy analysis (003 §1.3, steps 3-4 and 7 of
:mod:`processing.star_tracker.accuracy`).

Holds the per-segment result :class:`SegmentFit`, the last smoothing of a segment after the removal of the
real motion the gyro saw (step 7), the residuals about the sensor axes and the rates gathered over the
segments (steps 3-4), and the sigmas pooled over the segments with the least-squares degrees of freedom,
with their robust (MAD) and 003 eq. 2 versions (step 3). The method is described in
:mod:`processing.star_tracker.accuracy`.

Angles rad, rates rad/s, quaternions scalar first, Hamilton, q_AB maps B to A.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.attitude import rotations
from processing.signal.sine_series_fit import SineSeriesFit
from processing.star_tracker.robust import MAD_TO_SIGMA
from processing.star_tracker.smoothing import (
    SegmentSmoothing,
    rate_from_mrp,
    residual_mrps,
    sensor_axis_residuals,
)

__all__ = [
    "CorrectedSegment",
    "Residuals",
    "SegmentFit",
    "Sigmas",
    "correct_segment",
    "pool_residuals",
    "pooled_sigmas",
]


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
class CorrectedSegment:
    """Final smoothing of one segment: the removed oscillation motion_S (N, 3), the MRPs of the
    corrected quaternions z (N, 3) and their fit (the raw ones when nothing was removed)."""

    seg: SegmentSmoothing
    motion_S: NDArray
    z: NDArray
    fit: SineSeriesFit


def correct_segment(seg: SegmentSmoothing, motion_S: NDArray) -> CorrectedSegment:
    """Step 7, last part: q_n' = q_n o exp(-theta_S(t_n)) smoothed again (M chosen again if automatic)."""
    if not np.any(motion_S):
        return CorrectedSegment(seg, motion_S, seg.z, seg.fit_raw)
    q_corr = rotations.quat_multiply(seg.q, rotations.rotvec_to_quat(-motion_S))
    z_corr = residual_mrps(q_corr, seg.q_c)
    return CorrectedSegment(seg, motion_S, z_corr, seg.smooth(z_corr))


@dataclass(frozen=True)
class Residuals:
    """Steps 3-4 per star-tracker sample (N rows, NaN outside the segments; ``rows`` those inside, ``ok``
    those inside and accepted (not outliers), ``outlier`` (N,) bool): segment index, raw MRPs and their
    fit, residuals raw / eq. 2 / corrected, removed motion, w_S; the per-segment summaries (sums over
    the accepted samples) and the pooled degrees of freedom (raw, corrected)."""

    rows: NDArray
    ok: NDArray
    outlier: NDArray
    segment: NDArray
    z: NDArray
    z_fit: NDArray
    e_raw: NDArray
    e_eq2: NDArray
    e_cor: NDArray
    motion: NDArray
    w_S: NDArray
    segments: tuple[SegmentFit, ...]
    dof_raw: int
    dof_cor: int


def pool_residuals(n_all: int, corrected: tuple[CorrectedSegment, ...]) -> Residuals:
    """Steps 3-4: residuals about the sensor axes and rates from the final smoothing."""
    rows = np.concatenate([np.arange(c.seg.sl.start, c.seg.sl.stop) for c in corrected])
    z_all, z_fit_all, e_raw, e_eq2, e_cor, w_S = (np.full((n_all, 3), np.nan) for _ in range(6))
    motion = np.zeros((n_all, 3))
    outlier = np.zeros(n_all, dtype=bool)
    seg_index = np.full(n_all, -1, dtype=np.int64)
    seg_out = []
    dof_raw = dof_cor = 0
    for i, c in enumerate(corrected):
        seg, sl, fit = c.seg, c.seg.sl, c.fit
        z_all[sl] = seg.z
        z_fit_all[sl] = seg.fit_raw.fitted
        e_raw[sl] = sensor_axis_residuals(seg.z, seg.fit_raw.fitted)
        e_eq2[sl] = 4.0 * (seg.z - seg.fit_raw.fitted)
        e_cor[sl] = sensor_axis_residuals(c.z, fit.fitted)
        motion[sl] = c.motion_S
        w_S[sl] = rate_from_mrp(fit.fitted, seg.solver.derivative_at_samples(fit))
        seg_index[sl] = i
        outlier[sl] = ~seg.accepted
        dof_raw += seg.fit_raw.dof
        dof_cor += fit.dof
        acc = seg.accepted
        seg_out.append(SegmentFit(
            sl.start, sl.stop, fit.harmonics, fit.cutoff_hz, fit.method, fit.span_s, fit.dof,
            np.sum(e_raw[sl][acc] ** 2, axis=0), np.sum(e_cor[sl][acc] ** 2, axis=0), seg.q_c,
        ))
    ok = rows[~outlier[rows]]
    return Residuals(rows, ok, outlier, seg_index, z_all, z_fit_all, e_raw, e_eq2, e_cor, motion, w_S,
                      tuple(seg_out), dof_raw, dof_cor)


@dataclass(frozen=True)
class Sigmas:
    """Step 3, per axis (3,) rad: sensor noise, 003's smoothing figure, robust (MAD) versions, eq. 2
    literally, and the rms of the removed motion."""

    sigma: NDArray
    smoothing: NDArray
    robust: NDArray
    smoothing_robust: NDArray
    eq2: NDArray
    motion_rms: NDArray


def _pooled(rss: NDArray, dof: int) -> NDArray:
    return np.sqrt(rss / dof) if dof > 0 else np.full(3, np.nan)


def _robust(resid: NDArray, n: int, dof: int) -> NDArray:
    if dof <= 0:
        return np.full(3, np.nan)
    mad = np.median(np.abs(resid - np.median(resid, axis=0)), axis=0)
    return MAD_TO_SIGMA * mad * np.sqrt(n / dof)


def pooled_sigmas(res: Residuals, have_gyro: bool) -> Sigmas:
    """Step 3: sigmas pooled over segments with the least-squares degrees of freedom (module docstring),
    over the accepted samples."""
    rows = res.ok
    rss_raw = np.sum([s.rss_smoothing_rad2 for s in res.segments], axis=0)
    rss_cor = np.sum([s.rss_rad2 for s in res.segments], axis=0)
    sigma = _pooled(rss_cor, res.dof_cor)
    if have_gyro:  # white part dof-corrected, removed motion (not absorbed by the fit) per sample
        sigma_smoothing = np.sqrt(sigma**2 + np.maximum(rss_raw - rss_cor, 0.0) / rows.size)
    else:
        sigma_smoothing = _pooled(rss_raw, res.dof_raw)
    return Sigmas(
        sigma=sigma,
        smoothing=sigma_smoothing,
        robust=_robust(res.e_cor[rows], rows.size, res.dof_cor),
        smoothing_robust=_robust(res.e_raw[rows], rows.size, res.dof_raw),
        eq2=_pooled(np.sum(res.e_eq2[rows] ** 2, axis=0), res.dof_raw),
        motion_rms=np.sqrt(np.mean(res.motion[res.rows] ** 2, axis=0)),
    )

