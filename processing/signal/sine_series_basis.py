"""The numerical basis of the sine-series smoother (processing.signal.sine_series, 003 §1.3-1.4).

Holds the dense design [1, tau, sin(pi m tau)] built by recurrence (:func:`sine_series_design`), the DST-I
pair of the uniform route (least-squares sine coefficients and the synthesis S c) and the factorisation of
the weighted design of the general route (:func:`gram_factor`: Cholesky of the Gram matrix, built by BLAS
or from trigonometric sums by a NUFFT, while it is well conditioned, else Householder QR). The method and
the two routes are described in :mod:`processing.signal.sine_series`.

tau dimensionless in [0, 1]; values in any unit.
"""

from __future__ import annotations

import numpy as np
import scipy.fft
import scipy.linalg
import scipy.linalg.blas
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "dst_coefficients",
    "dst_synthesis",
    "gram_factor",
    "gram_nufft",
    "sine_series_design",
]


SINE_RESTART = 64
"""sin(pi m tau) is built by the Chebyshev recurrence sin((m+1)x) = 2 cos(x) sin(mx) - sin((m-1)x), restarted
from two np.sin rows every this many harmonics (between restarts its rounding error stays below ~m^2 eps:
~1e-12 here; an error is amplified by up to m per step near tau = 0 and 1, which is why it restarts)."""


def sine_series_design(t_s: ArrayLike, harmonics: int, t1_s: float, span_s: float) -> NDArray:
    """Dense design matrix (N, M + 2) with columns [1, tau, sin(pi tau), ..., sin(pi M tau)].

    tau = (t_s - t1_s) / span_s (dimensionless; the slope coefficient of this design is per span,
    divide by span_s for per second). Column-major (Fortran order, what BLAS and LAPACK take without a
    copy); the sines by recurrence (:data:`SINE_RESTART`), ~10x faster than evaluating every sine.
    """
    tau = (np.asarray(t_s, dtype=np.float64) - t1_s) / span_s
    out = np.empty((harmonics + 2, tau.size))
    out[0] = 1.0
    out[1] = tau
    x = np.pi * tau
    c2 = 2.0 * np.cos(x)
    for m in range(1, harmonics + 1):
        row = out[m + 1]
        if (m - 1) % SINE_RESTART < 2:  # two exact consecutive rows start each block
            np.sin(m * x, out=row)
        else:
            np.multiply(c2, out[m], out=row)
            row -= out[m - 1]
    return out.T


CHIRP_MIN_SAMPLES = 4096
"""From this many samples, when 2 (N - 1) is not a fast FFT length, the leading M sine coefficients and their
synthesis go by a chirp-z convolution of length ~N + M (:func:`_chirp_sums`) instead of pocketfft's DST-I,
whose FFT of length 2 (N - 1) then takes the Bluestein route at ~4 N: a gyro segment of 20 min at 10 Hz
(N ~ 11,900, e.g. N - 1 = 2^4 x 5 x 149) took 4.3 ms per 3-column DST against ~0.5 ms. Shorter series (the
1 Hz star-tracker segments) and fast lengths keep the DST."""


def _use_chirp(n: int, harmonics: int) -> bool:
    """Whether the chirp-z route is cheaper for the first ``harmonics`` sines on n samples (constant above)."""
    p = 2 * (n - 1)
    return n >= CHIRP_MIN_SAMPLES and harmonics < n - 2 and int(scipy.fft.next_fast_len(p, real=True)) != p


def _chirp(count: int, n: int) -> NDArray:
    """exp(i pi k^2 / (2 (n - 1))) for k = 0..count-1, k^2 reduced exactly modulo its period 4 (n - 1) first."""
    r = (np.arange(count, dtype=np.int64) ** 2) % (4 * (n - 1))
    arg = (np.pi / (2 * (n - 1))) * r.astype(np.float64)
    return np.cos(arg) + 1j * np.sin(arg)


def _chirp_sums(a: NDArray, n: int, n_out: int) -> NDArray:
    """The sums y_o = sum_i a_i exp(i pi (i + 1)(o + 1) / (n - 1)), o < n_out, of real a (n_in, C): complex
    (n_out, C), whose imaginary part is the sine sum of S^T x and S c. Bluestein's identity
    (i + 1)(o + 1) = ((o + 1)^2 + (i + 1)^2 - (o - i)^2) / 2 makes it one convolution with the chirp, by FFTs
    of a fast length >= n_in + n_out - 1 (rounding ~eps log N of the sums, like the FFT's)."""
    n_in = a.shape[0]
    size = int(scipy.fft.next_fast_len(n_in + n_out - 1))
    chirp = _chirp(max(n_in, n_out) + 1, n)  # the chirp is even in k
    kernel = np.zeros(size, dtype=np.complex128)
    kernel[:n_out] = np.conj(chirp[:n_out])
    kernel[size - n_in + 1:] = np.conj(chirp[n_in - 1:0:-1])
    src = np.zeros((a.shape[1], size), dtype=np.complex128)  # columns as rows: contiguous transforms
    src[:, :n_in] = a.T * chirp[1:n_in + 1]
    spec = scipy.fft.fft(src, axis=1)
    spec *= scipy.fft.fft(kernel)
    return (scipy.fft.ifft(spec, axis=1, overwrite_x=True)[:, :n_out] * chirp[1:n_out + 1]).T


