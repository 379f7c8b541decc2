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

    def _sum(self, t_s: ArrayLike, derivative: bool) -> NDArray:
        t = np.asarray(t_s, dtype=np.float64)
        flat = t.reshape(-1)
        tau = (flat - self.t1_s) / self.span_s
        m = np.arange(1, self.harmonics + 1, dtype=np.float64)
        slope = np.reshape(self.slope, -1)
        k = slope.size
        sine = np.reshape(self.sine, (self.harmonics, k))
        if derivative:
            out = np.broadcast_to(slope, (flat.size, k)).copy()
            coef = sine * (np.pi * m / self.span_s)[:, None]
        else:
            out = np.reshape(self.const, -1) + np.outer(flat - self.t1_s, slope)
            coef = sine
        if self.harmonics:
            # sin/cos(m theta) by the angle-addition recurrence over m (vectorised over samples), re-seeded
            # exactly every _RESEED harmonics so the rounding error stays ~_RESEED eps.
            theta = np.pi * tau
            s1, c1 = np.sin(theta), np.cos(theta)
            sm, cm = s1, c1
            for j in range(self.harmonics):
                out += np.outer(cm if derivative else sm, coef[j])
                if (j + 1) % _RESEED == 0:
                    sm, cm = np.sin((j + 2) * theta), np.cos((j + 2) * theta)
                else:
                    sm, cm = sm * c1 + cm * s1, cm * c1 - sm * s1
        return self._out(out.reshape(*t.shape, k))

    def evaluate(self, t_s: ArrayLike) -> NDArray:
        """f(t) at t_s (...) seconds; returns (...) for a 1-D fit, (..., K) otherwise (003 §1.3)."""
        return self._sum(t_s, derivative=False)

    def derivative(self, t_s: ArrayLike) -> NDArray:
        """Analytic df/dt = slope + sum_m sine_m (pi m / span) cos(pi m tau) [unit of y per second]."""
        return self._sum(t_s, derivative=True)

    def residuals(self, y: ArrayLike) -> NDArray:
        """y - fitted at the samples (shape of y)."""
        return np.asarray(y, dtype=np.float64) - self.fitted
