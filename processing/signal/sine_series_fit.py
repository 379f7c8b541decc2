"""A fitted sine series plus linear trend of paper 003 §1.3 (processing.signal.sine_series fits it):
its values, its analytic derivative and its residuals at any times.

    f(t) = a_{M+1} + a_{M+2} (t - t_1) + sum_{m=1..M} a_m sin(pi m (t - t_1) / T),   T = t_N - t_1

Times in seconds, values in the unit of the fitted data (slopes per second).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["SineSeriesFit"]

_RESEED = 32  # evaluation: harmonics between exact sin/cos seeds of the recurrence
_CHUNK = 16_384  # evaluation: samples per block (two (_CHUNK, _RESEED) float64 work arrays, 4 MiB each)


@dataclass(frozen=True)
class SineSeriesFit:
    """A fitted series f(t) = const + slope (t - t1_s) + sum_m sine[m-1] sin(pi m (t - t1_s)/span_s).

    Coefficients have the unit of y (slope: per second) and follow the shape of y: for y (N,),
    const and slope are scalars (0-d arrays), sine (M,), fitted (N,), rss a scalar; for y (N, K) they
    carry a trailing K. ``fitted`` are the values at the samples, ``rss`` the weighted residual sums
    of squares, ``dof`` = samples with non-zero weight - (M + 2). 003 §1.3 order of the paper's a_k:
    sine = a_1..a_M, const = a_{M+1}, slope = a_{M+2}.
    """

    t1_s: float
    span_s: float
    harmonics: int
    const: NDArray
    slope: NDArray
    sine: NDArray
    fitted: NDArray
    rss: NDArray
    n_samples: int
    dof: int
    method: str
    vector: bool

    @property
    def sigma(self) -> NDArray:
        """Residual standard deviation per component, sqrt(rss / dof) (NaN when dof == 0)."""
        rss = np.asarray(self.rss, dtype=np.float64)
        return np.sqrt(rss / self.dof) if self.dof > 0 else np.full_like(rss, np.nan)

    @property
    def cutoff_hz(self) -> float:
        """Highest frequency of the series, M / (2 span_s) (sin(pi M tau) has period 2 span / M)."""
        return self.harmonics / (2.0 * self.span_s)

    def _out(self, values: NDArray) -> NDArray:
        return values[..., 0] if self.vector else values

    def _sums(self, t_s: ArrayLike, value: bool, derivative: bool) -> tuple[NDArray, NDArray]:
        """f(t) and/or df/dt at t_s as (n, K) arrays (an empty (0, K) for the one not asked for).

        sin/cos(m theta) come from the angle-addition recurrence over m (vectorised over samples),
        re-seeded exactly every _RESEED harmonics so the rounding error stays ~_RESEED eps; each block of
        _RESEED harmonics is summed by one matrix product, over blocks of _CHUNK samples.
        """
        t = np.asarray(t_s, dtype=np.float64)
        flat = t.reshape(-1)
        n = flat.size
        m = np.arange(1, self.harmonics + 1, dtype=np.float64)
        slope = np.reshape(self.slope, -1)
        k = slope.size
        sine = np.reshape(self.sine, (self.harmonics, k))
        val = np.reshape(self.const, -1) + np.outer(flat - self.t1_s, slope) if value else np.empty((0, k))
        der = np.broadcast_to(slope, (n, k)).copy() if derivative else np.empty((0, k))
        d_coef = sine * (np.pi * m / self.span_s)[:, None]
        theta_all = np.pi * ((flat - self.t1_s) / self.span_s)
        for lo in range(0, n if self.harmonics else 0, _CHUNK):
            theta = theta_all[lo:lo + _CHUNK]
            s1, c1 = np.sin(theta), np.cos(theta)
            s_blk = np.empty((theta.size, _RESEED), order="F")
            c_blk = np.empty((theta.size, _RESEED), order="F")
            tmp = np.empty(theta.size)
            for j0 in range(0, self.harmonics, _RESEED):
                b = min(_RESEED, self.harmonics - j0)
                if j0 == 0:
                    s_blk[:, 0], c_blk[:, 0] = s1, c1
                else:  # exact seeds of the block
                    np.sin((j0 + 1) * theta, out=s_blk[:, 0])
                    np.cos((j0 + 1) * theta, out=c_blk[:, 0])
                for i in range(1, b):  # sin/cos((j0 + i + 1) theta) by angle addition, in place
                    sp, cp, sn, cn = s_blk[:, i - 1], c_blk[:, i - 1], s_blk[:, i], c_blk[:, i]
                    np.multiply(sp, c1, out=sn)
                    sn += np.multiply(cp, s1, out=tmp)
                    np.multiply(cp, c1, out=cn)
                    cn -= np.multiply(sp, s1, out=tmp)
                if value:
                    val[lo:lo + _CHUNK] += s_blk[:, :b] @ sine[j0:j0 + b]
                if derivative:
                    der[lo:lo + _CHUNK] += c_blk[:, :b] @ d_coef[j0:j0 + b]
        return val, der

    def evaluate(self, t_s: ArrayLike) -> NDArray:
        """f(t) at t_s (...) seconds; returns (...) for a 1-D fit, (..., K) otherwise (003 §1.3)."""
        shape = np.shape(t_s)
        val, _ = self._sums(t_s, value=True, derivative=False)
        return self._out(val.reshape(*shape, val.shape[-1]))

    def derivative(self, t_s: ArrayLike) -> NDArray:
        """Analytic df/dt = slope + sum_m sine_m (pi m / span) cos(pi m tau) [unit of y per second]."""
        shape = np.shape(t_s)
        _, der = self._sums(t_s, value=False, derivative=True)
        return self._out(der.reshape(*shape, der.shape[-1]))

    def evaluate_with_derivative(self, t_s: ArrayLike) -> tuple[NDArray, NDArray]:
        """(:meth:`evaluate`, :meth:`derivative`) at t_s from one pass of the harmonic recurrence."""
        shape = np.shape(t_s)
        val, der = self._sums(t_s, value=True, derivative=True)
        return self._out(val.reshape(*shape, val.shape[-1])), self._out(der.reshape(*shape, der.shape[-1]))

    def residuals(self, y: ArrayLike) -> NDArray:
        """y - fitted at the samples (shape of y)."""
        return np.asarray(y, dtype=np.float64) - self.fitted
