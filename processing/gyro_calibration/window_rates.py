"""The star-tracker side of the gyro alignment of paper 000 (steps ii-iii of
:mod:`processing.gyro_calibration.alignment`): the calibration intervals tiled into windows of 12..18
star-tracker samples, and in each window the MRPs fitted by a 5th-order least-squares polynomial and
differentiated into the star-tracker rate (inverse MRP kinematics) on the T_p grid, with the rate noise
gain of every output sample. The estimate itself (QUEST, scale factor, drift, observability, covariance)
is in :mod:`processing.gyro_calibration.alignment`.

Times s, rates rad/s, angles rad, quaternions (..., 4) scalar first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.attitude.mrp_kinematics import rate_from_mrp

__all__ = [
    "POLY_DEGREE",
    "AlignmentError",
    "WindowRates",
    "alignment_windows",
    "star_tracker_window_rates",
]

FloatArray = NDArray[np.float64]

POLY_DEGREE = 5
"""Degree of the star-tracker MRP polynomial in a window (000: 5)."""


class AlignmentError(ValueError):
    """Not enough or inconsistent data for the alignment (no windows, shapes)."""

def alignment_windows(
    t_s: ArrayLike, eligible: ArrayLike, *, n_min: int = 12, n_max: int = 18, max_spacing_s: float | None = None
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Tile runs of eligible star-tracker samples into windows of n_min..n_max samples (000: 12..18).

    t_s (K,) sample times [s]; eligible (K,) bool (class MT_alpha and gyro data on both sides). A run
    is a maximal sequence of eligible samples with spacing <= max_spacing_s (default 1.5 x the median
    spacing). A run of L samples gives floor(L / n_max) windows of n_max samples, plus one of the
    remaining L mod n_max if that is >= n_min (the longest windows carry the most information: the
    rate error of a window falls like n^-3/2). Returns the start and stop (exclusive) sample indices
    (W,) of the windows, in time order.
    """
    t = np.asarray(t_s, dtype=np.float64)
    ok = np.asarray(eligible, dtype=bool)
    if t.ndim != 1 or ok.shape != t.shape:
        raise AlignmentError(f"expected t_s (K,) and eligible (K,), got {t.shape} and {ok.shape}")
    if not 2 <= n_min <= n_max:
        raise AlignmentError(f"need 2 <= n_min <= n_max, got {n_min}, {n_max}")
    if t.size < 2:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    spacing = max_spacing_s if max_spacing_s is not None else 1.5 * float(np.median(np.diff(t)))
    brk = np.ones(t.size, dtype=bool)
    brk[1:] = (np.diff(t) > spacing) | ~ok[1:] | ~ok[:-1]
    run_start = np.flatnonzero(brk & ok)
    run_id = np.cumsum(brk) - 1
    lengths = np.bincount(run_id[ok], minlength=run_id[-1] + 1)[run_id[run_start]]
    starts: list[int] = []
    stops: list[int] = []
    for a, n in zip(run_start.tolist(), lengths.tolist(), strict=True):  # one iteration per run (tens)
        if n < n_min:
            continue
        sizes = [n_max] * (n // n_max)
        if n % n_max >= n_min:
            sizes.append(n % n_max)
        edges = a + np.concatenate([[0], np.cumsum(sizes)])
        starts.extend(edges[:-1].tolist())
        stops.extend(edges[1:].tolist())
    return np.asarray(starts, dtype=np.intp), np.asarray(stops, dtype=np.intp)


@dataclass(frozen=True)
class WindowRates:
    """Star-tracker-derived rates in the alignment windows (000, steps ii-iii).

    t_s (n,): the T_p grid of every window (from its first to its last sample); window (n,) index;
    w_A_rad_s (n, 3): rate of the star-tracker frame in its own axes; rate_variance_s2 (n,): variance
    of each rate component per unit variance of the star-tracker angle noise [1/s^2] (the polynomial
    derivative's error grows from the centre to the ends of a window by a factor ~6 in std); starts,
    stops (W,): sample ranges; residual_rms_rad (W, 3): rms of the polynomial fit residuals as angles
    (4 sigma) per axis, with the degrees of freedom n_j - 6 (an estimate of the star-tracker noise);
    rate_noise_gain (n, width): the rate error of each T_p sample per unit angle noise at each star-tracker
    sample of its window (the k-th from the window's start; zero beyond its end): e_i = sum_k gain_ik n_k,
    so rate_variance_s2 = sum_k gain_ik^2 (processing.gyro_calibration.observability.noise_meat).
    """

    t_s: FloatArray
    window: NDArray[np.intp]
    w_A_rad_s: FloatArray
    rate_variance_s2: FloatArray
    starts: NDArray[np.intp]
    stops: NDArray[np.intp]
    residual_rms_rad: FloatArray
    rate_noise_gain: FloatArray | None = None


def star_tracker_window_rates(
    t_s: ArrayLike, q_IS: ArrayLike, starts: ArrayLike, stops: ArrayLike, *, t_p_s: float = 0.125,
    degree: int = POLY_DEGREE,
) -> WindowRates:
    """Fit each window's star-tracker MRPs by a degree-5 LSQ polynomial and differentiate (000, ii-iii).

    t_s (K,) [s], q_IS (K, 4); starts, stops (W,) sample ranges (alignment_windows). The MRPs are those
    of the attitude relative to the window's middle sample, sigma_k = sigma(q_mid^-1 o q_k) (small, no
    shadow switching; the rate of S relative to I is the same); local time x = (t - t_c) / h in [-1, 1].
    Rates w^a = F^w(sigma(x), d sigma / dt) on t_first + j t_p_s <= t_last. Vectorised over windows
    (padded to the longest). Returns :class:`WindowRates`.
    """
    t = np.asarray(t_s, dtype=np.float64)
    q = rotations.quat_normalize(np.asarray(q_IS, dtype=np.float64))
    a = np.asarray(starts, dtype=np.intp)
    b = np.asarray(stops, dtype=np.intp)
    if a.size == 0:
        raise AlignmentError("no alignment windows: no calibration interval of at least n_min samples")
    n_w = b - a
    if np.any(n_w < degree + 2):
        raise AlignmentError(f"windows need at least degree + 2 = {degree + 2} samples, got {int(n_w.min())}")
    w_count, width = a.size, int(n_w.max())
    pos = np.arange(width)
    mask = pos[None, :] < n_w[:, None]
    idx = np.where(mask, a[:, None] + pos, a[:, None])
    mid = a + n_w // 2
    t_c = 0.5 * (t[a] + t[b - 1])
    half = 0.5 * (t[b - 1] - t[a])
    x = (t[idx] - t_c[:, None]) / half[:, None]
    q_rel = rotations.quat_multiply(rotations.quat_conjugate(q[mid])[:, None, :], q[idx])
    sigma = rotations.quat_to_mrp(q_rel)  # (W, width, 3)
    v = np.where(mask[..., None], x[..., None] ** np.arange(degree + 1), 0.0)
    vt = np.swapaxes(v, 1, 2)
    coef = np.linalg.solve(vt @ v, vt @ np.where(mask[..., None], sigma, 0.0))  # (W, degree + 1, 3)
    resid = np.where(mask[..., None], sigma - v @ coef, 0.0)
    rms = 4.0 * np.sqrt(np.sum(resid**2, axis=1) / (n_w - degree - 1)[:, None])
    counts = np.floor((t[b - 1] - t[a]) / t_p_s + 1e-9).astype(np.intp) + 1
    window = np.repeat(np.arange(w_count), counts)
    offset = np.arange(window.size) - np.repeat(np.cumsum(counts) - counts, counts)
    tp = t[a][window] + offset * t_p_s
    xp = (tp - t_c[window]) / half[window]
    powers = xp[:, None] ** np.arange(degree + 1)
    dpowers = np.zeros_like(powers)
    dpowers[:, 1:] = np.arange(1, degree + 1) * powers[:, :-1]
    c = coef[window]
    s_fit = np.einsum("np,npk->nk", powers, c)
    s_dot = np.einsum("np,npk->nk", dpowers, c) / half[window][:, None]
    # Var(sigma') = var_sigma d^T (V^T V)^-1 d / half^2; angle noise = 4 sigma noise and w ~ 4 sigma'.
    # The rate error per unit angle noise n_k at the window's samples: e_i = d_i^T G V^T (n / 4) 4 / half.
    gram_inv = np.linalg.inv(vt @ v)
    vg = v @ gram_inv  # (W, width, degree + 1)
    d_pad = np.zeros((w_count, int(counts.max()), degree + 1))  # the T_p samples of each window, padded
    d_pad[window, offset] = dpowers
    gain = (d_pad @ np.swapaxes(vg, 1, 2))[window, offset] / half[window][:, None]  # (n, width)
    var = np.sum(gain**2, axis=1)
    return WindowRates(t_s=tp, window=window, w_A_rad_s=rate_from_mrp(s_fit, s_dot), rate_variance_s2=var,
                       starts=a, stops=b, residual_rms_rad=rms, rate_noise_gain=gain)

