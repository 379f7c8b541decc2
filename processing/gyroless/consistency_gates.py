"""Consistency gates of a gyroless filter pass (step 7 of :mod:`processing.gyroless.estimation`, paper 004).

Holds the convergence time (the first time from which, over a window, the mean NIS lies within its 99 %
chi^2 interval and the attitude bound is below a threshold) and the gates of :func:`filter_consistency`:
the mean NIS over the tested segment and over its windows against their 99 % intervals (with an effect-size
tolerance), and the whiteness of the whitened innovations (Ljung-Box with an autocorrelation size limit),
built on the statistics of processing.estimation.consistency.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.estimation.chi2 import chi2_ppf
from processing.estimation.consistency import (
    ChiSquareStats,
    LjungBoxStats,
    chi_square_stats,
    ljung_box,
    whiteness,
)

__all__ = [
    "FilterConsistency",
    "convergence_time",
    "filter_consistency",
]


def convergence_time(t_s: NDArray, sigma_deg: NDArray, nis: NDArray, dof: NDArray, threshold_deg: float,
                 window_s: float) -> float | None:
    """First time from which, over a window, the mean NIS lies within its 99 % chi^2 interval and the
    largest 1-sigma attitude bound is below threshold_deg. None if never."""
    ok = np.isfinite(nis) & (dof > 0)
    if not np.any(ok):
        return None
    cs_n = np.concatenate([[0.0], np.cumsum(np.where(ok, nis, 0.0))])
    cs_d = np.concatenate([[0.0], np.cumsum(np.where(ok, dof, 0.0))])
    cs_c = np.concatenate([[0], np.cumsum(ok)])
    j = np.searchsorted(t_s, t_s + window_s, side="right")  # window [k, j)
    k = np.arange(t_s.size)
    full = t_s + window_s <= t_s[-1]
    cnt = cs_c[j] - cs_c[k]
    tot_d = cs_d[j] - cs_d[k]
    mean = (cs_n[j] - cs_n[k]) / np.maximum(cnt, 1)
    lo = chi2_ppf(0.005, np.maximum(tot_d, 1)) / np.maximum(cnt, 1)
    hi = chi2_ppf(0.995, np.maximum(tot_d, 1)) / np.maximum(cnt, 1)
    good = full & (cnt > 0) & (mean >= lo) & (mean <= hi) & (sigma_deg <= threshold_deg)
    idx = np.flatnonzero(good)
    return float(t_s[idx[0]] - t_s[0]) if idx.size else None


NIS_TOLERANCE = 0.1
"""The mean NIS fails its test when it is outside its 99 % chi^2 interval AND off its degrees of freedom by more
than this fraction (with thousands of updates the interval alone is ~1 % wide: a slightly wrong noise level
would flag every arc; a model error that matters moves it by tens of per cent)."""
NIS_WINDOW_FRACTION_MAX = 0.2
"""...and the windows (``nis_window_s``, non-overlapping) fail when more than this fraction of them do so."""
RHO_MAX = 0.1
"""Whiteness fails when the Ljung-Box test rejects (adjusted p < LJUNG_BOX_P_MIN) AND some autocorrelation of
the whitened innovations (lags 1..WHITENESS_MAX_LAG) exceeds RHO_MAX in size (the effect size: a correlation
of 0.1 at lag 1 inflates the variance of a mean by ~20 %; model errors of the magnetometer give 0.3-0.7)."""
LJUNG_BOX_P_MIN = 1e-3
WHITENESS_MAX_LAG = 20


@dataclass(frozen=True)
class FilterConsistency:
    """The consistency gates of a filter pass over the tested segment (from ``start_s``, seconds since the
    first step: the convergence time, else the end of the first NIS window).

    nis: chi^2 statistics of the NIS over the segment; nis_bounds_99: 99 % interval of its mean (with the
    summed degrees of freedom); nis_ok: the mean passes (see NIS_TOLERANCE). n_windows, windows_failed:
    non-overlapping windows of window_s and how many fail the same test; windows_ok. ljung: Ljung-Box
    test of the whitened innovations; max_abs_rho; whiteness_ok. consistent: all three pass; reasons:
    what failed, in words."""

    start_s: float
    nis: ChiSquareStats
    nis_bounds_99: tuple[float, float]
    nis_ok: bool
    window_s: float
    n_windows: int
    windows_failed: int
    windows_ok: bool
    ljung: LjungBoxStats
    max_abs_rho: float
    whiteness_ok: bool
    consistent: bool
    reasons: tuple[str, ...]


def _nis_mean_fails(nis: NDArray, dof: NDArray) -> tuple[bool, float, float, float, float]:
    """(fails, mean, mean dof, lo, hi) of the mean of NIS values with their dof against its 99 % interval."""
    n, tot = nis.size, float(dof.sum())
    if n == 0:
        return False, math.nan, math.nan, math.nan, math.nan
    lo, hi = chi2_ppf(0.005, tot) / n, chi2_ppf(0.995, tot) / n
    mean, mdof = float(nis.mean()), tot / n
    return (not lo <= mean <= hi) and abs(mean / mdof - 1.0) > NIS_TOLERANCE, mean, mdof, float(lo), float(hi)


def filter_consistency(t_s: NDArray, nis: NDArray, dof: NDArray, whitened: NDArray, start_s: float,
                       window_s: float) -> FilterConsistency:
    """NIS (mean over the segment from start_s and over its windows of window_s) and whiteness (Ljung-Box
    over lags 1..WHITENESS_MAX_LAG) of a filter pass: t_s (K,) [s], nis (K,), dof (K,) (NaN/0 where no
    update), whitened (K, C) whitened innovation components (NaN padded)."""
    seg = (t_s - t_s[0] >= start_s) & np.isfinite(nis) & (dof > 0)
    v, d = nis[seg], dof[seg]
    fails, mean, mdof, lo, hi = _nis_mean_fails(v, d)
    st = chi_square_stats(v, d)
    ts = t_s[seg] - t_s[0] - start_s
    win = np.floor(ts / window_s).astype(np.int64) if ts.size else np.zeros(0, np.int64)
    n_win, failed = 0, 0
    for w in np.unique(win):
        m = win == w
        if ts[m].size and ts[m][-1] - ts[m][0] >= 0.5 * window_s:  # full enough windows only
            n_win += 1
            failed += int(_nis_mean_fails(v[m], d[m])[0])
    windows_ok = n_win == 0 or failed <= NIS_WINDOW_FRACTION_MAX * n_win
    wseg = whitened[(t_s - t_s[0] >= start_s)]
    lb = ljung_box(wseg, max_lag=WHITENESS_MAX_LAG)
    wh = whiteness(wseg, max_lag=WHITENESS_MAX_LAG)
    rho_max = wh.max_abs_rho
    whiteness_ok = not (np.isfinite(lb.p_min_adjusted) and lb.p_min_adjusted < LJUNG_BOX_P_MIN
                        and rho_max > RHO_MAX)
    reasons = []
    if fails:
        reasons.append(f"mean NIS {mean:.2f} outside its 99 % interval [{lo:.2f}, {hi:.2f}] for {mdof:.2f} "
                       "degrees of freedom")
    if not windows_ok:
        reasons.append(f"mean NIS outside its 99 % interval in {failed} of {n_win} windows of {window_s:g} s")
    if not whiteness_ok:
        reasons.append(f"innovations correlated in time (Ljung-Box p = {lb.p_min_adjusted:.1e}, largest "
                       f"autocorrelation {rho_max:.2f} > {RHO_MAX:g})")
    return FilterConsistency(start_s=float(start_s), nis=st, nis_bounds_99=(lo, hi), nis_ok=not fails,
                             window_s=float(window_s), n_windows=n_win, windows_failed=failed, windows_ok=windows_ok,
                             ljung=lb, max_abs_rho=rho_max, whiteness_ok=whiteness_ok,
                             consistent=not reasons, reasons=tuple(reasons))

