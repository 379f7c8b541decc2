"""Building blocks of data screening (002): robust statistics, spike/stuck/time-grid checks, GNSS
orbit quantities (energy integral, Hermite interpolation, local velocity fits). Pure numpy."""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray

from processing.units import J2_EARTH, MU_EARTH_M3_S2, NS_PER_S, OMEGA_EARTH_RAD_S, R_EARTH_M


class ScreeningError(ValueError):
    """Inputs the screening cannot use (missing columns, inconsistent lengths)."""


# ------------------------------------------------------------------------------------------------
# Generic building blocks.


ROLLING_CHUNK_ROWS = 1 << 15
"""Rows of one block of :func:`rolling_median`: its windows are copied, (rows, d, 2 h + 1) floats per block,
so the memory it needs is bounded by the block, not by the stream (~10 MB for 3 columns, h = 5)."""


def rolling_median(x: ArrayLike, half_window: int, exclude: ArrayLike | None = None, *,
                   leave_out_centre: bool = False, chunk_rows: int = ROLLING_CHUNK_ROWS) -> NDArray[np.float64]:
    """Centred running median over +-half_window samples, per column, ignoring excluded and NaN rows.

    x: (n,) or (n, d). Windows shrink at the ends. leave_out_centre: the median of the neighbours
    only (the sample itself excluded). Returns the same shape. Computed in blocks of ``chunk_rows`` rows
    (each row's median is its own: the result does not depend on the block size).
    """
    a = np.asarray(x, dtype=np.float64)
    two_d = a.ndim == 2
    a2 = a if two_d else a[:, None]
    if exclude is not None:
        a2 = np.where(np.asarray(exclude, dtype=bool)[:, None], np.nan, a2)
    pad = np.full((half_window, a2.shape[1]), np.nan)
    padded = np.concatenate([pad, a2, pad])
    med = np.empty(a2.shape, dtype=np.float64)
    step = max(1, int(chunk_rows))
    for lo in range(0, a2.shape[0], step):
        hi = min(lo + step, a2.shape[0])
        win = sliding_window_view(padded[lo:hi + 2 * half_window], 2 * half_window + 1, axis=0)  # (rows, d, w)
        if leave_out_centre:  # the neighbours only, in an array of our own that is then sorted in place
            own = np.concatenate([win[:, :, :half_window], win[:, :, half_window + 1:]], axis=-1)
            med[lo:hi] = nanmedian_last_axis(own, overwrite=True)
        else:
            med[lo:hi] = nanmedian_last_axis(win)  # all-NaN windows (long rejected runs) give NaN
    return med if two_d else med[:, 0]


