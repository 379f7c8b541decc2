"""Allan deviation of gyro data and the noise terms read from it, with confidence intervals.

The deviation itself is allantools' (Wallin et al.; W. J. Riley, NIST SP 1065, 2008): overlapping Allan
deviation of rates (``oadev``, frequency data) or of angles (phase data; the gap-resistant ``gradev`` when
samples are missing, NaN). Confidence intervals of each point from its equivalent degrees of freedom
(Greenhall & Riley 2004, ``allantools.edf_greenhall``) for the noise type that dominates there, chi² as
in SP 1065 §5.3.

The noise terms (IEEE Std 952-1997, Annex C) are fitted to the Allan variance per axis,

    sigma²(tau) = 3 Q² / tau² + N² / tau + (2 ln 2 / pi) B² + K² tau / 3,

Q angle white noise (quantization; the star-tracker noise when the data are gyro-minus-star-tracker
angles), N angle random walk, B bias instability (flicker rate noise, the floor 0.664 B), K rate random
walk. The fit is linear in (Q², N², B², K²): weighted non-negative least squares with the variance of each
point 2 sigma_model⁴ / edf, iterated so that weights and edf follow the model. The points of an overlapping
deviation at octave-spaced taus are correlated (neighbours share data), which independent weights ignore:
the covariance is multiplied by ``CORRELATION_INFLATION`` (measured on simulated white, flicker and random-walk
noise, tests/processing/signal/test_allan.py, so that the 95 % intervals cover the truth). A term whose 95 %
interval reaches zero is not determined by the data (value None, its upper bound kept).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import nnls

from processing.estimation.chi2 import chi2_ppf

FloatArray = NDArray[np.float64]

TERMS = ("angle_white_noise", "angle_random_walk", "bias_instability", "rate_random_walk")
"""Names of the four terms (units rad, rad/sqrt(s), rad/s, rad/s/sqrt(s))."""
FLICKER_FLOOR = 2.0 * np.log(2.0) / np.pi
ALPHAS = (2, 0, -1, -2)
"""Power-law exponent of each term's phase... (white PM, white FM, flicker FM, random-walk FM)."""
CORRELATION_INFLATION = 4.0
Z95 = 1.959963984540054
MIN_POINTS = 4


class AllanError(ValueError):
    """Data that give no Allan deviation (too short, not (N, k), no finite values)."""


@dataclass(frozen=True)
class AllanDeviation:
    """tau_s (T,); adev (T, k) per axis (NaN where undefined); lo, hi (T, k) 95 % bounds; edf (T, k);
    n (T,) terms in each estimate; rate_hz; kind "rates" or "angles"; n_points: phase points of the series."""

    tau_s: FloatArray
    adev: FloatArray
    lo: FloatArray
    hi: FloatArray
    edf: FloatArray
    n: FloatArray
    rate_hz: float
    kind: str
    n_points: int


@dataclass(frozen=True)
class NoiseTerm:
    """One term per axis: value (k,) (NaN where not determined), lo/hi (k,) 95 % bounds (lo 0 when the
    interval reaches zero), determined (k,) bool."""

    value: FloatArray
    lo: FloatArray
    hi: FloatArray
    determined: NDArray[np.bool_]


@dataclass(frozen=True)
class NoiseFit:
    """terms name -> NoiseTerm (TERMS); model_adev (T, k) of the fit; used (T, k) points in the fit;
    chi2_per_dof (k,) of the weighted residuals (about 1 when the model fits)."""

    terms: dict[str, NoiseTerm]
    model_adev: FloatArray
    used: NDArray[np.bool_]
    chi2_per_dof: FloatArray


def _design(tau: FloatArray) -> FloatArray:
    return np.stack([3.0 / tau**2, 1.0 / tau, np.full_like(tau, FLICKER_FLOOR), tau / 3.0], axis=-1)


