"""Least-squares fit of a polynomial trend plus the 003 §1.3 sine series (the orbital-attitude smoother).

Split from processing.star_tracker.orbital_attitude, whose :func:`smooth_attitude` fits each Rodrigues
component with :func:`fit_trend_sines`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from processing.signal.sine_series import fit_sine_series, select_harmonics, sine_series_design


def _trend_sines_design(tau: NDArray, trend_degree: int, harmonics: int) -> NDArray:
    """[P_0(x) .. P_d(x), sin(pi tau) .. sin(pi M tau)] (N, d + 1 + M), x = 2 tau - 1 (Legendre)."""
    return np.column_stack([np.polynomial.legendre.legvander(2.0 * tau - 1.0, trend_degree),
                            sine_series_design(tau, harmonics, 0.0, 1.0)[:, 2:]])


def fit_trend_sines(t_s: NDArray, y: NDArray, *, trend_degree: int = 3, harmonics: int | None = None,
                    max_harmonics: int | None = None) -> tuple[NDArray, int]:
    """Least-squares fit of a degree-d polynomial trend plus the 003 §1.3 sine series to y (N,).

    t_s (N,) [s] increasing; tau = (t - t1)/T. With d = 1 this is 003's a_{M+1} + a_{M+2}(t - t1) +
    sum a_m sin(pi m tau) (then processing.signal.sine_series does the fit). Why d = 3 is the default for
    attitude: integrating by parts, the sine coefficients of the detrended signal g are
    b_m = 2/(m pi) [g(0) - (-1)^m g(T)] - 2 T^2/(m pi)^3 [g''(0) - (-1)^m g''(T)] + O(m^-5); a linear
    trend removes the first term only, so a slow motion that does not start and end with zero
    curvature needs ~25-30 harmonics to be followed to 1 arcsec, each passing on noise; a cubic trend
    also absorbs the end curvature (coefficients ~m^-5) and ~15 harmonics do (seed-003 simulator:
    pitch error 3.9-4.5" instead of 4.3-5.8", harmonics 12-19 instead of 18-38). M by generalised
    cross-validation over 0..max_harmonics (default (N - 2)/4) from one Householder QR of the widest
    design (the columns are nested). Returns (fitted values (N,), M).
    """
    n = t_s.size
    tau = (t_s - t_s[0]) / (t_s[-1] - t_s[0])
    if trend_degree == 1:
        cap = max(0, (n - 2) // 4) if max_harmonics is None else max_harmonics
        m = harmonics if harmonics is not None else select_harmonics(t_s, y, cap, criterion="gcv")[0]
        m = int(min(m, n - 3))
        return fit_sine_series(t_s, y, m).fitted, m
    base = trend_degree + 1
    cap = max(0, min((n - 2) // 4 if max_harmonics is None else max_harmonics, n - base - 1))
    top = cap if harmonics is None else int(min(harmonics, n - base - 1))
    a = _trend_sines_design(tau, trend_degree, top)
    q, r = np.linalg.qr(a)
    proj = q.T @ y
    if harmonics is None:
        resid0 = float(np.sum((y - q @ proj) ** 2))
        tail = np.concatenate([np.cumsum((proj ** 2)[::-1])[::-1], [0.0]])
        ms = np.arange(cap + 1)
        n_par = base + ms
        rss = resid0 + tail[n_par]
        score = np.where(n > n_par, n * rss / np.maximum(n - n_par, 1) ** 2, np.inf)
        m = int(ms[int(np.argmin(score))])
    else:
        m = top
    p = base + m
    coef = np.linalg.solve(r[:p, :p], proj[:p])
    return a[:, :p] @ coef, m
