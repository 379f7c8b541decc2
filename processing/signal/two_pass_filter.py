"""Two-pass filtering of gyro angle increments (000, figure 1 and eq. 2) and its integration (eq. 7).

Paper 000 (Somov & Butyrin 2016) smooths the gyro's quasi-coordinates (the integrals of the measured
rate, "приращения квазиординат") in two passes:

1. a cubic least-squares polynomial over a sliding window of 9 samples (000: "полиномом 3-го порядка
   в скользящем окне 9 измерений по МНК"), centred on each sample, which gives the smoothed
   quasi-coordinate F^ and its first and second derivatives at the window centre;
2. a quintic polynomial between the centres of adjacent windows that matches F^, F^' and F^'' at both
   ends (000: "сплайновой интерполяции по центрам двух смежных скользящих окон полиномом 5-го
   порядка"), i.e. a C2 quintic Hermite spline through the centres.

The rate w^(t) = dF^/dt is the spline's analytic derivative (000: "по явным аналитическим
соотношениям ... строго согласована с оценкой квазиординаты"), so the rate and the increments are
consistent exactly: the integral of w^ over any interval is F^(t_b) - F^(t_a). The window centre lags
the newest sample by 4 T_q, which is 000's fixed delay T_d = 4 T_q of the on-board filter; here the
data are post-processed, so the spline is simply centred (no lag).

Quasi-coordinates. A contiguous run of increments i_s over (t_s - T_s, t_s] gives the node values
F(t_a - T_a) = 0, F(t_s) = sum of the increments up to s. Where an increment does not start at the end
of the previous one (a gap), a new run starts; the spline is not defined across a gap (those segments
are flagged invalid). On a uniform grid the window fit is a fixed 9-tap filter (Savitzky-Golay
coefficients); near the ends of a run and on irregular spacing the window is shifted to stay inside
the run and fitted by least squares in the actual times. Runs shorter than the window are fitted whole
with the degree reduced to (nodes - 1).

Correction (000, eq. 2): the calibrated increments are i^_k(tau) = (1 - m^)(i~_k(tau) - b^ tau) in G, then
(S^Delta)^t i^ in A. Here the exact form (w~ - b) / (1 + m) is used (``(1 - m)`` is the paper's first-order
form of ``1 / (1 + m)``; at m = 0.005 the two differ by 2.5e-5, i.e. 27 arcsec over a 60 s slew at
5 deg/s). :meth:`QuasiCoordinateSpline.corrected` applies it to the node data (the corrected spline is
again a spline); ``interval_rotations`` applies it inside the integration and expresses the result
in frame A by conjugation with q_GS (a constant rotation of the rate conjugates the solution exactly).

Integration (000, eq. 7), in processing.signal.gyro_integration: ``interval_rotations`` integrates the MRP
kinematics over the spline by one Dormand-Prince 5(4) step per spline segment (the segments are split at
the output times, once, by ``plan_substeps``), for all segments at once (processing.attitude.mrp_kinematics),
and multiplies the step rotations of each output interval in order (a pairwise tree when the intervals
hold equal numbers of steps, else differences of the prefix product). The local error estimates of the
embedded 4th-order solution are summed per interval and returned: the measured integration error (below
1e-3 arcsec per second through 5 deg/s slews of the seed-000 scenario; the spline's approximation of the
increments, not the integrator, dominates the difference to the truth, ~1e-5 arcsec per second without
noise).

Times are float64 seconds from any epoch; increments rad; rates rad/s; vectors (..., 3).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DEGREE",
    "WINDOW",
    "QuasiCoordinateSpline",
    "TwoPassFilterError",
    "increments_from_rates",
    "two_pass_filter",
]

FloatArray = NDArray[np.float64]

WINDOW = 9
"""Samples per sliding window of the first pass (000: 9)."""
DEGREE = 3
"""Degree of the first-pass least-squares polynomial (000: cubic)."""
GAP_TOLERANCE = 1e-3
"""An increment continues the previous one when its start is within this fraction of its interval of
the previous sample time (1e-3 of 1/128 s = 7.8 us)."""


class TwoPassFilterError(ValueError):
    """Bad gyro input to the two-pass filter: shapes, non-increasing times, non-positive intervals."""


def _check_series(time_s: ArrayLike, values: ArrayLike, name: str) -> tuple[FloatArray, FloatArray]:
    t = np.asarray(time_s, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if t.ndim != 1 or v.shape != (t.size, 3):
        raise TwoPassFilterError(f"expected time_s (N,) and {name} (N, 3), got {t.shape} and {v.shape}")
    if t.size < 2:
        raise TwoPassFilterError(f"need at least 2 gyro samples, got {t.size}")
    if not np.all(np.diff(t) > 0):
        bad = int(np.argmin(np.diff(t) > 0))
        raise TwoPassFilterError(f"gyro times must be strictly increasing; sample {bad + 1} is not after {bad}")
    if not np.all(np.isfinite(v)):
        raise TwoPassFilterError(f"{name} must be finite; {int(np.sum(~np.isfinite(v)))} values are not")
    return t, v


def increments_from_rates(
    time_s: ArrayLike, w: ArrayLike, *, max_gap_factor: float = 1.5
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Angle increments from sampled rates by the trapezoidal rule (rates given, increments wanted).

    time_s (N,) s; w (N, 3) rad/s. Returns (time_s, increments, interval_s) for the intervals between
    consecutive samples, each ending at its later sample: increments (n, 3) rad = (w_{k-1} + w_k)/2
    (t_k - t_{k-1}). Intervals longer than max_gap_factor x the median spacing are gaps and dropped
    (the two-pass filter then starts a new run). The error of the trapezoid, -h^3 w''/12 per interval,
    is what the rate sampling allows; the gyro_increments stream should be preferred when it exists.
    """
    t, rate = _check_series(time_s, w, "w")
    dt = np.diff(t)
    keep = dt <= max_gap_factor * np.median(dt)
    incr = 0.5 * (rate[:-1] + rate[1:]) * dt[:, None]
    return t[1:][keep], incr[keep], dt[keep]


