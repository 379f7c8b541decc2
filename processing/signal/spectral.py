"""Periodogram and amplitude spectrum of 003 §1.5, their gapped/uneven equivalent, and aliasing.

003 §1.5: for samples x_n at t_n = t_0 + n h (n = 1..N) the periodogram on 0 <= f <= F = 1/(2h) is

    I(f) = [sum_n (x_n - x̄) cos(pi n f / F)]^2 + [sum_n (x_n - x̄) sin(pi n f / F)]^2,

and the amplitude spectrum A(f) = 2 sqrt(I(f)) / N estimates the amplitude of a harmonic component
("cyclic trend") of frequency f: for x = a cos 2 pi f t + b sin 2 pi f t, A(f) ~ sqrt(a^2 + b^2).

- Uniform data: :func:`amplitude_spectrum` evaluates I(f) with an FFT on f_k = k / (M h), M the
  smallest fast FFT length >= N s (s the oversampling factor; :func:`fft_length`: N s itself when it
  has only small prime factors, else an even ``scipy.fft.next_fast_len`` a few % above it, so the grid
  still ends at 1/(2h)), by zero padding. That is the paper's sum exactly at
  those frequencies: A(f) is a function of continuous f and the grid only samples it, a little finer
  than 1/(N h s). Padding to a fast length avoids the Bluestein route of pocketfft for lengths with
  a large prime factor (24 h of 10 Hz with both ends, N = 864,001 = 31 x 47 x 593: 0.35 s per
  transform against 0.04 s at M = 874,800). The independent-frequency spacing stays
  ``Spectrum.resolution_hz`` = 1/(N h); consumers count cells with it, not with the grid step.
- Gapped or uneven data: :func:`amplitude_spectrum_uneven` is the floating-mean generalised
  Lomb-Scargle periodogram (Zechmeister & Kürster 2009; equal to ``scipy.signal.lombscargle(...,
  normalize="amplitude", floating_mean=True)``, computed here for all components at once) scaled to
  amplitude: at each f it is the amplitude sqrt(a^2 + b^2) of the least-squares fit
  c + a cos 2 pi f t + b sin 2 pi f t, which equals the paper's A(f) for uniform data at the Fourier
  frequencies and stays an unbiased amplitude estimate when samples are missing. When the times lie
  on a uniform grid with missing nodes and the product samples x frequencies is large, the paper's
  sums over the present samples (zero-filled FFT, normalised by the number present) are used
  instead (:func:`amplitude_spectrum_gapped`); that is O(N log N) and the same estimator to
  within the small leakage the gaps cause.
- :func:`alias_frequency` folds a frequency into 0..1/(2h) of a sampling step h
  (003 §1.5 and §2.4: the 0.4 Hz mirror line seen at h = 3 s as 0.0667 Hz, period 15 s).
- Lines in these spectra (detection, sinusoid fits, prewhitening): processing.signal.spectral_lines.

Times in seconds, frequencies in Hz, amplitudes in the unit of x. Pure numpy/scipy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Spectrum",
    "SpectralError",
    "alias_frequency",
    "amplitude_spectrum",
    "amplitude_spectrum_gapped",
    "amplitude_spectrum_of_samples",
    "amplitude_spectrum_uneven",
    "explained_sum_of_squares",
    "fft_length",
    "grid_nodes",
    "sample_values",
]

LOMB_SCARGLE_MAX_WORK = 20_000_000
"""Above this many samples x frequencies no spectrum is summed directly: on-grid gapped data use the
zero-filled FFT, other samples on a uniform frequency grid the NUFFT (finufft)."""
MAX_FREQUENCIES = 1 << 25
"""Work guard of every route: a spectrum of more frequencies (33.5 M: over 38 days of 10 Hz samples)
is refused with a SpectralError naming the sizes, rather than exhausting memory."""
GRID_RTOL = 1e-6
"""Times are on a grid of step h when every (t_n - t_1)/h is within GRID_RTOL of an integer."""
MAX_GRID_FILL = 64
"""The zero-filled FFT is used only when the grid has at most this many nodes per present sample
(otherwise a few samples spread over a long span would allocate a huge, mostly empty grid)."""
NUFFT_MIN_FREQUENCIES = 256
"""Fewer trial frequencies (e.g. the 9-point refinement grids) are always summed directly."""
NUFFT_EPS = 1e-12
"""Requested relative precision of the NUFFT sums (finufft's eps)."""


class SpectralError(ValueError):
    """Bad input to a spectral function: shapes, too few samples, bad step or frequencies."""


@dataclass(frozen=True)
class Spectrum:
    """freq_hz (F,), amplitude (F,) or (F, K) in the unit of x (003: A(f) = 2 sqrt(I)/N);
    n_samples used; method "fft" | "fft_gapped" | "lomb_scargle"; resolution_hz = 1/(span) the
    independent-frequency spacing. The grid step freq_hz[1] - freq_hz[0] may be finer: oversampled
    grids, and the FFT methods' padding to a fast length (k / (M h), M = :func:`fft_length`)."""

    freq_hz: NDArray
    amplitude: NDArray
    n_samples: int
    method: str
    resolution_hz: float

    @property
    def periodogram(self) -> NDArray:
        """The paper's I(f) = (N A(f) / 2)^2."""
        return (0.5 * self.n_samples * self.amplitude) ** 2


def sample_values(x: ArrayLike, n: int | None = None) -> NDArray:
    """x as float64 (N,) or (N, K), N = n rows (when given) >= 3, finite; SpectralError otherwise."""
    v = np.asarray(x, dtype=np.float64)
    if v.ndim not in (1, 2):
        raise SpectralError(f"x must be (N,) or (N, K), got shape {v.shape}")
    if n is not None and v.shape[0] != n:
        raise SpectralError(f"x must have {n} rows to match t_s, got {v.shape[0]}")
    if v.shape[0] < 3:
        raise SpectralError(f"need at least 3 samples, got {v.shape[0]}")
    if not np.all(np.isfinite(v)):
        raise SpectralError("x must be finite")
    return v


def fft_length(n: int) -> int:
    """The FFT length used for n (>= 1) points: n itself when it is a fast length (2-3-5 smooth,
    ``scipy.fft.next_fast_len(n, real=True)``), else the smallest even fast length above n, so that
    the padded grid k / (M h) ends exactly at the Nyquist frequency 1/(2h) of 003 §1.5. The samples
    are padded with zeros to it (see the module docstring)."""
    n = int(n)
    if int(scipy.fft.next_fast_len(n, real=True)) == n:
        return n
    return 2 * int(scipy.fft.next_fast_len((n + 1) // 2, real=True))


def amplitude_spectrum(x: ArrayLike, sample_period_s: float, *, oversample: int = 1) -> Spectrum:
    """Amplitude spectrum A(f) = 2 sqrt(I(f))/N of uniform samples (003 §1.5), 0 <= f <= 1/(2h).

    x: (N,) or (N, K) samples at step sample_period_s = h [s]; mean removed (x̄ of 003); oversample:
    integer zero-padding factor. Grid f_k = k / (M h), k = 0..M // 2, M = fft_length(N oversample):
    frequency step 1/(M h) <= 1/(N h oversample). Returns :class:`Spectrum`.
    """
    v = sample_values(x)
    if not sample_period_s > 0:
        raise SpectralError(f"sample_period_s must be > 0, got {sample_period_s}")
    if int(oversample) < 1:
        raise SpectralError(f"oversample must be an integer >= 1, got {oversample}")
    n = v.shape[0]
    n_fft = fft_length(n * int(oversample))
    spec = scipy.fft.rfft(v - v.mean(axis=0), n=n_fft, axis=0)
    freq = scipy.fft.rfftfreq(n_fft, d=sample_period_s)
    return Spectrum(freq, 2.0 * np.abs(spec) / n, n, "fft", 1.0 / (n * sample_period_s))


def grid_nodes(t_s: ArrayLike, step_s: float) -> tuple[NDArray, float] | None:
    """Grid node of each sample and the grid step, when the times lie on a grid t_1 + k h.

    t_s (N,) increasing [s]; step_s: an estimate of h (e.g. the median step). The step is refined as
    span / (last node index), so that the float error of one difference (1.5e-12 s at t = 86,400 s)
    does not accumulate over 10^6 nodes; then every (t_n - t_1)/h must be within GRID_RTOL of an
    integer and the nodes must be distinct. Returns (k (N,) int64 from 0, h [s]) or None (off grid).
    """
    t = np.asarray(t_s, dtype=np.float64)
    dt = t - t[0]
    h = float(step_s)
    if not h > 0 or t.size < 2:
        return None
    for _ in range(2):  # the refined step re-rounds nodes far from t_1 that a coarse step misplaced
        k = np.round(dt / h)
        if not k[-1] > 0:
            return None
        h = float(dt[-1] / k[-1])
    if np.any(np.diff(k) <= 0) or np.any(np.abs(dt / h - k) > GRID_RTOL):
        return None
    return k.astype(np.int64), h


def _grid_index(t: NDArray, h: float) -> NDArray | None:
    nodes = grid_nodes(t, h)
    return None if nodes is None else nodes[0]


def _check_frequency_count(n_freq: float, n_samples: int) -> None:
    if n_freq > MAX_FREQUENCIES:
        raise SpectralError(
            f"a spectrum of {n_samples} samples would need {n_freq:.3g} frequencies, more than the "
            f"{MAX_FREQUENCIES} this module evaluates: analyse a shorter window or decimate the samples"
        )


def amplitude_spectrum_gapped(
    t_s: ArrayLike, x: ArrayLike, sample_period_s: float, *, oversample: int = 1
) -> Spectrum:
    """003 §1.5 sums over the samples present, for times on a grid t_1 + k h with missing nodes.

    t_s (N,) [s] on the grid of step sample_period_s (SpectralError otherwise), x (N,) or (N, K).
    The mean of the present samples is removed, absent nodes count as zero, and A(f) = 2 sqrt(I)/N
    with N the number present. Grid k / (M h), M = fft_length(nodes x oversample), as in
    :func:`amplitude_spectrum`. O(N log N).
    """
    t = np.asarray(t_s, dtype=np.float64)
    v = sample_values(x, t.size)
    nodes = grid_nodes(t, sample_period_s)
    if nodes is None:
        raise SpectralError(f"times are not on a grid of step {sample_period_s} s")
    idx, sample_period_s = nodes
    n = t.size
    _check_frequency_count(0.5 * (int(idx[-1]) + 1) * int(oversample), n)
    filled = np.zeros((int(idx[-1]) + 1,) + v.shape[1:])
    filled[idx] = v - v.mean(axis=0)
    n_fft = fft_length(filled.shape[0] * int(oversample))
    spec = scipy.fft.rfft(filled, n=n_fft, axis=0)
    freq = scipy.fft.rfftfreq(n_fft, d=sample_period_s)
    return Spectrum(freq, 2.0 * np.abs(spec) / n, n, "fft_gapped", 1.0 / (t[-1] - t[0] + sample_period_s))


def amplitude_spectrum_uneven(
    t_s: ArrayLike, x: ArrayLike, freq_hz: ArrayLike | None = None, *, oversample: int = 2
) -> Spectrum:
    """Amplitude spectrum of gapped/uneven samples: floating-mean Lomb-Scargle scaled to amplitude.

    t_s (N,) increasing [s]; x (N,) or (N, K); freq_hz (F,) >= 0 or None for the default grid (below),
    in steps of 1/(span oversample). At each f the value is the amplitude of the
    least-squares c + a cos + b sin fit (see module docstring); f = 0 is reported as 0. Cost O(N F)
    summed directly up to LOMB_SCARGLE_MAX_WORK, beyond that O(N + F log F) by NUFFT when the
    frequencies are uniformly spaced (the default grid is); SpectralError for larger non-uniform sets.
    The default grid runs from 1/span to Nyquist - 1/span: within one resolution cell of 0 a sinusoid
    is not separable from the floating mean, and within one of the Nyquist frequency of (nearly)
    uniform samples its sine term vanishes.
    """
    t = np.asarray(t_s, dtype=np.float64)
    v = sample_values(x, t.size)
    if t.ndim != 1 or np.any(np.diff(t) <= 0):
        raise SpectralError("t_s must be 1-D and strictly increasing")
    span = float(t[-1] - t[0])
    if freq_hz is None:  # from one resolution cell (lower frequencies are degenerate with the mean)
        nyquist = 0.5 / float(np.median(np.diff(t)))
        df = 1.0 / (span * int(oversample))
        _check_frequency_count((nyquist - 1.0 / span) / df, t.size)
        freq = np.arange(1.0 / span, nyquist - 1.0 / span + 0.5 * df, df)
    else:
        freq = np.asarray(freq_hz, dtype=np.float64)
        if freq.ndim != 1 or np.any(freq < 0):
            raise SpectralError("freq_hz must be 1-D and >= 0")
    cols = v.reshape(t.size, -1)
    amp = np.zeros((freq.size, cols.shape[1]))
    pos = freq > 0
    a, b, _, _ = _ls_terms(t - t[0], cols, freq[pos])
    amp[pos] = np.hypot(a, b)
    return Spectrum(freq, amp.reshape((freq.size,) + v.shape[1:]), t.size, "lomb_scargle", 1.0 / span)


def amplitude_spectrum_of_samples(
    t_s: ArrayLike, x: ArrayLike, *, oversample: int = 1, prefer_fft: bool = False
) -> Spectrum:
    """The spectrum of 003 §1.5 for any sampling: uniform -> FFT, on-grid gaps -> Lomb-Scargle (or the
    zero-filled FFT when N x F > LOMB_SCARGLE_MAX_WORK or prefer_fft), uneven -> Lomb-Scargle.
    t_s (N,) [s], x (N,) or (N, K)."""
    t = np.asarray(t_s, dtype=np.float64)
    v = sample_values(x, t.size)
    steps = np.diff(t)
    if np.any(steps <= 0):
        raise SpectralError("t_s must be strictly increasing")
    nodes = grid_nodes(t, float(np.median(steps)))
    if nodes is not None and nodes[0][-1] == t.size - 1:
        return amplitude_spectrum(v, nodes[1], oversample=oversample)
    h = float(np.median(steps)) if nodes is None else nodes[1]
    n_freq = 0.5 * (t[-1] - t[0]) / h * oversample
    _check_frequency_count(n_freq, t.size)
    if nodes is not None and nodes[0][-1] < MAX_GRID_FILL * t.size:
        if prefer_fft or t.size * n_freq > LOMB_SCARGLE_MAX_WORK:
            return amplitude_spectrum_gapped(t, v, h, oversample=oversample)
    return amplitude_spectrum_uneven(t, v, oversample=max(1, oversample))


def alias_frequency(freq_hz: ArrayLike, sample_period_s: float) -> NDArray:
    """Apparent frequency |f - k/h| (k = round(f h)) in 0..1/(2h) of a line f sampled at step h.

    003 §2.4: 0.4 Hz at h = 3 s appears at 0.0667 Hz (period 15 s). Returns the shape of freq_hz.
    """
    if not sample_period_s > 0:
        raise SpectralError(f"sample_period_s must be > 0, got {sample_period_s}")
    f = np.asarray(freq_hz, dtype=np.float64)
    fs = 1.0 / sample_period_s
    return np.abs(f - np.round(f / fs) * fs)


_LS_CHUNK = 1 << 20  # trial frequencies x samples per block of the direct least-squares spectrum


def _ls_terms(t: NDArray, v: NDArray, freq: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Floating-mean least-squares sinusoid at each trial frequency, all components at once.

    t (N,) [s], v (N, K), freq (F,) > 0 [Hz]. Returns (a, b, yc, ys), each (F, K): the fit
    c + a cos 2 pi f t + b sin 2 pi f t (the mean is absorbed by centring the columns) and the
    projections yc = C^T v, ys = S^T v of the centred data; a yc + b ys is the explained sum of
    squares. Zechmeister & Kürster (2009) generalised Lomb-Scargle, computed directly while
    N x F <= LOMB_SCARGLE_MAX_WORK, else from NUFFT sums (:func:`_ls_terms_nufft`).
    """
    if t.size * freq.size > LOMB_SCARGLE_MAX_WORK and freq.size > NUFFT_MIN_FREQUENCIES:
        df = _uniform_step(freq)
        if df is None:
            raise SpectralError(
                f"{freq.size} non-uniform trial frequencies x {t.size} samples exceed the direct-sum work "
                f"limit {LOMB_SCARGLE_MAX_WORK:.0e}: give a uniform frequency grid (NUFFT route)"
            )
        return _ls_terms_nufft(t, v, float(freq[0]), df, freq.size)
    vc = v - v.mean(axis=0)
    out = [np.empty((freq.size, v.shape[1])) for _ in range(4)]
    step = max(1, _LS_CHUNK // max(t.size, 1))
    for i in range(0, freq.size, step):  # blocks of frequencies, vectorised over samples
        f = freq[i:i + step]
        arg = 2.0 * np.pi * f[:, None] * t[None, :]
        c, s = np.cos(arg), np.sin(arg)
        c -= c.mean(axis=1, keepdims=True)
        s -= s.mean(axis=1, keepdims=True)
        cc, ss, cs = np.sum(c * c, 1), np.sum(s * s, 1), np.sum(c * s, 1)
        yc, ys = c @ vc, s @ vc
        det = (cc * ss - cs * cs)[:, None]
        out[0][i:i + step] = (ss[:, None] * yc - cs[:, None] * ys) / det
        out[1][i:i + step] = (cc[:, None] * ys - cs[:, None] * yc) / det
        out[2][i:i + step] = yc
        out[3][i:i + step] = ys
    return out[0], out[1], out[2], out[3]


def _uniform_step(freq: NDArray) -> float | None:
    """The step df of freq when freq = freq[0] + i df to 1e-9 of df, else None."""
    if freq.size < 2:
        return None
    df = float(freq[-1] - freq[0]) / (freq.size - 1)
    ok = df > 0 and np.all(np.abs(freq - (freq[0] + df * np.arange(freq.size))) <= 1e-9 * df)
    return df if ok else None


def _uniform_sums(t: NDArray, c: NDArray, f0: float, df: float, n: int) -> NDArray:
    """sum_j c[k, j] exp(i 2 pi (f0 + m df) t_j) for m = 0..n-1: (K, n) complex, by a type-1 NUFFT.

    The strengths are turned by the phase at the middle frequency f0 + (n // 2) df, so that the
    n modes requested, -n/2..(n-1)/2, are m - n // 2 (finufft's default increasing mode order).
    """
    import finufft  # imported on first use: only long off-grid spectra need it

    mid = f0 + (n // 2) * df
    strengths = np.ascontiguousarray(c * np.exp(2j * np.pi * mid * t)[None, :], dtype=np.complex128)
    x = np.mod(2.0 * np.pi * df * t + np.pi, 2.0 * np.pi) - np.pi
    return np.atleast_2d(finufft.nufft1d1(x, strengths, n, eps=NUFFT_EPS, isign=1, nthreads=1))


def _ls_terms_nufft(t: NDArray, v: NDArray, f0: float, df: float, n: int) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """:func:`_ls_terms` on the uniform grid f0 + m df (m < n), from type-1 NUFFT sums: O(N + n log n).

    The centred sums follow from sum cos, sum sin (at f), sum cos 2wt, sum sin 2wt (at 2f) and the
    data sums: C C = (N + sum cos 2wt)/2 - (sum cos)^2/N, S S = (N - sum cos 2wt)/2 - (sum sin)^2/N,
    C S = sum sin 2wt / 2 - sum cos sum sin / N (the Press & Rybicki 1989 route of fast Lomb-Scargle).
    """
    n_s = t.size
    vc = v - v.mean(axis=0)
    at_f = _uniform_sums(t, np.vstack([np.ones(n_s), vc.T]), f0, df, n)  # (1 + K, n)
    at_2f = _uniform_sums(t, np.ones((1, n_s)), 2.0 * f0, 2.0 * df, n)[0]
    sc, ss = at_f[0].real, at_f[0].imag
    cc = 0.5 * (n_s + at_2f.real) - sc * sc / n_s
    sn = 0.5 * (n_s - at_2f.real) - ss * ss / n_s
    cs = 0.5 * at_2f.imag - sc * ss / n_s
    yc, ys = at_f[1:].real.T, at_f[1:].imag.T  # (n, K)
    det = (cc * sn - cs * cs)[:, None]
    a = (sn[:, None] * yc - cs[:, None] * ys) / det
    b = (cc[:, None] * ys - cs[:, None] * yc) / det
    return a, b, yc, ys


ESS_RECURRENCE_MAX = 64
"""Uniform trial grids of at most this many frequencies (the refinement grids of spectral_lines.fit_sinusoid)
take cos/sin by angle addition from the first frequency (:func:`_ess_uniform`): two trigonometric evaluations
per sample and step instead of one each per frequency, which took 2/3 of the least-squares sums (a 9-point grid
over 837,000 gyro samples: 0.26 s CPU); the rounding of the recurrence grows ~eps per step."""


def _ess_uniform(t: NDArray, v: NDArray, f0: float, df: float, n: int) -> NDArray:
    """:func:`explained_sum_of_squares` on the grid f0 + k df (k < n): the same centred least-squares sums as
    :func:`_ls_terms`, one frequency at a time, with cos/sin(2 pi (f0 + k df) t) by angle addition."""
    vc = v - v.mean(axis=0)
    w0, dw = 2.0 * np.pi * f0 * t, 2.0 * np.pi * df * t
    c, s = np.cos(w0), np.sin(w0)
    cd, sd = np.cos(dw), np.sin(dw)
    out = np.empty(n)
    for k in range(n):  # trial frequencies (few)
        if k:
            c, s = c * cd - s * sd, s * cd + c * sd
        cc_, sc_ = c - c.mean(), s - s.mean()
        cc, ss, cs = cc_ @ cc_, sc_ @ sc_, cc_ @ sc_
        yc, ys = cc_ @ vc, sc_ @ vc
        det = cc * ss - cs * cs
        a, b = (ss * yc - cs * ys) / det, (cc * ys - cs * yc) / det
        out[k] = np.sum(a * yc + b * ys)
    return out


def explained_sum_of_squares(t: NDArray, v: NDArray, freq: NDArray) -> NDArray:
    """Sum over components of the explained sum of squares of the floating-mean least-squares sinusoid
    at each trial frequency freq (F,) [Hz] for samples v (N, K) at t (N,) [s]; returns (F,). Small uniform
    grids by angle addition (ESS_RECURRENCE_MAX)."""
    df = _uniform_step(freq) if 1 < freq.size <= ESS_RECURRENCE_MAX else None
    if df is not None and freq[0] > 0:
        return _ess_uniform(t, v, float(freq[0]), df, freq.size)
    a, b, yc, ys = _ls_terms(t, v, freq)
    return np.sum(a * yc + b * ys, axis=1)