def _octave_taus(n: int, rate_hz: float) -> FloatArray:
    m = 2.0 ** np.arange(0, int(np.floor(np.log2(max(n // 3, 1)))) + 1)
    return np.asarray(m / rate_hz, dtype=np.float64)


def allan_deviation(data: FloatArray, rate_hz: float, kind: str = "rates") -> AllanDeviation:
    """Overlapping Allan deviation per column of data (N, k) sampled at rate_hz: ``rates`` (frequency
    data, rad/s) or ``angles`` (phase data, rad; NaN for missing samples: gap-resistant estimator).
    Octave-spaced taus from 1/rate to N/(3 rate). Bounds from Greenhall's edf for white rate noise here
    (refined by :func:`fit_noise`)."""
    x = np.asarray(data, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] < 3 * (2 ** 2) or rate_hz <= 0:
        raise AllanError(f"need (N, k) data with N >= 12 and a positive rate, got {x.shape} at {rate_hz} Hz")
    if kind not in ("rates", "angles"):
        raise AllanError(f"kind must be 'rates' or 'angles', got {kind!r}")
    import allantools  # here, not at import: it pulls scipy.signal and scipy.stats (~2.5 s into every job process)

    taus = _octave_taus(x.shape[0], rate_hz)
    adev = np.full((taus.size, x.shape[1]), np.nan)
    counts = np.zeros(taus.size)
    for c in range(x.shape[1]):
        col = x[:, c]
        if kind == "rates":
            if not np.all(np.isfinite(col)):
                raise AllanError("rates must be finite (use angles with NaN for gaps)")
            t, d, _, n = allantools.oadev(col, rate=rate_hz, data_type="freq", taus=taus)
        elif np.all(np.isfinite(col)):
            t, d, _, n = allantools.oadev(col, rate=rate_hz, data_type="phase", taus=taus)
        else:
            t, d, _, n = allantools.gradev(col, rate=rate_hz, data_type="phase", taus=taus)
        idx = np.searchsorted(taus, t)
        adev[idx, c] = d
        counts[idx] = np.maximum(counts[idx], n)
    n_points = x.shape[0] + (1 if kind == "rates" else 0)
    edf = _edf(taus, rate_hz, n_points, np.full(adev.shape, 0))
    lo, hi = _bounds(adev, edf)
    return AllanDeviation(tau_s=taus, adev=adev, lo=lo, hi=hi, edf=edf, n=counts, rate_hz=float(rate_hz), kind=kind,
                          n_points=n_points)


def _edf(taus: FloatArray, rate_hz: float, n_points: int, alpha: NDArray[np.int_]) -> FloatArray:
    """Greenhall's edf of the overlapping Allan variance at each tau for the noise exponent alpha (T, k)."""
    import allantools

    out = np.empty(alpha.shape)
    for i, tau in enumerate(taus):
        m = max(int(round(tau * rate_hz)), 1)
        for c in range(alpha.shape[1]):
            a = int(alpha[i, c])
            try:
                out[i, c] = float(allantools.edf_greenhall(alpha=a, d=2, m=m, N=n_points, overlapping=True))
            except (AssertionError, ValueError, ZeroDivisionError):
                out[i, c] = max(n_points / m - 2.0, 1.0)
    return np.maximum(out, 1.0)


def _bounds(adev: FloatArray, edf: FloatArray) -> tuple[FloatArray, FloatArray]:
    """95 % bounds of a deviation with edf degrees of freedom (NIST SP 1065 eq. 36)."""
    lo = adev * np.sqrt(edf / chi2_ppf(0.975, edf))
    hi = adev * np.sqrt(edf / chi2_ppf(0.025, edf))
    return lo, hi


def fit_noise(ad: AllanDeviation, iterations: int = 4) -> tuple[NoiseFit, AllanDeviation]:
    """The four IEEE 952 terms per axis (module docstring) and the deviation with its bounds from the edf of
    the dominant term at each tau. Needs MIN_POINTS finite points per axis."""
    tau = ad.tau_s
    A = _design(tau)
    k = ad.adev.shape[1]
    n_pts = ad.n_points
    theta = np.zeros((4, k))
    cov = np.zeros((k, 4, 4))
    used = np.isfinite(ad.adev) & (ad.adev > 0)
    edf = ad.edf.copy()
    model = np.where(used, ad.adev**2, np.nan)
    for _ in range(iterations):
        for c in range(k):
            u = used[:, c]
            if np.count_nonzero(u) < MIN_POINTS:
                raise AllanError(f"axis {c}: {int(np.count_nonzero(u))} usable Allan points, need {MIN_POINTS}")
            y = ad.adev[u, c] ** 2
            sd = np.sqrt(2.0 / edf[u, c]) * np.where(np.isfinite(model[u, c]), model[u, c], y)
            Aw, yw = A[u] / sd[:, None], y / sd
            th, _ = nnls(Aw, yw)
            theta[:, c] = th
            active = th > 0
            cv = np.zeros((4, 4))
            # covariance of the free terms; a term held at zero keeps the variance of its own column
            if np.any(active):
                cv[np.ix_(active, active)] = np.linalg.pinv(Aw[:, active].T @ Aw[:, active])
            for j in map(int, np.flatnonzero(~active)):
                others = np.flatnonzero(active)
                cols = np.append(others, j)
                cv[j, j] = np.linalg.pinv(Aw[:, cols].T @ Aw[:, cols])[-1, -1]
            cov[c] = cv * CORRELATION_INFLATION
        model = (A @ theta)
        dominant = np.argmax(A[:, :, None] * theta[None, :, :], axis=1)  # (T, k)
        edf = _edf(tau, ad.rate_hz, n_pts, np.asarray(ALPHAS)[dominant])
    lo, hi = _bounds(ad.adev, edf)
    terms = {}
    for j, name in enumerate(TERMS):
        v, s = theta[j], np.sqrt(cov[:, j, j])
        lo_t = np.sqrt(np.clip(v - Z95 * s, 0.0, None))
        hi_t = np.sqrt(v + Z95 * s)
        det = v - Z95 * s > 0
        terms[name] = NoiseTerm(value=np.where(det, np.sqrt(v), np.nan), lo=lo_t, hi=hi_t, determined=det)
    resid = np.where(used, (ad.adev**2 - model) / (np.sqrt(2.0 / edf) * model), 0.0)
    dof = np.maximum(used.sum(axis=0) - 4, 1)
    fit = NoiseFit(terms=terms, model_adev=np.sqrt(np.clip(model, 0.0, None)), used=used,
                   chi2_per_dof=np.sum(resid**2, axis=0) / dof)
    return fit, AllanDeviation(tau_s=tau, adev=ad.adev, lo=lo, hi=hi, edf=edf, n=ad.n, rate_hz=ad.rate_hz,
                               kind=ad.kind, n_points=ad.n_points)
