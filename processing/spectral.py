"""Periodogram and amplitude spectrum of 003 §1.5, their gapped/uneven equivalent, lines and aliasing.

003 §1.5: for samples x_n at t_n = t_0 + n h (n = 1..N) the periodogram on 0 <= f <= F = 1/(2h) is

    I(f) = [sum_n (x_n - x̄) cos(pi n f / F)]^2 + [sum_n (x_n - x̄) sin(pi n f / F)]^2,

and the amplitude spectrum A(f) = 2 sqrt(I(f)) / N estimates the amplitude of a harmonic component
("cyclic trend") of frequency f: for x = a cos 2 pi f t + b sin 2 pi f t, A(f) ~ sqrt(a^2 + b^2).

- Uniform data: :func:`amplitude_spectrum` evaluates I(f) with an FFT on f_k = k / (N h s) (s the
  oversampling factor, zero padding), which is the paper's sum exactly at those frequencies.
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
- :func:`detect_lines`: local maxima of A(f)^2 above a false-alarm threshold over a running-median
  noise floor; :func:`fit_sinusoid` refines the frequency and fits amplitude and phase by least
  squares; :func:`find_lines` alternates the two and subtracts each line found ("prewhitening"), so
  that the spectral-window sidelobes of a strong line are not taken for lines;
  :func:`alias_frequency` folds a frequency into 0..1/(2h) of a sampling step h
  (003 §1.5 and §2.4: the 0.4 Hz mirror line seen at h = 3 s as 0.0667 Hz, period 15 s).

Times in seconds, frequencies in Hz, amplitudes in the unit of x. Pure numpy/scipy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft
import scipy.ndimage
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "FoundLine",
    "LinePeak",
    "SinusoidFit",
    "Spectrum",
    "SpectralError",
    "alias_frequency",
    "amplitude_spectrum",
    "amplitude_spectrum_gapped",
    "amplitude_spectrum_of_samples",
    "amplitude_spectrum_uneven",
    "detect_lines",
    "find_lines",
    "fit_sinusoid",
]

LOMB_SCARGLE_MAX_WORK = 20_000_000
"""Above this many samples x frequencies, on-grid gapped data use the zero-filled FFT route."""
GRID_RTOL = 1e-6
"""Times are on a grid of step h when every (t_n - t_1)/h is within GRID_RTOL of an integer."""


class SpectralError(ValueError):
    """Bad input to a spectral function: shapes, too few samples, bad step or frequencies."""


@dataclass(frozen=True)
class Spectrum:
    """freq_hz (F,), amplitude (F,) or (F, K) in the unit of x (003: A(f) = 2 sqrt(I)/N);
    n_samples used; method "fft" | "fft_gapped" | "lomb_scargle"; resolution_hz = 1/(span) the
    independent-frequency spacing (oversampled grids are finer)."""

    freq_hz: NDArray
    amplitude: NDArray
    n_samples: int
    method: str
    resolution_hz: float

    @property
    def periodogram(self) -> NDArray:
        """The paper's I(f) = (N A(f) / 2)^2."""
        return (0.5 * self.n_samples * self.amplitude) ** 2


def _values(x: ArrayLike, n: int | None = None) -> NDArray:
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


def amplitude_spectrum(x: ArrayLike, sample_period_s: float, *, oversample: int = 1) -> Spectrum:
    """Amplitude spectrum A(f) = 2 sqrt(I(f))/N of uniform samples (003 §1.5), 0 <= f <= 1/(2h).

    x: (N,) or (N, K) samples at step sample_period_s = h [s]; mean removed (x̄ of 003); oversample:
    integer zero-padding factor (frequency step 1/(N h oversample)). Returns :class:`Spectrum`.
    """
    v = _values(x)
    if not sample_period_s > 0:
        raise SpectralError(f"sample_period_s must be > 0, got {sample_period_s}")
    if int(oversample) < 1:
        raise SpectralError(f"oversample must be an integer >= 1, got {oversample}")
    n = v.shape[0]
    n_fft = int(n * int(oversample))
    spec = scipy.fft.rfft(v - v.mean(axis=0), n=n_fft, axis=0)
    freq = scipy.fft.rfftfreq(n_fft, d=sample_period_s)
    return Spectrum(freq, 2.0 * np.abs(spec) / n, n, "fft", 1.0 / (n * sample_period_s))


def _grid_index(t: NDArray, h: float) -> NDArray | None:
    k = (t - t[0]) / h
    ki = np.round(k)
    return ki.astype(np.int64) if np.all(np.abs(k - ki) <= GRID_RTOL) else None


