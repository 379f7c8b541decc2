"""Consistency measures of a Kalman filter: NIS, innovation whiteness, NEES (Bar-Shalom, Li &
Kirubarajan, Estimation with Applications to Tracking and Navigation, 2001, §5.4).

- NIS (normalised innovation squared) per update, nu^T S^-1 nu, is chi^2 with m degrees of freedom
  (m = measurement dimension) when the filter is consistent; its time average over N updates lies
  in [chi2_ppf(0.025, sum m) / N, chi2_ppf(0.975, sum m) / N] with 95 % probability.
- Whiteness: the whitened innovations (L^-1 nu, S = L L^T) are independent N(0, 1); their sample
  autocorrelation at lag l != 0 is within +-1.96 / sqrt(N) with 95 % probability.
- NEES (normalised estimation error squared) e^T P^-1 e, chi^2 with n degrees of freedom, needs the
  truth (simulations). A single run's errors are correlated in time, so its per-step values are
  judged by the fraction inside the per-step 95 % interval (~95 % expected) and its mean by
  [chi2_ppf(0.025, n), chi2_ppf(0.975, n)] loosely; Monte-Carlo averages give the sharp test.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.estimation.chi2 import chi2_ppf

__all__ = ["ChiSquareStats", "LjungBoxStats", "WhitenessStats", "chi_square_stats", "ljung_box", "nees", "whiteness"]


@dataclass(frozen=True)
class ChiSquareStats:
    """Statistics of a chi^2-distributed sequence (NIS or NEES): n values used, mean, mean degrees of
    freedom, the 95 % interval of the time average (independent samples), the fraction of values
    inside their per-step 95 % interval, and whether the mean lies in its interval."""

    n: int
    mean: float
    mean_dof: float
    mean_bounds: tuple[float, float]
    fraction_in_95: float
    mean_in_bounds: bool


def chi_square_stats(values: ArrayLike, dof: ArrayLike) -> ChiSquareStats:
    """Summarise chi^2 values (K,) with their degrees of freedom (K,) (entries with dof <= 0 or NaN skipped)."""
    v = np.asarray(values, dtype=float)
    d = np.broadcast_to(np.asarray(dof, dtype=float), v.shape)
    ok = np.isfinite(v) & (d > 0)
    v, d = v[ok], d[ok]
    if v.size == 0:
        return ChiSquareStats(0, float("nan"), float("nan"), (float("nan"), float("nan")), float("nan"), False)
    total = float(d.sum())
    lo, hi = chi2_ppf(0.025, total) / v.size, chi2_ppf(0.975, total) / v.size
    inside = (v >= chi2_ppf(0.025, d)) & (v <= chi2_ppf(0.975, d))
    mean = float(v.mean())
    return ChiSquareStats(n=int(v.size), mean=mean, mean_dof=float(d.mean()), mean_bounds=(float(lo), float(hi)),
                          fraction_in_95=float(inside.mean()), mean_in_bounds=bool(lo <= mean <= hi))


@dataclass(frozen=True)
class WhitenessStats:
    """Sample autocorrelation of whitened innovations per component at lags 1..max_lag:
    rho (components, max_lag) (NaN for components without data), the 95 % bound 1.96/sqrt(N),
    the fraction of |rho| above it and the largest |rho|."""

    rho: NDArray
    bound: float
    fraction_outside: float
    max_abs_rho: float


def whiteness(whitened: ArrayLike, max_lag: int = 20) -> WhitenessStats:
    """Whiteness of whitened innovation components (K, C) (NaN where absent; each column is treated as
    one sequence over the steps where it is finite, i.e. gaps are closed)."""
    w = np.asarray(whitened, dtype=float)
    if w.ndim == 1:
        w = w[:, None]
    rhos = np.full((w.shape[1], max_lag), np.nan)
    n_min = None
    for c in range(w.shape[1]):
        x = w[np.isfinite(w[:, c]), c]
        if x.size <= 2 * max_lag:
            continue
        x = x - x.mean()
        den = float(x @ x)
        if den <= 0:
            continue
        rhos[c] = [float(x[:-lag] @ x[lag:]) / den for lag in range(1, max_lag + 1)]
        n_min = x.size if n_min is None else min(n_min, x.size)
    if n_min is None:
        return WhitenessStats(rhos, float("nan"), float("nan"), float("nan"))
    bound = 1.96 / np.sqrt(n_min)
    finite = rhos[np.isfinite(rhos)]
    return WhitenessStats(rho=rhos, bound=float(bound), fraction_outside=float(np.mean(np.abs(finite) > bound)),
                          max_abs_rho=float(np.max(np.abs(finite))))


def nees(errors: ArrayLike, covariances: ArrayLike) -> NDArray:
    """e^T P^-1 e per step for errors (K, n) and covariances (K, n, n). Returns (K,)."""
    e = np.asarray(errors, dtype=float)
    P = np.asarray(covariances, dtype=float)
    return np.einsum("ki,ki->k", e, np.linalg.solve(P, e[..., None])[..., 0])


@dataclass(frozen=True)
class LjungBoxStats:
    """Ljung-Box portmanteau test of whitened innovations per component over lags 1..max_lag:
    q (components,) the statistic Q = N (N + 2) sum_l rho_l^2 / (N - l) (NaN for components without
    data), p (components,) its chi^2(max_lag) tail probability, n (components,) samples used, and
    p_min_adjusted = min(1, C * min p) (Bonferroni over the C components with data; NaN if none)."""

    q: NDArray
    p: NDArray
    n: NDArray
    max_lag: int
    p_min_adjusted: float


def ljung_box(whitened: ArrayLike, max_lag: int = 20) -> LjungBoxStats:
    """Ljung & Box (1978) test of whitened innovation components (K, C) (NaN where absent; gaps closed as
    in :func:`whiteness`). Under whiteness each Q is chi^2 with max_lag degrees of freedom."""
    from processing.estimation.chi2 import chi2_sf

    wh = whiteness(whitened, max_lag=max_lag)
    w = np.asarray(whitened, dtype=float)
    if w.ndim == 1:
        w = w[:, None]
    n = np.isfinite(w).sum(axis=0).astype(float)
    lags = np.arange(1, max_lag + 1, dtype=float)
    q = n * (n + 2.0) * np.sum(wh.rho**2 / np.maximum(n[:, None] - lags[None, :], 1.0), axis=1)
    p = np.where(np.isfinite(q), chi2_sf(np.where(np.isfinite(q), q, 0.0), float(max_lag)), np.nan)
    have = np.isfinite(p)
    p_adj = float(min(1.0, have.sum() * float(np.min(p[have])))) if np.any(have) else float("nan")
    return LjungBoxStats(q=q, p=np.asarray(p, dtype=float), n=n, max_lag=max_lag, p_min_adjusted=p_adj)
