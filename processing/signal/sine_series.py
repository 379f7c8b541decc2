"""Sine series plus linear trend: the smoother of paper 003 §1.3-1.4.

A signal sampled at t_1 <= ... <= t_N is approximated by (003 §1.3, the expression for z_i(t))

    f(t) = a_{M+1} + a_{M+2} (t - t_1) + sum_{m=1..M} a_m sin(pi m (t - t_1) / T),   T = t_N - t_1

(the paper's T = (N - 1) h on a uniform grid of step h; 003 §1.4 uses the same series with the gyro
step h' to low-pass gyro rates). The coefficients minimise sum_n w_n (y_n - f(t_n))^2 (003 eq. 1 in
the form Phi_i = sum_n [z_i^(n) - z_i(t_n)]^2). Every sine vanishes at t_1 and t_N, so the series
is the discrete sine transform (DST-I) of the interior samples and the trend carries the end values.

Two exact routes to the same least-squares solution:

- ``"dst"`` (003: "the formulas of the theory of discrete Fourier series", for data without gaps):
  uniform times and equal weights. On that grid the sine columns S are orthogonal,
  S^T S = (N - 1)/2 I, and S^T x is a DST-I of the interior samples (``scipy.fft.dst(type=1)``).
  The trend is solved exactly by block elimination: b = S^+ (y - L a) and a minimises
  |(I - P_S)(y - L a)|, a two-column QR problem on DST-projected columns. O(N log N).
- ``"lstsq"`` (003: "the general least-squares method" when there are gaps): the dense weighted
  design [1, tau, sin(pi m tau)] (tau = (t - t_1)/T in [0, 1]) factorised by Householder QR
  (never the normal equations). O(N M^2).

:class:`SineSeriesSolver` factorises once for given times (DST coefficients of the trend columns, or
one QR of the widest design, whose leading columns are the QR of every narrower one) and then
fits any M, gives the residual sums of squares of every M = 0..M_max in one pass (:meth:`path`)
and the coefficient variances; :func:`fit_sine_series`, :func:`harmonics_path` and
:func:`select_harmonics` (M by an information criterion on the path) are one-shot wrappers.
The design matrix, the DST pair and the factorisation of the general route are in
processing.signal.sine_series_basis (:func:`sine_series_design` is importable from here too).

Times in seconds (any origin; pass times relative to the segment start for precision), values in
any unit; results carry the same unit (slopes per second). Pure numpy/scipy, vectorised over samples.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.fft
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from processing.signal.sine_series_basis import dst_coefficients, dst_synthesis, gram_factor, sine_series_design
from processing.signal.sine_series_fit import SineSeriesFit

__all__ = [
    "HarmonicsPath",
    "SineSeriesError",
    "SineSeriesSolver",
    "fit_sine_series",
    "harmonics_path",
    "is_uniform",
    "select_harmonics",
    "sine_series_design",
]

UNIFORM_RTOL = 1e-9
"""Times count as uniform (DST route) when every |t_n - (t_1 + (n-1) h)| <= UNIFORM_RTOL * h."""
RANK_RTOL = 1e-10
"""The weighted design is rank deficient when a diagonal element of its R factor is below
RANK_RTOL times the largest (e.g. too many harmonics for the samples left between gaps)."""

Method = Literal["auto", "dst", "lstsq"]
Criterion = Literal["gcv", "aic", "bic"]


class SineSeriesError(ValueError):
    """Bad input to the sine-series smoother: shapes, too few samples, bad harmonics or weights."""


def _as_inputs(t_s: ArrayLike, y: ArrayLike) -> tuple[NDArray, NDArray, bool]:
    t = np.asarray(t_s, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    if t.ndim != 1:
        raise SineSeriesError(f"t_s must be 1-D (N,), got shape {t.shape}")
    if yy.ndim not in (1, 2) or yy.shape[0] != t.size:
        raise SineSeriesError(f"y must have shape ({t.size},) or ({t.size}, K) to match t_s, got {yy.shape}")
    if t.size < 3:
        raise SineSeriesError(f"need at least 3 samples, got {t.size}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(yy))):
        raise SineSeriesError("t_s and y must be finite (drop NaN samples first)")
    if np.any(np.diff(t) <= 0):
        raise SineSeriesError("t_s must be strictly increasing")
    vector = yy.ndim == 1
    return t, (yy[:, None] if vector else yy), vector


def _as_weights(weights: ArrayLike | None, n: int) -> NDArray | None:
    if weights is None:
        return None
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != (n,):
        raise SineSeriesError(f"weights must have shape ({n},), got {w.shape}")
    if not np.all(np.isfinite(w)) or np.any(w < 0) or not np.any(w > 0):
        raise SineSeriesError("weights must be finite, >= 0 and not all zero")
    return w


def is_uniform(t_s: ArrayLike, rtol: float = UNIFORM_RTOL) -> bool:
    """True when t_s (N,) is an arithmetic progression to rtol * step (no gaps, no jitter)."""
    t = np.asarray(t_s, dtype=np.float64)
    if t.size < 3:
        return True
    h = (t[-1] - t[0]) / (t.size - 1)
    grid = t[0] + h * np.arange(t.size)
    return bool(h > 0 and np.max(np.abs(t - grid)) <= rtol * h)




def _choose_method(method: Method, t: NDArray, w: NDArray | None) -> str:
    uniform_weights = w is None or bool(np.all(w == w[0]))
    if method == "auto":
        return "dst" if uniform_weights and is_uniform(t) else "lstsq"
    if method == "dst":
        if not uniform_weights:
            raise SineSeriesError("method='dst' needs equal weights; use 'lstsq' or 'auto' with weights")
        if not is_uniform(t):
            raise SineSeriesError(
                f"method='dst' needs uniform times without gaps (to {UNIFORM_RTOL:g} of the step); "
                "use 'lstsq' or 'auto'"
            )
        return "dst"
    if method == "lstsq":
        return "lstsq"
    raise SineSeriesError(f"method must be 'auto', 'dst' or 'lstsq', got {method!r}")


def _as_harmonics(harmonics: object, low: int, high: int, what: str) -> int:
    if isinstance(harmonics, bool) or not isinstance(harmonics, int | np.integer):
        raise SineSeriesError(f"{what} must be an integer, got {harmonics!r}")
    m = int(harmonics)
    if not low <= m <= high:
        raise SineSeriesError(f"{what} must be in [{low}, {high}], got {m}")
    return m


class SineSeriesSolver:
    """The 003 §1.3 least-squares problem prepared once for given times, weights and a largest M.

    Factorises once (DST coefficients of the trend columns, or one Householder QR of the widest
    weighted design, whose leading columns are the QR of every smaller design) and then fits any
    M <= max_harmonics, gives the RSS of all M at once (:meth:`path`), and the diagonal of the
    coefficient covariance (:meth:`covariance_diag`) for any data y at these times. Use it when
    several series or several M are fitted at the same times (e.g. raw and corrected data, or
    choosing M); :func:`fit_sine_series` and :func:`harmonics_path` are one-shot wrappers.

    t_s (N,) strictly increasing [s]; max_harmonics 0..N-2; weights (N,) >= 0 or None; method as in
    :func:`fit_sine_series`. Attributes: route ("dst" | "lstsq"), t1_s, span_s, n_samples, n_used
    (non-zero weights), max_harmonics, rank_harmonics (largest M the samples determine).
    """

    def __init__(
        self,
        t_s: ArrayLike,
        max_harmonics: int,
        *,
        weights: ArrayLike | None = None,
        method: Method = "auto",
    ) -> None:
        t, _, _ = _as_inputs(t_s, np.zeros(np.size(t_s)))
        n = t.size
        self.max_harmonics = _as_harmonics(max_harmonics, 0, n - 2, f"harmonics (N = {n} samples, N - 2 = {n - 2})")
        self._w = _as_weights(weights, n)
        self.route = _choose_method(method, t, self._w)
        self.n_samples = n
        self.n_used = n if self._w is None else int(np.count_nonzero(self._w))
        self.t1_s = float(t[0])
        self.span_s = float(t[-1] - t[0])
        self.tau = (t - t[0]) / self.span_s
        self._lin = np.column_stack([np.ones(n), self.tau])
        self._sqrt_w = None if self._w is None else np.sqrt(self._w)
        if self.route == "dst":
            self._c_lin = dst_coefficients(self._lin, self.max_harmonics)
            self.rank_harmonics = self.max_harmonics
        else:
            self._design = sine_series_design(self.tau, self.max_harmonics, 0.0, 1.0)
            a = self._design if self._sqrt_w is None else self._design * self._sqrt_w[:, None]
            self._a = a
            self._q, self._r = gram_factor(a, self.tau, self._w)
            d = np.abs(np.diag(self._r))
            ok = d > RANK_RTOL * d.max()
            self.rank_harmonics = (int(np.argmin(ok)) if not np.all(ok) else d.size) - 2

    def _y(self, y: ArrayLike) -> tuple[NDArray, bool]:
        yy = np.asarray(y, dtype=np.float64)
        if yy.ndim not in (1, 2) or yy.shape[0] != self.n_samples:
            raise SineSeriesError(
                f"y must have shape ({self.n_samples},) or ({self.n_samples}, K) to match t_s, got {yy.shape}"
            )
        if not np.all(np.isfinite(yy)):
            raise SineSeriesError("t_s and y must be finite (drop NaN samples first)")
        return (yy[:, None], True) if yy.ndim == 1 else (yy, False)

    def _qt(self, rhs: NDArray, p: int) -> NDArray:
        """Q^T rhs restricted to the first p columns (Q = A R^-1 of the weighted design A)."""
        if self._q is not None:
            return self._q[:, :p].T @ rhs
        return scipy.linalg.solve_triangular(self._r[:p, :p], self._a[:, :p].T @ rhs, trans="T", check_finite=False)

    def _rhs(self, y: NDArray) -> NDArray:
        return y if self._sqrt_w is None else y * self._sqrt_w[:, None]

    def _check_rank(self, harmonics: int) -> None:
        if harmonics > self.rank_harmonics:
            raise SineSeriesError(
                f"{harmonics} harmonics are not determined by the {self.n_used} samples (rank-deficient design; "
                f"the gaps leave too few samples): use at most {max(self.rank_harmonics, 0)}"
            )

    def fit(self, y: ArrayLike, harmonics: int) -> SineSeriesFit:
        """Least-squares fit with M = harmonics <= max_harmonics of y (N,) or (N, K) at these times."""
        yy, vector = self._y(y)
        m = _as_harmonics(harmonics, 0, self.max_harmonics, f"harmonics (prepared up to {self.max_harmonics})")
        n = self.n_samples
        if self.route == "dst":
            x = np.concatenate([self._lin, yy], axis=1)
            c = np.concatenate([self._c_lin[:m], dst_coefficients(yy, m)], axis=1)
            r = x - dst_synthesis(c, n)  # (I - P_S) applied to every column
            q, rr = np.linalg.qr(r[:, :2])
            trend = scipy.linalg.solve_triangular(rr, q.T @ r[:, 2:])
            sine = c[:, 2:] - c[:, :2] @ trend
            fitted = yy - (r[:, 2:] - r[:, :2] @ trend)
        else:
            self._check_rank(m)
            p = m + 2
            coef = scipy.linalg.solve_triangular(self._r[:p, :p], self._qt(self._rhs(yy), p), check_finite=False)
            trend, sine = coef[:2], coef[2:]
            fitted = self._design[:, :p] @ coef
        resid = yy - fitted
        rss = np.sum(resid * resid * (1.0 if self._w is None else self._w[:, None]), axis=0)

        def shaped(a: NDArray) -> NDArray:
            return np.array(a[..., 0] if vector else a)  # a copy; 0-d stays 0-d

        return SineSeriesFit(
            t1_s=self.t1_s,
            span_s=self.span_s,
            harmonics=m,
            const=shaped(trend[0]),
            slope=shaped(trend[1] / self.span_s),
            sine=shaped(sine),
            fitted=shaped(fitted),
            rss=shaped(rss),
            n_samples=n,
            dof=self.n_used - (m + 2),
            method=self.route,
            vector=vector,
        )

    def path(self, y: ArrayLike) -> HarmonicsPath:
        """RSS (P, K) of the fits with M = 0..max_harmonics (lstsq: ..rank_harmonics) of y (N,) or (N, K).

        DST route: the projections of [1, tau, y] on the first M sines are cumulative sums of squared
        DST coefficients (S^T S is diagonal) and each RSS a 2x2 Schur complement of those Gram
        matrices (y pre-detrended by its LSQ line, so the subtraction keeps its digits). General
        route: the fits are nested, so RSS(M) = |(I - QQ^T) y|^2 + sum of the squared components of
        Q^T y beyond column M + 2.
        """
        yy, _ = self._y(y)
        n = self.n_samples
        top = self.max_harmonics
        if self.route == "dst":
            line = np.linalg.lstsq(self._lin, yy, rcond=None)[0]
            x = np.concatenate([self._lin, yy - self._lin @ line], axis=1)
            c = np.concatenate([self._c_lin, dst_coefficients(x[:, 2:], top)], axis=1)
            gram0 = x.T @ x
            cum = np.cumsum(0.5 * (n - 1) * c[:, :, None] * c[:, None, :], axis=0)
            gram = np.concatenate([gram0[None], gram0[None] - cum], axis=0)  # (P, 2+K, 2+K)
            g_ly = gram[:, :2, 2:]
            g_yy = np.diagonal(gram[:, 2:, 2:], axis1=1, axis2=2)
            sol = np.linalg.solve(gram[:, :2, :2], g_ly)
            rss = np.maximum(g_yy - np.einsum("pik,pik->pk", g_ly, sol), 0.0)
            if self._w is not None:  # equal weights on this route
                rss = rss * self._w[0]
        else:
            top = min(top, self.rank_harmonics)
            if top < 0:
                raise SineSeriesError("the samples do not determine even the linear trend")
            p = top + 2
            rhs = self._rhs(yy)
            proj = self._qt(rhs, p)
            base = rhs - self._a[:, :p] @ scipy.linalg.solve_triangular(self._r[:p, :p], proj, check_finite=False)
            tail = np.cumsum((proj * proj)[::-1], axis=0)[::-1]  # tail[j] = sum_{i >= j} proj_i^2
            tail = np.concatenate([tail, np.zeros((1, tail.shape[1]))], axis=0)
            rss = np.sum(base * base, axis=0) + tail[2:]
        harmonics = np.arange(top + 1)
        return HarmonicsPath(harmonics=harmonics, rss=rss, dof=self.n_used - (harmonics + 2), n_used=self.n_used,
                             method=self.route)

    def derivative_at_samples(self, fit: SineSeriesFit) -> NDArray:
        """d fit / dt at this solver's sample times (shape of fit.fitted) [unit of y per second].

        DST route: sum_m b_m (pi m / T) cos(pi m n / (N - 1)) is half a DCT-I of the padded
        coefficients (O(N log N)); otherwise :meth:`SineSeriesFit.derivative`.
        """
        if fit.n_samples != self.n_samples or fit.span_s != self.span_s or fit.t1_s != self.t1_s:
            raise SineSeriesError("the fit was not made by this solver (different sample times)")
        if self.route != "dst" or fit.harmonics == 0:
            return fit.derivative(self.t1_s + self.tau * self.span_s)
        n, m = self.n_samples, fit.harmonics
        sine = np.reshape(fit.sine, (m, -1))
        padded = np.zeros((n, sine.shape[1]))
        padded[1 : m + 1] = sine * (np.pi * np.arange(1, m + 1) / self.span_s)[:, None]
        out = 0.5 * scipy.fft.dct(padded, type=1, axis=0) + np.reshape(fit.slope, -1)
        return out[:, 0] if fit.vector else out

    def leverage(self, harmonics: int) -> NDArray:
        """h_n = a_n^T (A^T W A)^-1 a_n (N,) for every sample's design row a_n (M = harmonics): the
        hat-matrix diagonal (times w_n) where w_n > 0, and the prediction-variance factor of the fit at
        the samples with zero weight (per unit noise variance). The general route reuses its QR; the DST
        route (equal weights) factorises the design once here."""
        m = _as_harmonics(harmonics, 0, self.max_harmonics, f"harmonics (prepared up to {self.max_harmonics})")
        p = m + 2
        if self.route == "dst":
            design = sine_series_design(self.tau, m, 0.0, 1.0)
            r = scipy.linalg.qr(design, mode="r", check_finite=False)[0][:p]
            scale = 1.0 if self._w is None else float(np.sqrt(self._w[0]))
            x = scipy.linalg.solve_triangular(r * scale, design.T, trans="T", check_finite=False)
        else:
            self._check_rank(m)
            x = scipy.linalg.solve_triangular(self._r[:p, :p], self._design[:, :p].T, trans="T", check_finite=False)
        return np.sum(x * x, axis=0)

    def covariance_diag(self, harmonics: int) -> NDArray:
        """diag((A^T W A)^-1) (M + 2,) of the design A = [1, tau, sin(pi m tau)] (tau-scaled slope):
        the coefficient variances per unit noise variance. Covariance of the fitted coefficients of a
        component with white noise sigma: sigma^2 times this."""
        m = _as_harmonics(harmonics, 0, self.max_harmonics, f"harmonics (prepared up to {self.max_harmonics})")
        n = self.n_samples
        if self.route == "dst":
            # A^T A = [[L^T L, L^T S], [S^T L, h I]], h = (N - 1)/2, S^T L = h C; Schur complement
            # Z = L^T L - h C^T C; inverse: G_LL = Z^-1, G_SS = I/h + C Z^-1 C^T.
            c = self._c_lin[:m]
            z = self._lin.T @ self._lin - 0.5 * (n - 1) * c.T @ c
            z_inv = np.linalg.inv(z)
            g_ss = 2.0 / (n - 1) + np.einsum("mi,ij,mj->m", c, z_inv, c)
            return np.concatenate([np.diag(z_inv), g_ss])
        self._check_rank(m)
        p = m + 2
        r_inv = scipy.linalg.solve_triangular(self._r[:p, :p], np.eye(p))
        return np.sum(r_inv * r_inv, axis=1)


def fit_sine_series(
    t_s: ArrayLike,
    y: ArrayLike,
    harmonics: int,
    *,
    weights: ArrayLike | None = None,
    method: Method = "auto",
) -> SineSeriesFit:
    """Least-squares fit of the sine series plus linear trend of 003 §1.3 (eq. 1, Phi_i).

    t_s: (N,) strictly increasing times [s]; y: (N,) or (N, K) values (K components fitted at once
    with the same harmonics); harmonics: M, 0 <= M <= N - 2 (003: M <= N - 2); weights: optional
    (N,) >= 0, minimising sum w_n (y_n - f(t_n))^2 (None: all 1); method: "dst" (uniform times, equal
    weights: 003's discrete-Fourier formulas, O(N log N)), "lstsq" (general QR least squares, for gaps
    or uneven times), or "auto" (dst when allowed). Both routes give the same solution to rounding.
    T = t_N - t_1 (003: (N - 1) h). Returns :class:`SineSeriesFit`; raises :class:`SineSeriesError`.
    """
    t, _, _ = _as_inputs(t_s, y)
    return SineSeriesSolver(t, harmonics, weights=weights, method=method).fit(y, harmonics)


@dataclass(frozen=True)
class HarmonicsPath:
    """Residual sums of squares of the fits with M = 0..max_harmonics harmonics.

    harmonics (P,) = 0..M_max; rss (P, K) weighted RSS per component; dof (P,) = n_used - (M + 2);
    n_used samples with non-zero weight; method the route used.
    """

    harmonics: NDArray
    rss: NDArray
    dof: NDArray
    n_used: int
    method: str

    def score(self, criterion: Criterion = "gcv") -> NDArray:
        """Joint criterion over the K components (each with its own noise variance), lower is better.

        gcv: sum_k log(n rss_k / dof^2) (generalised cross-validation, Craven & Wahba 1979);
        aic: sum_k [n log(rss_k / n)] + 2 K p; bic: sum_k [n log(rss_k / n)] + K p log n;
        p = M + 2 parameters per component. Infinite where dof <= 0 or rss == 0.
        """
        n = self.n_used
        p = self.harmonics + 2
        k = self.rss.shape[1]
        with np.errstate(divide="ignore", invalid="ignore"):
            log_rss = np.sum(np.log(self.rss), axis=1)
            if criterion == "gcv":
                s = log_rss + k * (np.log(n) - 2.0 * np.log(self.dof.astype(float)))
            elif criterion == "aic":
                s = n * (log_rss - k * np.log(n)) + 2.0 * k * p
            elif criterion == "bic":
                s = n * (log_rss - k * np.log(n)) + k * p * np.log(n)
            else:
                raise SineSeriesError(f"criterion must be 'gcv', 'aic' or 'bic', got {criterion!r}")
        bad = (self.dof <= 0) | np.any(self.rss <= 0, axis=1) | ~np.isfinite(s)
        return np.where(bad, np.inf, s)

    def select(self, criterion: Criterion = "gcv") -> int:
        """The M minimising :meth:`score`."""
        return int(self.harmonics[int(np.argmin(self.score(criterion)))])


def harmonics_path(
    t_s: ArrayLike,
    y: ArrayLike,
    max_harmonics: int,
    *,
    weights: ArrayLike | None = None,
    method: Method = "auto",
) -> HarmonicsPath:
    """RSS of the 003 §1.3 fit for every M = 0..max_harmonics in one pass (see
    :meth:`SineSeriesSolver.path`). t_s (N,), y (N,) or (N, K), weights and method as in
    :func:`fit_sine_series`; max_harmonics is lowered to N - 2 and, on the general route, to the
    last harmonic the samples determine."""
    t, _, _ = _as_inputs(t_s, y)
    if isinstance(max_harmonics, bool) or not isinstance(max_harmonics, int | np.integer) or max_harmonics < 0:
        raise SineSeriesError(f"max_harmonics must be an integer >= 0, got {max_harmonics!r}")
    top = int(min(max_harmonics, t.size - 2))
    return SineSeriesSolver(t, top, weights=weights, method=method).path(y)


def select_harmonics(
    t_s: ArrayLike,
    y: ArrayLike,
    max_harmonics: int,
    *,
    criterion: Criterion = "gcv",
    weights: ArrayLike | None = None,
    method: Method = "auto",
) -> tuple[int, HarmonicsPath]:
    """Harmonic count M in 0..max_harmonics minimising ``criterion`` over the K components jointly.

    Same arguments as :func:`harmonics_path`; returns (M, path). See :meth:`HarmonicsPath.score`.
    """
    path = harmonics_path(t_s, y, max_harmonics, weights=weights, method=method)
    return path.select(criterion), path