def amplitude_spectrum_gapped(
    t_s: ArrayLike, x: ArrayLike, sample_period_s: float, *, oversample: int = 1
) -> Spectrum:
    """003 §1.5 sums over the samples present, for times on a grid t_1 + k h with missing nodes.

    t_s (N,) [s] on the grid of step sample_period_s (SpectralError otherwise), x (N,) or (N, K).
    The mean of the present samples is removed, absent nodes count as zero, and A(f) = 2 sqrt(I)/N
    with N the number present. O(N log N).
    """
    t = np.asarray(t_s, dtype=np.float64)
    v = _values(x, t.size)
    idx = _grid_index(t, sample_period_s)
    if idx is None:
        raise SpectralError(f"times are not on a grid of step {sample_period_s} s")
    n = t.size
    filled = np.zeros((int(idx[-1]) + 1,) + v.shape[1:])
    filled[idx] = v - v.mean(axis=0)
    n_fft = filled.shape[0] * int(oversample)
    spec = scipy.fft.rfft(filled, n=n_fft, axis=0)
    freq = scipy.fft.rfftfreq(n_fft, d=sample_period_s)
    return Spectrum(freq, 2.0 * np.abs(spec) / n, n, "fft_gapped", 1.0 / (t[-1] - t[0] + sample_period_s))


def amplitude_spectrum_uneven(
    t_s: ArrayLike, x: ArrayLike, freq_hz: ArrayLike | None = None, *, oversample: int = 2
) -> Spectrum:
    """Amplitude spectrum of gapped/uneven samples: floating-mean Lomb-Scargle scaled to amplitude.

    t_s (N,) increasing [s]; x (N,) or (N, K); freq_hz (F,) >= 0 or None for the default grid (below),
    in steps of 1/(span oversample). At each f the value is the amplitude of the
    least-squares c + a cos + b sin fit (see module docstring); f = 0 is reported as 0. Cost O(N F).
    The default grid runs from 1/span to Nyquist - 1/span: within one resolution cell of 0 a sinusoid
    is not separable from the floating mean, and within one of the Nyquist frequency of (nearly)
    uniform samples its sine term vanishes.
    """
    t = np.asarray(t_s, dtype=np.float64)
    v = _values(x, t.size)
    if t.ndim != 1 or np.any(np.diff(t) <= 0):
        raise SpectralError("t_s must be 1-D and strictly increasing")
    span = float(t[-1] - t[0])
    if freq_hz is None:  # from one resolution cell (lower frequencies are degenerate with the mean)
        nyquist = 0.5 / float(np.median(np.diff(t)))
        df = 1.0 / (span * int(oversample))
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
    v = _values(x, t.size)
    steps = np.diff(t)
    if np.any(steps <= 0):
        raise SpectralError("t_s must be strictly increasing")
    h = float(np.median(steps))
    idx = _grid_index(t, h)
    if idx is not None and idx[-1] == t.size - 1:
        return amplitude_spectrum(v, h, oversample=oversample)
    n_freq = 0.5 * (t[-1] - t[0]) / h * oversample
    if idx is not None and (prefer_fft or t.size * n_freq > LOMB_SCARGLE_MAX_WORK):
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


@dataclass(frozen=True)
class LinePeak:
    """A significant spectral maximum: freq_hz, amplitude (unit of x), component index, and
    ratio = A^2 / threshold (> 1)."""

    freq_hz: float
    amplitude: float
    component: int
    ratio: float