def _sg_coefficients(window: int, degree: int) -> FloatArray:
    """Rows: weights giving the value, first and second derivative (unit spacing) at the window centre."""
    half = window // 2
    x = np.arange(-half, half + 1, dtype=np.float64)
    v = np.vander(x, degree + 1, increasing=True)
    pinv = np.linalg.solve(v.T @ v, v.T)
    return np.stack([pinv[0], pinv[1], 2.0 * pinv[2] if degree >= 2 else np.zeros(window)])


def _hermite_d(u: FloatArray) -> tuple[FloatArray, ...]:
    """Derivatives d/du of the quintic Hermite basis (value0, slope0, curv0, curv1, slope1, value1)."""
    u2 = u * u
    u3 = u2 * u
    u4 = u3 * u
    return (
        -30.0 * u2 + 60.0 * u3 - 30.0 * u4,
        1.0 - 18.0 * u2 + 32.0 * u3 - 15.0 * u4,
        u - 4.5 * u2 + 6.0 * u3 - 2.5 * u4,
        1.5 * u2 - 4.0 * u3 + 2.5 * u4,
        -12.0 * u2 + 28.0 * u3 - 15.0 * u4,
        30.0 * u2 - 60.0 * u3 + 30.0 * u4,
    )


def _hermite(u: FloatArray) -> tuple[FloatArray, ...]:
    """Quintic Hermite basis on [0, 1]: H0 (value at 0), H1 (slope 0), H2 (curvature 0), H3 (curvature 1),
    H4 (slope 1), H5 (value at 1)."""
    u2 = u * u
    u3 = u2 * u
    u4 = u3 * u
    u5 = u4 * u
    return (
        1.0 - 10.0 * u3 + 15.0 * u4 - 6.0 * u5,
        u - 6.0 * u3 + 8.0 * u4 - 3.0 * u5,
        0.5 * u2 - 1.5 * u3 + 1.5 * u4 - 0.5 * u5,
        0.5 * u3 - u4 + 0.5 * u5,
        -4.0 * u3 + 7.0 * u4 - 3.0 * u5,
        10.0 * u3 - 15.0 * u4 + 6.0 * u5,
    )


_HERMITE_D_COEF = np.array(
    [  # d/du of the quintic Hermite basis as coefficients of u^0..u^4 (rows in the order of _hermite_d)
        [0.0, 0.0, -30.0, 60.0, -30.0],
        [1.0, 0.0, -18.0, 32.0, -15.0],
        [0.0, 1.0, -4.5, 6.0, -2.5],
        [0.0, 0.0, 1.5, -4.0, 2.5],
        [0.0, 0.0, -12.0, 28.0, -15.0],
        [0.0, 0.0, 30.0, -60.0, 30.0],
    ]
)