def dst_coefficients(x: NDArray, harmonics: int | None = None) -> NDArray:
    """Least-squares sine coefficients c_m = (S^T x)_m / ((N-1)/2), m = 1..M, of columns x (N, C): M = harmonics
    (None: all N - 2). DST-I, or the chirp-z sums for long series of awkward length (CHIRP_MIN_SAMPLES)."""
    n = x.shape[0]
    m = n - 2 if harmonics is None else int(harmonics)
    if _use_chirp(n, m):
        return _chirp_sums(x[1:-1], n, m).imag * (2.0 / (n - 1))
    return scipy.fft.dst(x[1:-1], type=1, axis=0)[:m] / (n - 1)


def dst_synthesis(c: NDArray, n: int) -> NDArray:
    """S c on the uniform grid of n samples (zero at both ends) for coefficients c (M, C), M <= n-2 (DST-I, or
    the chirp-z sums as in :func:`dst_coefficients`)."""
    out = np.zeros((n, c.shape[1]))
    if _use_chirp(n, c.shape[0]):
        if c.shape[0]:
            out[1:-1] = _chirp_sums(c, n, n - 2).imag
        return out
    full = np.zeros((n - 2, c.shape[1]))
    full[: c.shape[0]] = c
    out[1:-1] = 0.5 * scipy.fft.dst(full, type=1, axis=0)
    return out


GRAM_MIN_PIVOT_RATIO = 1e-4
"""The general route factorises the Gram matrix A^T W A by Cholesky (A^T A = R^T R, the same R as
QR's up to signs, ~4x fewer flops and BLAS-3 speed) while the smallest diagonal of R is above this
times the largest (cond(A) below ~1e4, so the normal equations lose at most ~8 of 16 digits); a
worse-conditioned design (long gaps, too many harmonics) is factorised by Householder QR."""


NUFFT_GRAM_MIN_HARMONICS = 16
"""From this many harmonics the Gram matrix is built from trigonometric sums by a NUFFT (below, by BLAS)."""


def gram_nufft(tau: NDArray, w: NDArray | None, harmonics: int) -> NDArray:
    """A^T W A of the design [1, tau, sin(pi m tau)] from the sums E_j = sum w e^(i pi j tau) (j <= 2M) and
    F_j = sum w tau e^(i pi j tau) (j <= M), one type-1 NUFFT (O(N + M log M)) instead of N (M + 2)^2 flops:
    sin a x sin b x = (cos (a - b) x - cos (a + b) x) / 2 makes the sine block Toeplitz minus Hankel."""
    import finufft  # imported on first use (the service does not need it)

    m = harmonics
    ww = np.ones_like(tau) if w is None else w
    n_modes = 2 * (2 * m + 1)  # modes -(2M+1) .. 2M; the non-negative half is used
    f = finufft.nufft1d1(np.pi * tau, np.vstack([ww, ww * tau]).astype(np.complex128), n_modes,
                         eps=NUFFT_GRAM_EPS, isign=1, nthreads=1)
    e, ft = f[0, n_modes // 2:], f[1, n_modes // 2:n_modes // 2 + m + 1]
    g = np.empty((m + 2, m + 2))
    g[0, 0], g[0, 1], g[1, 1] = float(np.sum(ww)), float(ww @ tau), float(ww @ (tau * tau))
    g[1, 0] = g[0, 1]
    g[0, 2:] = g[2:, 0] = e[1:m + 1].imag
    g[1, 2:] = g[2:, 1] = ft[1:m + 1].imag
    er = e.real
    g[2:, 2:] = 0.5 * (scipy.linalg.toeplitz(er[:m]) - scipy.linalg.hankel(er[2:m + 2], er[m + 1:2 * m + 1]))
    return g


NUFFT_GRAM_EPS = 1e-14
"""Relative tolerance of those sums (against sum |w|): far below what the pivot check lets the solution lose."""


def gram_factor(a: NDArray, tau: NDArray, w: NDArray | None) -> tuple[NDArray | None, NDArray]:
    """(Q or None, R) of the weighted design a (N, P) = sqrt(w) [1, tau, sin(pi m tau)]: R from the Cholesky
    factor of its Gram matrix when that is well conditioned (Q then implicit, a R^-1), else the economic
    Householder QR."""
    try:
        if a.shape[1] - 2 >= NUFFT_GRAM_MIN_HARMONICS:
            gram = gram_nufft(tau, w, a.shape[1] - 2)
        else:
            gram = scipy.linalg.blas.dsyrk(1.0, np.asfortranarray(a), trans=1)  # upper triangle of a^T a
        r = scipy.linalg.cholesky(gram, lower=False, check_finite=False)
        d = np.abs(np.diag(r))
        if d.min() > GRAM_MIN_PIVOT_RATIO * d.max():
            return None, r
    except np.linalg.LinAlgError:
        pass
    q, r = scipy.linalg.qr(a, mode="economic", check_finite=False)
    return q, r