def detect_lines(
    spectrum: Spectrum,
    *,
    min_freq_hz: float = 0.0,
    max_freq_hz: float | None = None,
    false_alarm: float = 1e-3,
    floor_window_hz: float | None = None,
) -> list[LinePeak]:
    """Significant lines of an amplitude spectrum, per component.

    Noise floor: running median of A(f)^2 over floor_window_hz (default about 1/20 of the band,
    50..500 resolution cells: a longer window makes the floor, hence the threshold, steadier). For
    noise alone A^2 is exponential (2 degrees of freedom), so its mean is median / ln 2 and the
    chance that any of the F_ind independent cells exceeds mean ln(F_ind / false_alarm) is about
    false_alarm. A line is a local maximum above that threshold, the largest within +-2 resolution
    cells, in min_freq_hz < f <= max_freq_hz and below the last resolution cell (Nyquist). The floor
    is taken inside that band only. Returned sorted by frequency.
    """
    f = spectrum.freq_hz
    amp = spectrum.amplitude.reshape(f.size, -1)
    df = float(f[1] - f[0]) if f.size > 1 else 1.0
    cells_per_res = max(1, int(round(spectrum.resolution_hz / df)))
    top = f[-1] - spectrum.resolution_hz  # the Nyquist cell: amplitude undetermined (sin term vanishes)
    band = (f > min_freq_hz) & (f <= (top if max_freq_hz is None else min(max_freq_hz, top)))
    n_ind = max(2.0, band.sum() / cells_per_res)
    guard = 2 * cells_per_res
    out = []
    idx = np.flatnonzero(band)
    if idx.size < 3:
        return []
    if floor_window_hz is None:  # 50..500 resolution cells, about 1/20 of the band
        win = int(np.clip(n_ind / 20.0, 50, 500)) * cells_per_res
    else:
        win = int(round(floor_window_hz / df))
    win = max(5, win | 1)
    fb = f[idx]
    for k in range(amp.shape[1]):  # components (few)
        p = amp[idx, k] ** 2  # the floor only from the band: e.g. a smoother's residuals are ~0 below it
        floor = scipy.ndimage.median_filter(p, size=min(win, p.size), mode="reflect") / np.log(2.0)
        thr = floor * np.log(n_ind / false_alarm)
        local_max = scipy.ndimage.maximum_filter1d(p, size=2 * guard + 1, mode="nearest")
        hits = np.flatnonzero((p > thr) & (p >= local_max) & (thr > 0))
        out += [LinePeak(float(fb[i]), float(np.sqrt(p[i])), k, float(p[i] / thr[i])) for i in hits]
    return sorted(out, key=lambda peak: (peak.freq_hz, peak.component))


@dataclass(frozen=True)
class SinusoidFit:
    """x(t) ~ c + cos_coef cos(2 pi f (t - t0_s)) + sin_coef sin(2 pi f (t - t0_s)) per component.

    freq_hz; t0_s the phase origin; cos_coef, sin_coef, mean, amplitude = hypot(cos, sin) (K,).
    """

    freq_hz: float
    t0_s: float
    cos_coef: NDArray
    sin_coef: NDArray
    mean: NDArray
    amplitude: NDArray

    def evaluate(self, t_s: ArrayLike) -> NDArray:
        """The oscillating part (without the mean) at t_s (...): (..., K)."""
        arg = 2.0 * np.pi * self.freq_hz * (np.asarray(t_s, dtype=np.float64) - self.t0_s)
        return np.cos(arg)[..., None] * self.cos_coef + np.sin(arg)[..., None] * self.sin_coef

    def integral(self, t_s: ArrayLike) -> NDArray:
        """Zero-mean antiderivative of :meth:`evaluate` (e.g. rate line -> attitude oscillation)."""
        w = 2.0 * np.pi * self.freq_hz
        arg = w * (np.asarray(t_s, dtype=np.float64) - self.t0_s)
        return (np.sin(arg)[..., None] * self.cos_coef - np.cos(arg)[..., None] * self.sin_coef) / w


_LS_CHUNK = 1 << 20  # trial frequencies x samples per block of the direct least-squares spectrum


