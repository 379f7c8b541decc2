"""Is the star-tracker residual noise white? A spectral test above the smoothing cutoff, the effective
degrees of freedom of the sigma, and its chi-square confidence interval (processing.star_tracker.accuracy,
step 3b).

Why a spectral test and not Ljung-Box on the residuals: the sine-series fit removes everything below its
cutoff f_c = M/(2T), and with M up to (N - 2)/4 the residuals of white noise have lag-1 autocorrelations
of -0.1 to -0.2 from the fit alone; Ljung-Box would flag every clean data set. Above the cutoff the fit
leaves the noise as it is, so there white noise has a flat spectrum while time-correlated noise (e.g.
first-order Gauss-Markov with tau of tens of seconds: S(f) ~ 1/(1 + (2 pi f tau)^2)) falls with f:

1. per segment, the residuals are put on their sampling grid (index round(t / h)), rejected samples and
   gaps as zeros (a zero-filled white series still has a flat expected periodogram), and the
   periodogram P_j = |X_j|^2 taken at the Fourier frequencies f_j = j / (L h);
2. the band [CUTOFF_MARGIN f_c, f_Nyquist) is split at its middle; bins within two resolutions of a
   spectral line found in the residuals are left out (a line is reported as a line, and is not
   absorbed by the fit);
3. per axis, the ratio F of the mean power in the lower half to that in the upper half, pooled over
   segments, is F(2 n_low, 2 n_high)-distributed for white noise (periodogram ordinates ~ chi-square 2
   each, independent at the Fourier frequencies); the one-sided p-value P(F' >= F) tests for red noise
   (power rising towards the cutoff: the case where the harmonics absorb noise with the motion);
4. ``correlated`` when the smallest of the three p-values is below alpha / 3 (alpha = 1 %, Bonferroni
   over the axes).

What the test means for the sigma: sigma = sqrt(rss / dof) extrapolates the noise above the cutoff to
the band below it as if white. ``sigma_above_cutoff`` = sqrt(rss / n) is the noise the fit cannot have
absorbed; when the power rises towards the cutoff, ``sigma_lower_bound`` continues the lower half-band's
level flat below the cutoff (for noise whose spectrum falls with frequency, a lower bound of the total;
the truth can be much larger, and these data cannot tell how much).

Effective degrees of freedom: the variance of a sum of squares of a correlated Gaussian series is
2 sigma^4 n (1 + 2 sum_k rho_k^2), so the sigma's chi-square has nu_eff = dof / (1 + 2 sum_{k=1..K} rho_k^2)
(K = MAX_LAGS lags of the pooled residual autocorrelation). Used when the test fails; for white noise the
estimated rho_k are noise (sum rho_k^2 ~ K / n) and the plain least-squares dof are used.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import betainc

from processing.estimation.chi2 import chi2_ppf

__all__ = [
    "CUTOFF_MARGIN",
    "MAX_LAGS",
    "WHITENESS_ALPHA",
    "ResidualSeries",
    "Whiteness",
    "f_sf",
    "sigma_interval",
    "whiteness_test",
]

CUTOFF_MARGIN = 1.25
"""The test band starts at this multiple of the smoothing cutoff (clear of the fit's transition)."""
WHITENESS_ALPHA = 0.01
"""False-alarm probability of ``correlated`` for white noise (over the three axes together)."""
MAX_LAGS = 30
"""Lags of the residual autocorrelation in the effective degrees of freedom."""
MIN_BINS = 4


@dataclass(frozen=True)
class ResidualSeries:
    """One segment's residuals for the test: times t_s (N,) [s], residuals e (N, 3), accepted (N,) bool,
    the fit's cutoff [Hz]."""

    t_s: NDArray
    e: NDArray
    accepted: NDArray
    cutoff_hz: float


@dataclass(frozen=True)
class Whiteness:
    """Result of :func:`whiteness_test`, per axis (3,) unless noted: p_value, ratio (lower / upper half-band
    mean power), the F dof (2 n_low, 2 n_high; scalars), the band edges [Hz] (f_lo, f_mid, f_nyquist of
    the first segment), rho (MAX_LAGS, 3) pooled autocorrelation at lags 1.., dof_factor 1 / (1 + 2 sum
    rho^2), ``tested`` (enough bins), ``correlated``, alpha."""

    p_value: NDArray
    ratio: NDArray
    dof_low: int
    dof_high: int
    band_hz: tuple[float, float, float]
    rho: NDArray
    dof_factor: NDArray
    tested: bool
    correlated: bool
    alpha: float


def f_sf(x: NDArray | float, d1: float, d2: float) -> NDArray:
    """P(F > x) for F ~ F(d1, d2) (regularised incomplete beta; scipy.stats is not imported)."""
    x = np.asarray(x, dtype=np.float64)
    return np.asarray(betainc(d2 / 2.0, d1 / 2.0, d2 / (d2 + d1 * np.maximum(x, 0.0))))


def _grid(s: ResidualSeries, h: float) -> tuple[NDArray, NDArray]:
    """Residuals (L, 3) and mask (L,) on the grid of step h (zeros where no accepted sample)."""
    k = np.round((s.t_s - s.t_s[0]) / h).astype(np.int64)
    length = int(k[-1]) + 1
    x = np.zeros((length, 3))
    m = np.zeros(length)
    keep = s.accepted & np.concatenate([[True], np.diff(k) > 0])
    x[k[keep]] = s.e[keep]
    m[k[keep]] = 1.0
    return x, m


def whiteness_test(
    series: Sequence[ResidualSeries], sample_period_s: float, line_freqs_hz: Sequence[float] = (), *,
    alpha: float = WHITENESS_ALPHA, max_lags: int = MAX_LAGS,
) -> Whiteness:
    """Steps 1-4 of the module docstring and the effective-dof factor, pooled over the segments."""
    h = float(sample_period_s)
    f_nyq = 0.5 / h
    s_low, s_high = np.zeros(3), np.zeros(3)
    n_low = n_high = 0
    r_x = np.zeros((max_lags + 1, 3))
    r_m = np.zeros(max_lags + 1)
    band = (float("nan"),) * 3
    lines = np.asarray(list(line_freqs_hz), dtype=np.float64)
    for s in series:
        x, m = _grid(s, h)
        length = x.shape[0]
        f = np.arange(length // 2 + 1) / (length * h)
        p = np.abs(np.fft.rfft(x, axis=0)) ** 2
        f_lo = CUTOFF_MARGIN * s.cutoff_hz
        f_mid = 0.5 * (f_lo + f_nyq)
        use = (f >= f_lo) & (f < f_nyq * (1.0 - 1e-9)) & (f > 0)
        if lines.size:
            use &= np.min(np.abs(f[:, None] - lines[None, :]), axis=1) > 2.0 / (length * h)
        lo, hi = use & (f < f_mid), use & (f >= f_mid)
        s_low += p[lo].sum(axis=0)
        s_high += p[hi].sum(axis=0)
        n_low += int(lo.sum())
        n_high += int(hi.sum())
        if np.isnan(band[0]):
            band = (float(f_lo), float(f_mid), float(f_nyq))
        nfft = 2 * length
        lags = min(max_lags + 1, length)
        r_x[:lags] += np.fft.irfft(np.abs(np.fft.rfft(x, nfft, axis=0)) ** 2, nfft, axis=0)[:lags]
        r_m[:lags] += np.fft.irfft(np.abs(np.fft.rfft(m, nfft)) ** 2, nfft)[:lags]
    with np.errstate(invalid="ignore", divide="ignore"):
        acov = r_x / r_m[:, None]
        rho = np.nan_to_num(acov[1:] / acov[0])
    dof_factor = 1.0 / (1.0 + 2.0 * np.sum(rho**2, axis=0))
    tested = n_low >= MIN_BINS and n_high >= MIN_BINS and bool(np.all(s_high > 0))
    if not tested:
        return Whiteness(np.full(3, np.nan), np.full(3, np.nan), 2 * n_low, 2 * n_high, band, rho, dof_factor,
                         False, False, alpha)
    ratio = (s_low / n_low) / (s_high / n_high)
    p_value = f_sf(ratio, 2.0 * n_low, 2.0 * n_high)
    return Whiteness(p_value, ratio, 2 * n_low, 2 * n_high, band, rho, dof_factor, True,
                     bool(np.min(p_value) < alpha / 3.0), alpha)


def sigma_interval(sigma: NDArray, dof: NDArray | float, level: float = 0.95) -> NDArray:
    """Two-sided chi-square interval (3, 2) of sigma (3,) estimated with dof degrees of freedom:
    sigma sqrt(dof / chi2_ppf((1 +- level)/2, dof))."""
    nu = np.broadcast_to(np.asarray(dof, dtype=np.float64), np.shape(sigma))
    lo = sigma * np.sqrt(nu / chi2_ppf(0.5 + level / 2.0, nu))
    hi = sigma * np.sqrt(nu / chi2_ppf(0.5 - level / 2.0, nu))
    return np.stack([lo, hi], axis=-1)