@dataclass(frozen=True)
class QuasiCoordinateSpline:
    """C2 quintic Hermite spline of the quasi-coordinates F(t) (integral of the rate), 3 axes.

    t_s (M,) node times [s]; f, d1, d2 (M, 3): F^ [rad], F^' [rad/s], F^'' [rad/s^2] at the nodes;
    valid (M - 1,): segment j = [t_j, t_j+1] lies inside a run (False across gaps). F is defined up to
    a constant per run. Frame: that of the increments (the gyro frame G unless :meth:`corrected`).
    """

    t_s: FloatArray
    f: FloatArray
    d1: FloatArray
    d2: FloatArray
    valid: NDArray[np.bool_]

    def locate(self, t_s: ArrayLike) -> tuple[NDArray[np.intp], FloatArray, NDArray[np.bool_]]:
        """Segment index j, local coordinate u in [0, 1] and inside-flag for times t_s (...)."""
        t = np.asarray(t_s, dtype=np.float64)
        nodes = self.t_s
        j = np.clip(np.searchsorted(nodes, t, side="right") - 1, 0, nodes.size - 2)
        at_run_end = (t == nodes[j]) & ~self.valid[j] & (j > 0)
        j = np.where(at_run_end, j - 1, j)
        h = nodes[j + 1] - nodes[j]
        u = (t - nodes[j]) / h
        inside = (t >= nodes[0]) & (t <= nodes[-1]) & self.valid[j]
        return j, np.clip(u, 0.0, 1.0), inside

    def _gather(self, j: NDArray[np.intp]) -> tuple[FloatArray, ...]:
        h = (self.t_s[j + 1] - self.t_s[j])[..., None]
        return (self.f[j], h * self.d1[j], h * h * self.d2[j], h * h * self.d2[j + 1], h * self.d1[j + 1],
                self.f[j + 1], h)

    def rate_at(self, j: ArrayLike, u: ArrayLike) -> FloatArray:
        """Rate w^ = dF^/dt (..., 3) [rad/s] at local coordinate u (...) of segments j (...)."""
        jj = np.asarray(j, dtype=np.intp)
        f0, s0, c0, c1, s1, f1, h = self._gather(jj)
        b0, b1, b2, b3, b4, b5 = _hermite_d(np.asarray(u, dtype=np.float64)[..., None])
        return (b5 * (f1 - f0) + b1 * s0 + b2 * c0 + b3 * c1 + b4 * s1) / h

    def rate_polynomial(self, j: ArrayLike, u_a: ArrayLike, du: ArrayLike) -> FloatArray:
        """Coefficients P (5, n, 3) with w^(c) = sum_p P[p] c^p on u = u_a + c du of segments j (n,).

        The rate on a spline segment is a quartic in u; this is it re-expanded in the sub-step
        coordinate c in [0, 1] (Taylor shift), so an integrator evaluates it by Horner's rule.
        """
        jj = np.asarray(j, dtype=np.intp)
        poly = self.segment_rate_polynomials()
        if not (jj.size and jj[0] == 0 and jj.size == poly.shape[1] and np.all(np.diff(jj) == 1)):
            poly = poly[:, jj]
        ua = np.asarray(u_a, dtype=np.float64)
        d = np.asarray(du, dtype=np.float64)
        partial = (ua != 0.0) | (d != 1.0)
        if np.any(partial):
            p_u = poly[:, partial]
            a, s = ua[partial][:, None], d[partial][:, None]
            shifted = np.zeros_like(p_u)
            for k in range(5):  # Q_k = du^k sum_{p >= k} C(p, k) P_p u_a^(p - k)
                for p in range(k, 5):
                    shifted[k] += comb(p, k) * p_u[p] * a ** (p - k)
                shifted[k] *= s**k
            poly[:, partial] = shifted
        return poly

    def rate(self, t_s: ArrayLike) -> FloatArray:
        """Rate w^(t) (..., 3) [rad/s]; NaN outside the spline or in a gap."""
        j, u, inside = self.locate(t_s)
        return np.where(inside[..., None], self.rate_at(j, u), np.nan)

    def angle(self, t_s: ArrayLike) -> FloatArray:
        """Quasi-coordinate F^(t) (..., 3) [rad] (constant offset per run); NaN outside or in a gap."""
        j, u, inside = self.locate(t_s)
        data = self._gather(j)
        value = sum(b * d for b, d in zip(_hermite(u[..., None]), data[:6], strict=True))
        return np.where(inside[..., None], value, np.nan)

    def corrected(self, dcm: ArrayLike, scale_factor_error: float = 0.0, drift: ArrayLike = (0.0, 0.0, 0.0)
                  ) -> QuasiCoordinateSpline:
        """Calibrated spline of 000 eq. (2): rate dcm (w~ - drift) / (1 + scale_factor_error).

        dcm (3, 3): rotation into the target frame (dcm_GS^T = dcm_SG for frame A = S); drift (3,)
        [rad/s] in the spline's frame, subtracted as drift * (t - t_0) from F. Exact in 1/(1 + m).
        """
        mat = np.asarray(dcm, dtype=np.float64) / (1.0 + float(scale_factor_error))
        b = np.asarray(drift, dtype=np.float64)
        if mat.shape != (3, 3) or b.shape != (3,):
            raise TwoPassFilterError(f"expected dcm (3, 3) and drift (3,), got {mat.shape} and {b.shape}")
        tau = (self.t_s - self.t_s[0])[:, None]
        return QuasiCoordinateSpline(
            t_s=self.t_s, f=_apply(mat, self.f - b * tau), d1=_apply(mat, self.d1 - b), d2=_apply(mat, self.d2),
            valid=self.valid,
        )

    def segment_rate_polynomials(self) -> FloatArray:
        """Coefficients P (5, M - 1, 3) of the rate on every segment, w^ = sum_p P[p] u^p, u in [0, 1].

        The value terms enter as H5'(u) (f1 - f0) (H0' = -H5'), so no large quasi-coordinates cancel.
        """
        h = (self.t_s[1:] - self.t_s[:-1])[:, None]
        data = np.empty((5,) + self.f[:-1].shape)
        np.subtract(self.f[1:], self.f[:-1], out=data[0])
        np.multiply(h, self.d1[:-1], out=data[1])
        np.multiply(h * h, self.d2[:-1], out=data[2])
        np.multiply(h * h, self.d2[1:], out=data[3])
        np.multiply(h, self.d1[1:], out=data[4])
        coef = _HERMITE_D_COEF[[5, 1, 2, 3, 4]]  # rows: (f1 - f0), h d1_0, h^2 d2_0, h^2 d2_1, h d1_1
        out = (coef.T @ data.reshape(5, -1)).reshape(data.shape)
        out /= h
        return out