def _ls_terms(t: NDArray, v: NDArray, freq: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Floating-mean least-squares sinusoid at each trial frequency, all components at once.

    t (N,) [s], v (N, K), freq (F,) > 0 [Hz]. Returns (a, b, yc, ys), each (F, K): the fit
    c + a cos 2 pi f t + b sin 2 pi f t (the mean is absorbed by centring the columns) and the
    projections yc = C^T v, ys = S^T v of the centred data; a yc + b ys is the explained sum of
    squares. Zechmeister & Kürster (2009) generalised Lomb-Scargle, computed directly.
    """
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


def _ls_amplitudes(t: NDArray, v: NDArray, freq: NDArray) -> NDArray:
    """Sum over components of the explained sum of squares at each trial frequency (F,)."""
    a, b, yc, ys = _ls_terms(t, v, freq)
    return np.sum(a * yc + b * ys, axis=1)


def fit_sinusoid(
    t_s: ArrayLike, x: ArrayLike, freq_hz: float, *, refine: bool = True, search_halfwidth_hz: float | None = None
) -> SinusoidFit:
    """Least-squares sinusoid (common frequency, per-component amplitude and phase) plus mean.

    t_s (N,) [s], x (N,) or (N, K). With refine, the frequency maximising the explained sum of
    squares over all components is searched within +-search_halfwidth_hz (default one resolution
    cell 1/span) of freq_hz on a 9-point grid, again on a 9-point grid one step either side of the best,
    then by a parabola through the best three points.
    Phase origin t0_s = t_s[0].
    """
    t = np.asarray(t_s, dtype=np.float64)
    v = _values(x, t.size).reshape(t.size, -1)
    tc = t - t[0]
    f0 = float(freq_hz)
    if refine:  # two 9-point grids (+-half, then +-one step of the first), then a parabola
        half = search_halfwidth_hz if search_halfwidth_hz is not None else 1.0 / (tc[-1])
        for _ in range(2):
            grid = f0 + np.linspace(-half, half, 9)
            grid = grid[grid > 0]
            ess = _ls_amplitudes(tc, v, grid)
            i = int(np.argmax(ess))
            f0 = float(grid[i])
            half = float(grid[1] - grid[0])
        if 0 < i < grid.size - 1:
            y0, y1, y2 = ess[i - 1], ess[i], ess[i + 1]
            den = y0 - 2.0 * y1 + y2
            if den < 0:
                f0 += 0.5 * (y0 - y2) / den * float(grid[1] - grid[0])
    arg = 2.0 * np.pi * f0 * tc
    design = np.column_stack([np.ones_like(tc), np.cos(arg), np.sin(arg)])
    coef = np.linalg.lstsq(design, v, rcond=None)[0]
    return SinusoidFit(f0, float(t[0]), coef[1], coef[2], coef[0], np.hypot(coef[1], coef[2]))


@dataclass(frozen=True)
class FoundLine:
    """A line found by :func:`find_lines`: its least-squares fit (all components, common frequency),
    the components in which it was significant, and the largest A^2/threshold ratio."""

    fit: SinusoidFit
    components: tuple[int, ...]
    ratio: float


def find_lines(
    t_s: ArrayLike,
    x: ArrayLike,
    *,
    min_freq_hz: float = 0.0,
    false_alarm: float = 1e-3,
    max_lines: int = 10,
    oversample: int = 1,
) -> tuple[list[FoundLine], NDArray]:
    """Lines by prewhitening: spectrum (:func:`amplitude_spectrum_of_samples`), strongest significant
    peak (:func:`detect_lines`) over min_freq_hz, its sinusoid fitted (:func:`fit_sinusoid`, refined
    frequency common to the components) and subtracted from every component; repeated until nothing
    is significant or max_lines are found. A peak within 1.5 resolution cells of a line already
    found is the remainder of that line (gaps, frequency error), not a new one. Finally all lines
    are fitted jointly at their frequencies. t_s (N,) [s], x (N,) or (N, K).
    Returns (lines sorted by frequency, x with the lines removed, shape of x).
    """
    t = np.asarray(t_s, dtype=np.float64)
    v = _values(x, t.size)
    cols = v.reshape(t.size, -1)
    work = cols.copy()
    freqs: list[float] = []
    comps: list[set[int]] = []
    ratios: list[float] = []
    for _ in range(max_lines):
        spec = amplitude_spectrum_of_samples(t, work, oversample=oversample)
        peaks = detect_lines(spec, min_freq_hz=min_freq_hz, false_alarm=false_alarm)
        if not peaks:
            break
        best = max(peaks, key=lambda p: p.ratio)
        near = {p.component for p in peaks if abs(p.freq_hz - best.freq_hz) <= 2.0 * spec.resolution_hz}
        fit = fit_sinusoid(t, work, best.freq_hz)
        work = work - fit.evaluate(t)
        same = [i for i, f in enumerate(freqs) if abs(f - fit.freq_hz) <= 1.5 * spec.resolution_hz]
        if same:  # what a first fit of a line left (gaps, frequency error): the same line
            comps[same[0]] |= near
            continue
        freqs.append(fit.freq_hz)
        comps.append(near)
        ratios.append(best.ratio)
    if not freqs:
        return [], v.copy()
    # Final joint least-squares fit of all lines at their frequencies (plus the mean).
    tc = t - t[0]
    arg = 2.0 * np.pi * tc[:, None] * np.asarray(freqs)[None, :]
    design = np.column_stack([np.ones_like(tc), np.cos(arg), np.sin(arg)])
    coef = np.linalg.lstsq(design, cols, rcond=None)[0]
    n = len(freqs)
    found = [
        FoundLine(
            SinusoidFit(f, float(t[0]), coef[1 + i], coef[1 + n + i], coef[0], np.hypot(coef[1 + i], coef[1 + n + i])),
            tuple(sorted(comps[i])),
            ratios[i],
        )
        for i, f in enumerate(freqs)
    ]
    residual = cols - design[:, 1:] @ coef[1:]
    return sorted(found, key=lambda line: line.fit.freq_hz), residual.reshape(v.shape)