def nanmedian_last_axis(win: NDArray[np.float64], *, overwrite: bool = False) -> NDArray[np.float64]:
    """``np.nanmedian(win, axis=-1)`` (the same values; NaN where a row has none) by one sort of the short
    last axis: numpy takes a masked-array route for short axes that costs ~5-10x more on long series.
    overwrite: sort ``win`` itself (the caller's own array) instead of a copy."""
    k = np.count_nonzero(~np.isnan(win), axis=-1)
    if overwrite:
        win.sort(axis=-1)  # NaN sort last
        s = win
    else:
        s = np.sort(win, axis=-1)
    lo = np.take_along_axis(s, np.maximum((k - 1) // 2, 0)[..., None], axis=-1)[..., 0]
    hi = np.take_along_axis(s, (k // 2)[..., None], axis=-1)[..., 0]
    return np.where(k == 0, np.nan, np.where(k % 2 == 1, lo, (lo + hi) / 2))


_CHI_MEDIAN = {1: 0.6744897501960817, 2: 1.1774100225154747, 3: 1.5381722544550522, 4: 1.8322150007462898}
"""Median of the chi distribution with d degrees of freedom (the norm of d standard normals)."""


def hampel(x: ArrayLike, half_window: int, k: float, *, floor: float = 0.0, exclude: ArrayLike | None = None
           ) -> tuple[NDArray[np.float64], float, NDArray[np.bool_]]:
    """Spike test (Hampel): distance of each sample (vector norm over columns) to the running median
    of its neighbours (+-half_window, itself left out).

    Returns (distance (n,), threshold, flagged (n,)). The threshold is k times the robust noise scale
    median(distance) / median(chi_d) (about sigma for Gaussian noise of sigma per component: the
    neighbours' median adds ~pi / (4 half_window) of variance), at least ``floor``.
    """
    a = np.asarray(x, dtype=np.float64)
    a2 = a if a.ndim == 2 else a[:, None]
    med = rolling_median(a2, half_window, exclude, leave_out_centre=True)
    dist = np.linalg.norm(a2 - med, axis=1)
    finite = np.isfinite(dist)
    d = a2.shape[1]
    scale = float(np.median(dist[finite])) / _CHI_MEDIAN.get(d, np.sqrt(d - 0.5)) if np.any(finite) else 0.0
    threshold = max(k * scale, floor)
    return dist, threshold, finite & (dist > threshold)


def stuck(values: ArrayLike, min_run: int, ignore: ArrayLike | None = None) -> NDArray[np.bool_]:
    """Rows repeating the previous row exactly, in runs of at least ``min_run`` equal rows (the first
    row of a run is not flagged). values: (n,) or (n, d); ignore: rows never counted (e.g. dark panels)."""
    a = np.asarray(values)
    a2 = a if a.ndim == 2 else a[:, None]
    n = a2.shape[0]
    same = np.zeros(n, dtype=bool)
    if n > 1:
        same[1:] = np.all(a2[1:] == a2[:-1], axis=1)
    if ignore is not None:
        same &= ~np.asarray(ignore, dtype=bool)
    # run id increases where a row differs from the previous one
    run = np.cumsum(~same)
    lengths = np.bincount(run)
    return same & (lengths[run] >= min_run)


def time_grid(t_ns: ArrayLike, tolerance: float) -> tuple[NDArray[np.bool_], NDArray[np.float64], int]:
    """Duplicated times and samples both of whose intervals are off the nominal grid.

    Returns (flagged (n,), deviation (n,) fraction of the period, period_ns).
    """
    t = np.asarray(t_ns, dtype=np.int64)
    n = t.size
    if n < 3:
        return np.zeros(n, dtype=bool), np.zeros(n), 0
    dt = np.diff(t)
    positive = dt[dt > 0]
    period = int(np.median(positive)) if positive.size else 0
    if period <= 0:
        return np.zeros(n, dtype=bool), np.zeros(n), 0
    ratio = dt / period
    off = np.abs(ratio - np.round(ratio))
    off = np.where(dt > 0, off, 0.5)
    before = np.concatenate([[0.0], off])
    after = np.concatenate([off, [0.0]])
    dev = np.minimum(np.where(np.arange(n) > 0, before, after), np.where(np.arange(n) < n - 1, after, before))
    dup = np.concatenate([[False], dt == 0])
    flagged = dup | (dev > tolerance)
    return flagged, dev, period


def time_grid_irregular(t_ns: ArrayLike, tolerance: float, k: float = 6.0
                        ) -> tuple[NDArray[np.bool_], NDArray[np.float64], int, float]:
    """:func:`time_grid` with a tolerance that accounts for the sampling jitter seen in the data.

    The signed offsets of the intervals from whole multiples of the period have a robust scale s
    (1.4826 MAD); a clock whose tags scatter that much is not faulty, so the tolerance is max(tolerance,
    k s). When that reaches half a period the stream has no grid to judge (irregular sampling, e.g. tags
    of an asynchronous downlink): only duplicated times are flagged (tolerance 0.5). Returns (flagged (n,),
    deviation (n,), period_ns, the tolerance used)."""
    t = np.asarray(t_ns, dtype=np.int64)
    tol = float(tolerance)
    if t.size >= 3:
        dt = np.diff(t)
        positive = dt[dt > 0]
        if positive.size >= 2:
            ratio = positive / float(np.median(positive))
            off = ratio - np.round(ratio)
            scale = 1.4826 * float(np.median(np.abs(off - np.median(off))))
            tol = min(max(tol, k * scale), 0.5)
    flagged, dev, period = time_grid(t, tol)
    return flagged, dev, period, tol


def quantisation_step(values: ArrayLike) -> NDArray[np.float64]:
    """Least significant bit per column of values (n,) or (n, d), estimated from the data (0 when the
    values are not on a grid).

    The step q is the smallest positive difference between distinct sorted values; the column is
    quantised when (nearly) every value is a whole multiple of q (|v / q - round(v / q)| < 0.01 for 99 %
    of them) and q is not below 1e-12 of the values' magnitude (unquantised floats).
    """
    a = np.asarray(values, dtype=np.float64)
    a2 = a if a.ndim == 2 else a[:, None]
    out = np.zeros(a2.shape[1])
    for j in range(a2.shape[1]):
        col = a2[:, j][np.isfinite(a2[:, j])]
        u = np.unique(col)
        if u.size < 3:
            continue
        d = np.diff(u)
        q = float(np.min(d))
        big = float(np.max(np.abs(u)))
        if q <= 1e-12 * max(big, 1e-300):
            continue
        frac = np.abs(col / q - np.round(col / q))
        if np.mean(frac < 0.01) >= 0.99:
            out[j] = q
    return out


def robust_polyfit(t_s: ArrayLike, y: ArrayLike, degree: int = 1, iterations: int = 5, k: float = 4.0,
                   exclude: ArrayLike | None = None) -> NDArray[np.float64]:
    """Least-squares polynomial of t with iterative rejection of |residual| > k * 1.4826 MAD.

    Returns the fitted values at every t (NaN if fewer than degree + 2 usable samples).
    """
    t = np.asarray(t_s, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    use = np.isfinite(yy) & np.isfinite(t)
    if exclude is not None:
        use &= ~np.asarray(exclude, dtype=bool)
    if use.sum() < degree + 2:
        return np.full(t.shape, np.nan)
    tc = t - np.mean(t[use])
    scale = max(float(np.max(np.abs(tc[use]))), 1.0)
    x = tc / scale
    fit = np.full(t.shape, np.nan)
    for _ in range(iterations):
        coef = np.polyfit(x[use], yy[use], degree)
        fit = np.polyval(coef, x)
        res = yy - fit
        mad = 1.4826 * float(np.median(np.abs(res[use])))
        new = np.isfinite(yy) & (np.abs(res) <= k * max(mad, 1e-300))
        if exclude is not None:
            new &= ~np.asarray(exclude, dtype=bool)
        if new.sum() < degree + 2 or np.array_equal(new, use):
            break
        use = new
    return fit


def attribute_increments(big: ArrayLike) -> NDArray[np.bool_]:
    """Samples to blame for failing increments between consecutive samples.

    big: (n - 1,) increment k (between samples k and k + 1) failed. A sample is an outlier when both
    of its increments fail (an end sample when its only increment fails); a failing increment that no
    outlier explains is a step, blamed on its later sample. Returns (n,) bool.
    """
    b = np.asarray(big, dtype=bool)
    n = b.size + 1
    prev_big = np.concatenate([[False], b])
    next_big = np.concatenate([b, [False]])
    first = np.arange(n) == 0
    last = np.arange(n) == n - 1
    outlier = (prev_big & next_big) | (prev_big & last & (n > 1)) | (next_big & first & (n > 1))
    explained = np.concatenate([[False], outlier[:-1]]) | outlier
    step = prev_big & ~explained
    return outlier | step


# ------------------------------------------------------------------------------------------------
# GNSS quantities.


def inertial_velocity_E(r_E: ArrayLike, v_E: ArrayLike) -> NDArray[np.float64]:
    """Inertial velocity in ITRF axes, v_E + w x r_E (w along the ITRF z axis; polar motion neglected)."""
    r = np.asarray(r_E, dtype=np.float64)
    return np.asarray(v_E, dtype=np.float64) + np.cross([0.0, 0.0, OMEGA_EARTH_RAD_S], r)


def energy_h(r_E: ArrayLike, v_E: ArrayLike, model: str = "j2") -> NDArray[np.float64]:
    """The energy constant h of 002 eq. 15, h = v^2 - 2 U (m^2/s^2), with the inertial speed.

    model "two_body": U = mu / r (the paper); "j2": U = mu / r (1 - J2_EARTH (R/r)^2 (3 sin^2 lat - 1) / 2),
    the potential including J2_EARTH, for which h is conserved (axisymmetric field).
    r_E, v_E: (..., 3) ITRF m, m/s (velocity relative to the Earth).
    """
    r = np.asarray(r_E, dtype=np.float64)
    v = inertial_velocity_E(r, v_E)
    rn = np.linalg.norm(r, axis=-1)
    u = MU_EARTH_M3_S2 / rn
    if model == "j2":
        s = r[..., 2] / rn
        u = u * (1.0 - J2_EARTH * (R_EARTH_M / rn) ** 2 * 0.5 * (3.0 * s * s - 1.0))
    elif model != "two_body":
        raise ScreeningError(f"energy model must be 'j2' or 'two_body', got {model!r}")
    return np.sum(v * v, axis=-1) - 2.0 * u


def energy_tolerance(r_E: ArrayLike, v_E: ArrayLike, dr_m: float, dv_m_s: float) -> NDArray[np.float64]:
    """dh = 2 (v dv + mu / r^2 dr) of 002 (the differential of h below eq. 15), m^2/s^2."""
    r = np.asarray(r_E, dtype=np.float64)
    v = inertial_velocity_E(r, v_E)
    rn = np.linalg.norm(r, axis=-1)
    return 2.0 * (np.linalg.norm(v, axis=-1) * dv_m_s + MU_EARTH_M3_S2 / rn**2 * dr_m)


def hermite_state(t_ns: ArrayLike, r: ArrayLike, v: ArrayLike, t_query_ns: ArrayLike, max_gap_s: float
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Cubic Hermite interpolation of positions with their velocities (same frame, e.g. ITRF).

    t_ns: (n,) increasing; r, v: (n, 3); t_query_ns: (m,). NaN outside [t0, tn] and inside intervals
    longer than max_gap_s. Returns r (m, 3), v (m, 3).
    """
    t = np.asarray(t_ns, dtype=np.int64)
    tq = np.asarray(t_query_ns, dtype=np.int64)
    rr, vv = np.asarray(r, dtype=np.float64), np.asarray(v, dtype=np.float64)
    out_r = np.full((tq.size, 3), np.nan)
    out_v = np.full((tq.size, 3), np.nan)
    if t.size < 2:
        return out_r, out_v
    k = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, t.size - 2)
    h = (t[k + 1] - t[k]) / NS_PER_S
    s = ((tq - t[k]) / NS_PER_S) / np.where(h > 0, h, 1.0)
    ok = (tq >= t[0]) & (tq <= t[-1]) & (h > 0) & (h <= max_gap_s)
    s_ = s[:, None]
    h_ = h[:, None]
    h00, h10 = 2 * s_**3 - 3 * s_**2 + 1, s_**3 - 2 * s_**2 + s_
    h01, h11 = -2 * s_**3 + 3 * s_**2, s_**3 - s_**2
    rq = h00 * rr[k] + h10 * h_ * vv[k] + h01 * rr[k + 1] + h11 * h_ * vv[k + 1]
    d00, d10 = (6 * s_**2 - 6 * s_) / h_, 3 * s_**2 - 4 * s_ + 1
    d01, d11 = (-6 * s_**2 + 6 * s_) / h_, 3 * s_**2 - 2 * s_
    with np.errstate(invalid="ignore", divide="ignore"):
        vq = d00 * rr[k] + d10 * vv[k] + d01 * rr[k + 1] + d11 * vv[k + 1]
    out_r[ok] = rq[ok]
    out_v[ok] = vq[ok]
    return out_r, out_v


def jerk_bound_m_s3(r_E: ArrayLike, v_E: ArrayLike) -> NDArray[np.float64]:
    """A bound on |d^3 r / dt^3| of an Earth-fixed orbit state (m/s^3): the central-field jerk
    2 mu v / r^3 plus the rotating frame's 2 w mu / r^2 (9e-3 + 1.2e-3 m/s^3 in LEO)."""
    r = np.linalg.norm(np.asarray(r_E, dtype=np.float64), axis=-1)
    v = np.linalg.norm(inertial_velocity_E(r_E, v_E), axis=-1)
    return 2.0 * MU_EARTH_M3_S2 * v / r**3 + 2.0 * OMEGA_EARTH_RAD_S * MU_EARTH_M3_S2 / r**2


def local_velocity_fit(t_ns: ArrayLike, r: ArrayLike, half_window: int, exclude: ArrayLike | None = None
                       ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Slope at each sample of a quadratic fitted to the positions of +-half_window neighbours.

    Returns (v_fit (n, 3), gain (n,), cubic_gain (n,)): the slope's standard deviation is gain * sigma_r
    for white position noise sigma_r, and a cubic term c t^3 of the trajectory biases it by
    cubic_gain * |c| (|c| <= jerk / 6). Excluded (and missing) neighbours are left out; NaN where < 4
    remain.
    """
    t = (np.asarray(t_ns, dtype=np.int64) - int(np.asarray(t_ns)[0])) / NS_PER_S
    rr = np.asarray(r, dtype=np.float64)
    n = t.size
    w = np.ones(n) if exclude is None else (~np.asarray(exclude, dtype=bool)).astype(float)
    w = np.where(np.isfinite(rr).all(axis=1), w, 0.0)
    pad = half_window
    tp = np.concatenate([np.full(pad, np.nan), t, np.full(pad, np.nan)])
    rp = np.concatenate([np.full((pad, 3), np.nan), rr, np.full((pad, 3), np.nan)])
    wp = np.concatenate([np.zeros(pad), w, np.zeros(pad)])
    tw = sliding_window_view(tp, 2 * pad + 1)  # (n, W)
    rw = np.moveaxis(sliding_window_view(rp, 2 * pad + 1, axis=0), 1, 2)  # (n, W, 3)
    ww = sliding_window_view(wp, 2 * pad + 1)
    dt = tw - t[:, None]
    ww = np.where(np.isfinite(dt), ww, 0.0)
    dt = np.nan_to_num(dt)
    rw = np.nan_to_num(rw)
    x = np.stack([np.ones_like(dt), dt, dt * dt], axis=-1)  # (n, W, 3)
    a = np.einsum("nw,nwi,nwj->nij", ww, x, x)
    enough = ww.sum(axis=1) >= 4
    a = np.where(enough[:, None, None], a, np.eye(3))
    with np.errstate(all="ignore"):
        ainv = np.linalg.inv(a)
        b = np.einsum("nw,nwi,nwk->nik", ww, x, rw)  # (n, 3 params, 3 axes)
        coef = ainv @ b
        cubic = ainv @ np.einsum("nw,nwi,nw->ni", ww, x, dt**3)[..., None]
    v = np.where(enough[:, None], coef[:, 1, :], np.nan)
    gain = np.where(enough, np.sqrt(np.abs(ainv[:, 1, 1])), np.nan)
    return v, gain, np.where(enough, np.abs(cubic[:, 1, 0]), np.nan)
