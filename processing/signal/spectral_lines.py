"""Spectral lines of 003 §1.5: detection above a noise floor, sinusoid fits and prewhitening.

- :func:`detect_lines`: local maxima of A(f)^2 above a false-alarm threshold over a running-median
  noise floor (spectra of processing.signal.spectral);
- :func:`fit_sinusoid` refines the frequency and fits amplitude and phase by least squares;
  :func:`fit_sinusoids` fits several at fixed frequencies jointly (:func:`separable_frequencies` merges
  those a record cannot separate);
- :func:`find_lines` alternates detection and fit and subtracts each line found ("prewhitening"), so
  that the spectral-window sidelobes of a strong line are not taken for lines.

Times in seconds, frequencies in Hz, amplitudes in the unit of x. Pure numpy/scipy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.ndimage
from numpy.typing import ArrayLike, NDArray

from processing.signal.spectral import (
    Spectrum,
    amplitude_spectrum_of_samples,
    explained_sum_of_squares,
    sample_values,
)

__all__ = [
    "FoundLine",
    "LinePeak",
    "SinusoidFit",
    "detect_lines",
    "find_lines",
    "fit_sinusoid",
    "fit_sinusoids",
    "separable_frequencies",
]


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
    false_alarm; F_ind and the floor window count resolution cells of Spectrum.resolution_hz, not grid
    steps (a fast-length FFT grid is a little finer than 1/span). A line is a local maximum above that
    threshold, the largest within +-2 resolution cells, in min_freq_hz < f <= max_freq_hz and below the
    last resolution cell (Nyquist). The floor is taken inside that band only. Returned sorted by frequency.
    """
    f = spectrum.freq_hz
    amp = spectrum.amplitude.reshape(f.size, -1)
    df = float(f[1] - f[0]) if f.size > 1 else 1.0
    cells_per_res = max(1, int(round(spectrum.resolution_hz / df)))
    per_res = spectrum.resolution_hz / df  # grid steps per resolution cell: not an integer when padded
    if abs(per_res - cells_per_res) < 1e-6 * cells_per_res:  # (over)sampled 1/span grids: exactly an integer
        per_res = float(cells_per_res)
    top = f[-1] - spectrum.resolution_hz  # the Nyquist cell: amplitude undetermined (sin term vanishes)
    band = (f > min_freq_hz) & (f <= (top if max_freq_hz is None else min(max_freq_hz, top)))
    n_ind = max(2.0, band.sum() / max(1.0, per_res))
    guard = 2 * cells_per_res
    out = []
    idx = np.flatnonzero(band)
    if idx.size < 3:
        return []
    if floor_window_hz is None:  # 50..500 resolution cells, about 1/20 of the band
        win = int(round(int(np.clip(n_ind / 20.0, 50, 500)) * max(1.0, per_res)))
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
    v = sample_values(x, t.size).reshape(t.size, -1)
    tc = t - t[0]
    f0 = float(freq_hz)
    if refine:  # two 9-point grids (+-half, then +-one step of the first), then a parabola
        half = search_halfwidth_hz if search_halfwidth_hz is not None else 1.0 / (tc[-1])
        for _ in range(2):
            grid = f0 + np.linspace(-half, half, 9)
            grid = grid[grid > 0]
            ess = explained_sum_of_squares(tc, v, grid)
            i = int(np.argmax(ess))
            f0 = float(grid[i])
            half = float(grid[1] - grid[0])
        if 0 < i < grid.size - 1:
            y0, y1, y2 = ess[i - 1], ess[i], ess[i + 1]
            den = y0 - 2.0 * y1 + y2
            if den < 0:
                f0 += 0.5 * (y0 - y2) / den * float(grid[1] - grid[0])
    arg = 2.0 * np.pi * tc * f0  # the product order of fit_sinusoids: the same design as its fit of one line
    design = np.column_stack([np.ones_like(tc), np.cos(arg), np.sin(arg)])
    coef = np.linalg.lstsq(design, v, rcond=None)[0]
    return SinusoidFit(f0, float(t[0]), coef[1], coef[2], coef[0], np.hypot(coef[1], coef[2]))


def fit_sinusoids(t_s: ArrayLike, x: ArrayLike, freqs_hz: ArrayLike) -> list[SinusoidFit]:
    """Joint least-squares fit of sinusoids at fixed frequencies plus one mean, per component.

    t_s (N,) [s], x (N,) or (N, K), freqs_hz (L,) > 0. Frequencies closer than one resolution cell of
    the span are nearly collinear over it: merge them first (:func:`separable_frequencies`). Each
    returned fit carries the common mean; phase origin t_s[0]. Returns L fits in the order given.
    """
    t = np.asarray(t_s, dtype=np.float64)
    v = sample_values(x, t.size).reshape(t.size, -1)
    f = np.asarray(freqs_hz, dtype=np.float64).reshape(-1)
    tc = t - t[0]
    arg = 2.0 * np.pi * tc[:, None] * f[None, :]
    design = np.column_stack([np.ones_like(tc), np.cos(arg), np.sin(arg)])
    coef = np.linalg.lstsq(design, v, rcond=None)[0]
    n = f.size
    return [
        SinusoidFit(float(fi), float(t[0]), coef[1 + i], coef[1 + n + i], coef[0],
                    np.hypot(coef[1 + i], coef[1 + n + i]))
        for i, fi in enumerate(f)
    ]


def separable_frequencies(freqs_hz: ArrayLike, weights: ArrayLike, resolution_hz: float) -> NDArray:
    """Frequencies that a record of resolution 1/span can tell apart: from the largest weight down,
    each kept frequency absorbs those within one resolution cell of it. Returns the kept ones, sorted."""
    f = np.asarray(freqs_hz, dtype=np.float64).reshape(-1)
    order = np.argsort(-np.asarray(weights, dtype=np.float64).reshape(-1), kind="stable")
    kept: list[float] = []
    for i in order:  # lines (few)
        if all(abs(f[i] - k) >= resolution_hz for k in kept):
            kept.append(float(f[i]))
    return np.sort(np.asarray(kept))


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
    are fitted jointly at their frequencies (a single line: its first fit, which is that fit already).
    t_s (N,) [s], x (N,) or (N, K).
    Returns (lines sorted by frequency, x with the lines removed, shape of x).
    """
    t = np.asarray(t_s, dtype=np.float64)
    v = sample_values(x, t.size)
    cols = v.reshape(t.size, -1)
    work = cols.copy()
    freqs: list[float] = []
    comps: list[set[int]] = []
    ratios: list[float] = []
    first: SinusoidFit | None = None
    for _ in range(max_lines):
        spec = amplitude_spectrum_of_samples(t, work, oversample=oversample)
        peaks = detect_lines(spec, min_freq_hz=min_freq_hz, false_alarm=false_alarm)
        if not peaks:
            break
        best = max(peaks, key=lambda p: p.ratio)
        near = {p.component for p in peaks if abs(p.freq_hz - best.freq_hz) <= 2.0 * spec.resolution_hz}
        fit = fit_sinusoid(t, work, best.freq_hz)
        first = first or fit  # fitted to x itself (nothing subtracted yet)
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
    # final joint least-squares fit of all lines (plus the mean); of one line, the first fit is that fit
    fits = [first] if len(freqs) == 1 and first is not None else fit_sinusoids(t, cols, freqs)
    found = [FoundLine(fit, tuple(sorted(comps[i])), ratios[i]) for i, fit in enumerate(fits)]
    residual = cols - sum(fit.evaluate(t) for fit in fits)
    return sorted(found, key=lambda line: line.fit.freq_hz), residual.reshape(v.shape)
