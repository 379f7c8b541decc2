"""Gyro offsets on sub-intervals (003 §2.4, figs. 15-16): the fit of processing.gyro_calibration.bias_fit
repeated on halves, quarters and sliding windows, to see whether the offsets drift, and the test of
constancy that makes the whole window's covariance honest when they do.

Constancy (beyond 003 §2.4, which plots the sub-interval offsets): K disjoint sub-intervals give independent
estimates Delta_k with honest covariances P_k (disjoint star-tracker samples, disjoint stretches of gyro
noise). Under constant offsets Q = sum_k (Delta_k - Delta_w)^T P_k^-1 (Delta_k - Delta_w), Delta_w the
inverse-covariance weighted mean, is chi-square with 3 (K - 1) degrees of freedom. When p < alpha the
offsets changed within the window: the whole window's estimate is then an average of a changing offset, and
its covariance must carry the change. Per axis i the between-sub-interval variance is the random-effects
(DerSimonian-Laird) tau_i² = max(0, (Q_i - (K - 1)) / (sum w - sum w² / sum w)), w = 1 / P_k,ii, the
excess scatter of the sub-interval estimates over their own sigmas; the reported variance of the whole
window's offset becomes sigma_i² + tau_i² (the error of estimating the window's mean offset is of the size of
the offset's variation within the window, whatever the estimator's own noise).

Times float64 seconds from any epoch; quaternions scalar first.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.estimation.chi2 import chi2_sf
from processing.gyro_calibration.bias_fit import GyroBiasFit, GyroBiasFitError, fit_gyro_bias

__all__ = ["ConstancyTest", "fit_subintervals", "offset_constancy", "subinterval_edges"]

CONSTANCY_ALPHA = 0.01
"""Significance level of the constancy test (the false-alarm rate on constant offsets)."""

FloatArray = NDArray[np.float64]


def subinterval_edges(
    start_s: float,
    end_s: float,
    *,
    splits: Sequence[int] = (2, 4),
    window_s: float | None = None,
    step_s: float | None = None,
) -> FloatArray:
    """(K, 2) [start, end] s of sub-intervals: each n in ``splits`` cuts [start, end] into n equal parts
    (003 §2.4: halves, quarters), then sliding windows of window_s every step_s (default window_s/2)."""
    if end_s <= start_s:
        raise GyroBiasFitError(f"end_s must exceed start_s, got [{start_s}, {end_s}]")
    parts = []
    for n in splits:
        if int(n) < 1:
            raise GyroBiasFitError(f"splits must be >= 1, got {n}")
        e = np.linspace(start_s, end_s, int(n) + 1)
        parts.append(np.column_stack([e[:-1], e[1:]]))
    if window_s is not None:
        step = window_s / 2.0 if step_s is None else step_s
        if window_s <= 0 or step <= 0:
            raise GyroBiasFitError(f"window_s and step_s must be > 0, got {window_s}, {step}")
        starts = np.arange(start_s, end_s - window_s + 1e-9 * window_s, step)
        parts.append(np.column_stack([starts, starts + window_s]))
    return np.concatenate(parts) if parts else np.zeros((0, 2))


def fit_subintervals(
    t_gyro_s: ArrayLike,
    w_G: ArrayLike,
    t_st_s: ArrayLike,
    q_IS: ArrayLike,
    edges_s: ArrayLike,
    *,
    q_RS: ArrayLike | None = None,
    sensor_index: ArrayLike | None = None,
    min_samples: int = 10,
    **kwargs: object,
) -> list[GyroBiasFit | None]:
    """:func:`fit_gyro_bias` on each [start, end] row of edges_s (K, 2) s (003 §2.4, offsets drifting).

    Star-tracker samples with start <= t <= end are used; a sub-interval with fewer than min_samples of
    them gives None. Other keyword arguments go to :func:`fit_gyro_bias` (pass gyro_arw_rad_sqrt_s so that
    every sub-interval uses the same noise level). With gyro_arw_rad_sqrt_s given, each fit is handed only
    the gyro nodes it integrates over (those :func:`fit_gyro_bias` would pick itself, so the same result),
    not the whole arc to check and slice again.
    """
    tg = np.asarray(t_gyro_s, dtype=np.float64)
    wg = np.asarray(w_G, dtype=np.float64)
    slice_gyro = kwargs.get("gyro_arw_rad_sqrt_s") is not None and tg.ndim == 1 and wg.shape == (tg.size, 3)
    ts = np.asarray(t_st_s, dtype=np.float64)
    qm = np.asarray(q_IS, dtype=np.float64)
    m = ts.size
    q_rs = None if q_RS is None else np.broadcast_to(np.asarray(q_RS, dtype=np.float64), (m, 4))
    sens = None if sensor_index is None else np.asarray(sensor_index)
    out: list[GyroBiasFit | None] = []
    for a, b in np.asarray(edges_s, dtype=np.float64).reshape(-1, 2):
        sel = (ts >= a) & (ts <= b)
        if np.count_nonzero(sel) < min_samples:
            out.append(None)
            continue
        t_g, w_g = t_gyro_s, w_G
        if slice_gyro and np.any(sel):  # fit_gyro_bias's own choice: from the node at or before the first
            lo = max(int(np.searchsorted(tg, ts[sel].min(), side="right")) - 1, 0)  # sample to the one at or
            hi = max(int(np.searchsorted(tg, ts[sel].max(), side="left")), lo + 1) + 1  # after the last
            t_g, w_g = tg[lo:hi], wg[lo:hi]
        out.append(
            fit_gyro_bias(
                t_g, w_g, ts[sel], qm[sel],
                q_RS=None if q_rs is None else q_rs[sel],
                sensor_index=None if sens is None else sens[sel],
                **kwargs,  # type: ignore[arg-type]
            )
        )
    return out


@dataclass(frozen=True)
class ConstancyTest:
    """Result of :func:`offset_constancy` (module docstring). Offsets Delta in the reference frame R, rad/s.

    parts: K sub-intervals used; chi2, dof = 3 (K - 1), p_value; constant: p_value >= alpha;
    estimates (K, 3) and sigmas (K, 3) of the sub-intervals; weighted_mean (3,); chi2_axis (3,) the per-axis
    parts Q_i; between_sigma_rad_s (3,) tau_i (0 when constant); sigma_rad_s (3,) the whole window's sigma to
    report: sqrt(sigma_i² + tau_i²) (the fit's own when constant); covariance (3, 3) likewise (the fit's own
    plus diag(tau²)); inflation (3,) the ratio of the two sigmas.
    """

    parts: int
    chi2: float
    dof: int
    p_value: float
    alpha: float
    constant: bool
    estimates: FloatArray
    sigmas: FloatArray
    weighted_mean: FloatArray
    chi2_axis: FloatArray
    between_sigma_rad_s: FloatArray
    sigma_rad_s: FloatArray
    covariance: FloatArray
    inflation: FloatArray


def offset_constancy(
    whole: GyroBiasFit, subs: Sequence[GyroBiasFit | None], *, alpha: float = CONSTANCY_ALPHA
) -> ConstancyTest | None:
    """Test the constancy of the offsets across the disjoint sub-interval fits ``subs`` of ``whole``.

    subs: the K fits of one split into K equal parts (None entries, too short to fit, are left out); at least
    2 fits are needed (else None). Returns :class:`ConstancyTest`; the whole window's covariance is inflated
    only when the test fails (p < alpha).
    """
    fits = [f for f in subs if f is not None]
    if len(fits) < 2:
        return None
    if not 0.0 < alpha < 1.0:
        raise GyroBiasFitError(f"alpha must be in (0, 1), got {alpha!r}")
    est = np.array([f.delta_R_rad_s for f in fits])
    covs = np.array([f.delta_covariance_R for f in fits])
    infos = np.linalg.inv(covs)
    mean = np.linalg.solve(infos.sum(axis=0), np.einsum("kij,kj->i", infos, est))
    dev = est - mean
    q = float(np.einsum("ki,kij,kj->", dev, infos, dev))
    k = len(fits)
    dof = 3 * (k - 1)
    p_value = float(chi2_sf(q, dof))
    constant = p_value >= alpha
    # per-axis random-effects variance of the offset across the window (DerSimonian-Laird)
    var = np.einsum("kii->ki", covs)
    w = 1.0 / var
    mean_axis = np.sum(w * est, axis=0) / np.sum(w, axis=0)
    q_axis = np.sum(w * (est - mean_axis) ** 2, axis=0)
    denom = np.sum(w, axis=0) - np.sum(w * w, axis=0) / np.sum(w, axis=0)
    tau2 = np.maximum((q_axis - (k - 1)) / denom, 0.0) if not constant else np.zeros(3)
    base = whole.delta_covariance_R
    cov = base + np.diag(tau2)
    sigma = np.sqrt(np.diag(cov))
    return ConstancyTest(
        parts=k, chi2=q, dof=dof, p_value=p_value, alpha=alpha, constant=constant, estimates=est,
        sigmas=np.sqrt(var), weighted_mean=mean, chi2_axis=q_axis, between_sigma_rad_s=np.sqrt(tau2),
        sigma_rad_s=sigma, covariance=cov, inflation=sigma / np.sqrt(np.diag(base)),
    )