def _apply(mat: FloatArray, v: FloatArray) -> FloatArray:
    """v @ mat.T for (n, 3) v and a (3, 3) matrix, as three broadcast products (faster than matmul here)."""
    return v[:, 0:1] * mat[:, 0] + v[:, 1:2] * mat[:, 1] + v[:, 2:3] * mat[:, 2]


def _window_fit(t: FloatArray, f: FloatArray, starts: NDArray[np.intp], centres: NDArray[np.intp], window: int,
                degree: int, h: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Least-squares polynomial fits of F over windows [start, start + window) evaluated at the centres."""
    idx = starts[:, None] + np.arange(window)
    x = (t[idx] - t[centres][:, None]) / h
    v = x[..., None] ** np.arange(degree + 1)  # (n, window, degree + 1)
    y = f[idx] - f[centres][:, None, :]
    coef = np.linalg.solve(np.swapaxes(v, 1, 2) @ v, np.swapaxes(v, 1, 2) @ y)  # (n, degree + 1, 3)
    zeros = np.zeros_like(coef[:, 0])
    c1 = coef[:, 1] if degree >= 1 else zeros
    c2 = coef[:, 2] if degree >= 2 else zeros
    return f[centres] + coef[:, 0], c1 / h, 2.0 * c2 / (h * h)


def two_pass_filter(
    time_s: ArrayLike, increments: ArrayLike, interval_s: ArrayLike, *, window: int = WINDOW, degree: int = DEGREE
) -> QuasiCoordinateSpline:
    """Two-pass filter of 000 (figure 1): windowed cubic LSQ of the quasi-coordinates, then a quintic C2 spline.

    time_s (N,) [s] strictly increasing ends of the intervals; increments (N, 3) [rad] (gyro frame);
    interval_s (N,) [s] > 0 the interval lengths. window: odd number of nodes per first-pass window
    (000: 9); degree: first-pass polynomial degree (000: 3). Returns the
    :class:`QuasiCoordinateSpline`, whose derivative is the filtered rate w^ (000, figure 1).
    """
    t_end, incr = _check_series(time_s, increments, "increments")
    dt = np.asarray(interval_s, dtype=np.float64)
    if dt.shape != t_end.shape or not np.all(dt > 0):
        raise TwoPassFilterError(f"interval_s must be (N,) = {t_end.shape} and > 0")
    if window < 3 or window % 2 == 0 or not 1 <= degree < window:
        raise TwoPassFilterError(f"window must be odd >= 3 and 1 <= degree < window, got {window}, {degree}")
    t_start = t_end - dt
    new_run = np.ones(t_end.size, dtype=bool)
    new_run[1:] = np.abs(t_start[1:] - t_end[:-1]) > GAP_TOLERANCE * dt[1:]
    if np.any(t_start[1:][~new_run[1:]] < t_end[:-1][~new_run[1:]] - GAP_TOLERANCE * dt[1:][~new_run[1:]]):
        raise TwoPassFilterError("gyro increments overlap: an interval starts before the previous sample")
    run = np.cumsum(new_run) - 1
    n_runs = int(run[-1]) + 1
    node_of_incr = np.arange(t_end.size) + run + 1
    m = t_end.size + n_runs
    t = np.empty(m)
    f = np.zeros((m, 3))
    t[node_of_incr] = t_end
    run_first_incr = np.flatnonzero(new_run)
    run_start_node = run_first_incr + np.arange(n_runs)
    t[run_start_node] = t_start[run_first_incr]
    csum = np.cumsum(incr, axis=0)
    base = np.where(run_first_incr[:, None] > 0, csum[np.maximum(run_first_incr - 1, 0)], 0.0)
    f[node_of_incr] = csum - base[run]
    if not np.all(np.diff(t) > 0):
        raise TwoPassFilterError("gyro intervals overlap the previous sample (node times not increasing)")
    run_end_node = np.append(run_start_node[1:] - 1, m - 1)
    node_run = np.repeat(np.arange(n_runs), run_end_node - run_start_node + 1)
    h = float(np.median(dt))

    f_hat, d1, d2 = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3))
    half = window // 2
    j = np.arange(m)
    rs, re = run_start_node[node_run], run_end_node[node_run]
    long_run = (re - rs + 1) >= window
    ws = np.clip(j - half, rs, re - window + 1)
    irregular = np.abs(np.diff(t) - h) > 1e-9 * max(1.0, h)
    cum_irr = np.concatenate([[0], np.cumsum(irregular)])
    centred = long_run & (ws == j - half)
    safe_ws = np.clip(ws, 0, m - window)
    uniform = centred & (cum_irr[safe_ws + window - 1] - cum_irr[safe_ws] == 0)
    # uniform interior: fixed Savitzky-Golay weights on F - F_centre
    coef = _sg_coefficients(window, degree)
    count = m - 2 * half
    if count > 0:
        sel = uniform[half : half + count]
        centres = np.arange(half, half + count)[sel]
        scales = (1.0, 1.0 / h, 1.0 / (h * h))
        for out, row, scale in zip((f_hat, d1, d2), coef, scales, strict=True):
            kernel = row[::-1] * scale  # np.convolve flips the kernel: correlate with the window weights
            for axis in range(3):
                out[centres, axis] = np.convolve(f[:, axis], kernel, mode="valid")[sel]
    general = long_run & ~uniform
    if np.any(general):
        g = np.flatnonzero(general)
        f_hat[g], d1[g], d2[g] = _window_fit(t, f, ws[g], g, window, degree, h)
    for r in np.flatnonzero(run_end_node - run_start_node + 1 < window):  # short runs: whole-run fits
        a, b = run_start_node[r], run_end_node[r]
        nodes = np.arange(a, b + 1)
        f_hat[nodes], d1[nodes], d2[nodes] = _window_fit(
            t, f, np.full(nodes.size, a), nodes, b - a + 1, min(degree, b - a), h
        )
    valid = node_run[1:] == node_run[:-1]
    return QuasiCoordinateSpline(t_s=t, f=f_hat, d1=d1, d2=d2, valid=valid)
