"""Tests of the 003 §1.5 spectra, line detection and aliasing (processing.signal.spectral).

Authority: the periodogram written out as in 003 §1.5, I(f) = [sum (x_n - x̄) cos(pi n f/F)]^2 +
[sum (x_n - x̄) sin(pi n f/F)]^2 with F = 1/(2h), evaluated by explicit sums here.
"""

import numpy as np
import pytest
import scipy.signal

from processing.signal import spectral
from processing.signal.spectral import (
    SpectralError,
    alias_frequency,
    amplitude_spectrum,
    amplitude_spectrum_gapped,
    amplitude_spectrum_of_samples,
    amplitude_spectrum_uneven,
)
from processing.signal.spectral_lines import detect_lines, find_lines, fit_sinusoid


def _paper_periodogram(x: np.ndarray, h: float, f: np.ndarray, n_index: np.ndarray | None = None) -> np.ndarray:
    """003 §1.5 I(f) by explicit sums (n = 1..N, or the given grid indices of present samples)."""
    n = np.arange(1, x.size + 1) if n_index is None else n_index
    big_f = 1.0 / (2.0 * h)
    xc = x - x.mean()
    arg = np.pi * np.outer(f, n) / big_f
    return (np.cos(arg) @ xc) ** 2 + (np.sin(arg) @ xc) ** 2


def test_fft_spectrum_is_the_papers_periodogram():
    rng = np.random.default_rng(0)
    h = 0.1
    x = rng.standard_normal(1000) + 0.3
    spec = amplitude_spectrum(x, h, oversample=3)
    pick = np.array([0, 1, 7, 300, 1499])
    scale = np.sum((x - x.mean()) ** 2)  # I(f) at f = 0 is rounding only
    np.testing.assert_allclose(spec.periodogram[pick], _paper_periodogram(x, h, spec.freq_hz[pick]), rtol=1e-10,
                               atol=1e-12 * scale)
    assert spec.freq_hz[-1] == pytest.approx(1.0 / (2 * h))
    assert spec.resolution_hz == pytest.approx(1.0 / (1000 * h))


def test_amplitude_of_a_harmonic_trend():
    h = 0.1
    t = h * np.arange(2000)
    x = 2.0 + 5.19 * np.cos(2 * np.pi * 0.4 * t + 0.7)  # 003 §1.5: 5.19"/s at 0.4 Hz on w1
    spec = amplitude_spectrum(x, h)
    k = int(np.argmax(spec.amplitude))
    assert spec.freq_hz[k] == pytest.approx(0.4)
    assert spec.amplitude[k] == pytest.approx(5.19, rel=1e-12)


def test_lomb_scargle_amplitude_equals_fft_amplitude_at_fourier_frequencies():
    rng = np.random.default_rng(1)
    h = 3.0
    x = rng.standard_normal((400, 2))
    t = h * np.arange(400)
    fft = amplitude_spectrum(x, h)
    ls = amplitude_spectrum_uneven(t, x, fft.freq_hz[1:-1])
    np.testing.assert_allclose(ls.amplitude, fft.amplitude[1:-1], rtol=1e-9)
    assert ls.method == "lomb_scargle"


def test_uneven_spectrum_is_scipys_floating_mean_lomb_scargle_amplitude():
    rng = np.random.default_rng(4)
    t = np.sort(rng.uniform(0.0, 1200.0, 350))
    x = rng.standard_normal((350, 2)) + np.column_stack([np.sin(0.3 * t), np.zeros(350)])
    spec = amplitude_spectrum_uneven(t, x)
    for k in range(2):
        ref = scipy.signal.lombscargle(t - t[0], x[:, k] - x[:, k].mean(), 2 * np.pi * spec.freq_hz,
                                       normalize="amplitude", floating_mean=True)
        np.testing.assert_allclose(spec.amplitude[:, k], np.abs(ref), rtol=1e-8, atol=1e-12)
    assert spec.freq_hz[0] == pytest.approx(1 / (t[-1] - t[0]))


def test_lomb_scargle_amplitude_is_exact_with_gaps_and_the_gapped_fft_is_the_papers_sum():
    h = 3.0
    idx = np.delete(np.arange(400), np.r_[40:52, 200:205])
    t = h * idx
    x = 1.0 + 3.0 * np.sin(2 * np.pi * (1 / 15.0) * t + 0.2)
    ls = amplitude_spectrum_uneven(t, x, np.array([1 / 15.0]))
    assert ls.amplitude[0] == pytest.approx(3.0, rel=1e-10)
    gapped = amplitude_spectrum_gapped(t, x, h)
    pick = np.array([3, 80, 133])
    np.testing.assert_allclose(gapped.periodogram[pick], _paper_periodogram(x, h, gapped.freq_hz[pick], idx + 1),
                               rtol=1e-10)


def test_spectrum_of_samples_chooses_the_route():
    t = 3.0 * np.arange(300)
    x = np.sin(t / 7.0)
    assert amplitude_spectrum_of_samples(t, x).method == "fft"
    assert amplitude_spectrum_of_samples(np.delete(t, [10, 11]), np.delete(x, [10, 11])).method == "lomb_scargle"
    t_long = np.arange(200_000, dtype=float)
    keep = np.ones(t_long.size, dtype=bool)
    keep[1000:1100] = False
    assert amplitude_spectrum_of_samples(t_long[keep], np.sin(t_long[keep])).method == "fft_gapped"


@pytest.mark.parametrize(
    ("f_hz", "h_s", "expected"),
    [(0.4, 3.0, 1 / 15.0), (0.1, 3.0, 0.1), (1 / 3, 3.0, 0.0), (0.4, 0.1, 0.4), (2.7, 1.0, 0.3)],
)
def test_alias_frequency(f_hz, h_s, expected):
    # 003 §2.4: the 0.4 Hz mirror line at 3 s sampling appears with period 15 s.
    assert alias_frequency(f_hz, h_s) == pytest.approx(expected, abs=1e-15)


def test_detector_is_quiet_on_white_noise_and_finds_a_line():
    rng = np.random.default_rng(5)
    t = 0.1 * np.arange(12000)
    noise = 1.5 * rng.standard_normal((12000, 3))
    assert detect_lines(amplitude_spectrum(noise, 0.1)) == []
    x = noise + np.array([0.5, 0.0, 0.0]) * np.cos(2 * np.pi * 1.3 * t)[:, None]
    lines = detect_lines(amplitude_spectrum(x, 0.1))
    assert [(round(p.freq_hz, 4), p.component) for p in lines] == [(1.3, 0)]
    assert lines[0].ratio > 1.0
    assert detect_lines(amplitude_spectrum(x, 0.1), min_freq_hz=1.5) == []


def test_fit_sinusoid_refines_the_frequency():
    t = 0.1 * np.arange(12000) + 5.0
    x = np.column_stack([7.5 * np.cos(2 * np.pi * 0.40003 * (t - 5.0) + 1.0), np.full(t.size, 2.0)])
    fit = fit_sinusoid(t, x, 0.4)
    assert fit.freq_hz == pytest.approx(0.40003, abs=1e-7)
    np.testing.assert_allclose(fit.amplitude, [7.5, 0.0], atol=1e-4)
    np.testing.assert_allclose(fit.mean, [0.0, 2.0], atol=1e-4)
    np.testing.assert_allclose(fit.evaluate(t)[:, 0], x[:, 0], atol=1e-3)
    # integral: its derivative is the oscillation, and it has no mean
    dt = 1e-4
    deriv = (fit.integral(t + dt) - fit.integral(t - dt)) / (2 * dt)
    np.testing.assert_allclose(deriv, fit.evaluate(t), atol=1e-5)


def test_find_lines_prewhitens_sidelobes_of_a_strong_line():
    rng = np.random.default_rng(2)
    t = 0.1 * np.arange(12000)
    lines_true = 7.5 * np.sin(2 * np.pi * 0.4 * t + 0.3) + 0.3 * np.cos(2 * np.pi * 1.7 * t)
    x = lines_true[:, None] + 0.5 * rng.standard_normal((12000, 1))
    lines, residual = find_lines(t, x, min_freq_hz=0.01)
    assert [round(line.fit.freq_hz, 3) for line in lines] == [0.4, 1.7]
    np.testing.assert_allclose([line.fit.amplitude[0] for line in lines], [7.5, 0.3], rtol=0.05)
    assert lines[0].components == (0,)
    assert np.std(residual) == pytest.approx(0.5, rel=0.03)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: amplitude_spectrum(np.ones(10), 0.0), "sample_period_s must be > 0"),
        (lambda: amplitude_spectrum(np.ones((2, 2, 2)), 1.0), r"\(N,\) or \(N, K\)"),
        (lambda: amplitude_spectrum_uneven(np.arange(5.0), np.ones(4)), "5 rows to match t_s, got 4"),
        (lambda: amplitude_spectrum_gapped(np.array([0.0, 1.5, 3.0]), np.ones(3), 1.0), "not on a grid"),
        (lambda: amplitude_spectrum(np.array([1.0, np.inf, 2.0]), 1.0), "finite"),
    ],
)
def test_bad_inputs(call, match):
    with pytest.raises(SpectralError, match=match):
        call()


@pytest.mark.parametrize("hours", [24, 72])
def test_long_10hz_records_take_the_fft_route(hours):
    # Issue 24: at 24 h of 10 Hz the float median step is 0.09999999999854481 s; taking it as the grid
    # step put far nodes 1.26e-5 steps off, and the spectrum fell back to an O(N x F) Lomb-Scargle that
    # never finished. Times come as the jobs make them: int64 TAI ns -> seconds since the first sample.
    n = hours * 36_000
    t_ns = 1_259_661_600_000_000_000 + np.arange(n, dtype=np.int64) * 100_000_000
    keep = np.ones(n, dtype=bool)
    keep[5_000:5_100] = False  # one gap: the zero-filled grid route
    t = (t_ns[keep] - t_ns[keep][0]).astype(np.float64) / 1e9
    assert np.median(np.diff(t)) != 0.1  # the float step really is off
    x = np.sin(2 * np.pi * 0.4 * t)
    spec = amplitude_spectrum_of_samples(t, x)
    assert spec.method == "fft_gapped"
    assert spec.freq_hz[-1] == pytest.approx(5.0, rel=1e-12)
    k = int(np.argmax(spec.amplitude))
    assert spec.freq_hz[k] == pytest.approx(0.4, abs=spec.resolution_hz)
    full = (t_ns - t_ns[0]).astype(np.float64) / 1e9
    assert amplitude_spectrum_of_samples(full, np.sin(full)).method == "fft"


def test_off_grid_samples_use_the_nufft_above_the_work_limit_and_agree_with_scipy(monkeypatch):
    # Genuinely off-grid (jittered) times: above LOMB_SCARGLE_MAX_WORK the uniform frequency grid is
    # summed by NUFFT; the estimator is unchanged (scipy's floating-mean Lomb-Scargle is the reference).
    rng = np.random.default_rng(11)
    t = np.arange(3000) * 0.5 + rng.uniform(-0.05, 0.05, 3000)
    x = rng.standard_normal((3000, 2)) + np.column_stack([0.8 * np.sin(2 * np.pi * 0.31 * t), np.zeros(3000)])
    direct = amplitude_spectrum_uneven(t, x)
    monkeypatch.setattr(spectral, "LOMB_SCARGLE_MAX_WORK", 1000)
    fast = amplitude_spectrum_uneven(t, x)
    assert fast.freq_hz.size * t.size > 1000
    np.testing.assert_allclose(fast.amplitude, direct.amplitude, rtol=1e-7, atol=1e-10)
    ref = scipy.signal.lombscargle(t - t[0], x[:, 0] - x[:, 0].mean(), 2 * np.pi * fast.freq_hz,
                                   normalize="amplitude", floating_mean=True)
    np.testing.assert_allclose(fast.amplitude[:, 0], np.abs(ref), rtol=1e-7, atol=1e-10)
    # non-uniform trial frequencies above the limit are refused, not summed for hours
    with pytest.raises(SpectralError, match="non-uniform"):
        amplitude_spectrum_uneven(t, x, np.sort(rng.uniform(0.01, 0.9, 500)))


def test_every_route_has_a_work_guard(monkeypatch):
    monkeypatch.setattr(spectral, "MAX_FREQUENCIES", 1000)
    t = 0.1 * np.arange(5000.0)
    with pytest.raises(SpectralError, match="frequencies"):
        amplitude_spectrum_of_samples(np.delete(t, [7]), np.ones(4999))
    with pytest.raises(SpectralError, match="frequencies"):
        amplitude_spectrum_of_samples(t + np.r_[0.0, np.full(4999, 0.01)], np.ones(5000))
    # a few samples over a long span do not allocate a mostly empty grid: the NUFFT route takes them
    monkeypatch.setattr(spectral, "MAX_FREQUENCIES", 1 << 25)
    sparse = np.r_[0.1 * np.arange(50), 1.0e5 + 0.1 * np.arange(50)]
    assert amplitude_spectrum_of_samples(sparse, np.sin(sparse)).method == "lomb_scargle"


@pytest.mark.parametrize("gapped", [False, True])
def test_lengths_with_a_large_prime_factor_are_padded_to_a_fast_length_and_stay_the_papers_sum(gapped):
    # Issue 24: 24 h of 10 Hz with both ends is 864,001 = 31 x 47 x 593 nodes, which pocketfft transforms
    # by Bluestein (~9x slower). Padded to an even fast length M the grid is k / (M h), a little finer than
    # 1/(N h), ends at Nyquist, and A(f) there is still the 003 §1.5 sum. Here N = 1201 (prime): M = 1250.
    rng = np.random.default_rng(8)
    h = 0.1
    idx = np.delete(np.arange(1201), np.r_[100:130]) if gapped else np.arange(1201)
    x = rng.standard_normal(idx.size) + 0.2 * np.cos(2 * np.pi * 1.7 * h * idx)
    spec = amplitude_spectrum_gapped(h * idx, x, h) if gapped else amplitude_spectrum(x, h)
    assert spectral.fft_length(1201) == 1250
    np.testing.assert_allclose(spec.freq_hz, np.arange(626) / (1250 * h), rtol=1e-12)
    assert spec.freq_hz[-1] == pytest.approx(1.0 / (2 * h), rel=1e-12)
    assert spec.resolution_hz == pytest.approx(1.0 / (1201 * h), rel=1e-12)  # independent cells: unchanged
    pick = np.array([1, 17, 255, 510, 625])
    np.testing.assert_allclose(spec.periodogram[pick], _paper_periodogram(x, h, spec.freq_hz[pick], idx + 1),
                               rtol=1e-10)
    # a fast length is left as it is: the grid of 1200 samples is k / (1200 h), as before
    assert spectral.fft_length(1200) == 1200
    assert amplitude_spectrum(x[:1200], h).freq_hz.size == 601


def test_detector_counts_resolution_cells_not_grid_steps_on_a_padded_grid():
    # A flat spectrum (A = 1) with one spike a: the threshold is ln(F_ind / false_alarm) / ln 2, with F_ind
    # the number of resolution cells in the band - here 1.25 grid steps each, as after padding.
    res, per_res, n = 1e-3, 1.25, 20_001
    f = np.arange(n) * (res / per_res)
    amp = np.ones(n)
    amp[8000] = 12.0
    spec = spectral.Spectrum(f, amp, 2 * n, "fft", res)
    (peak,) = detect_lines(spec, false_alarm=1e-3)
    n_band = int(np.sum((f > 0) & (f <= f[-1] - res)))
    assert peak.freq_hz == f[8000]
    assert peak.ratio == pytest.approx(144.0 * np.log(2.0) / np.log(n_band / per_res / 1e-3), rel=1e-12)


def test_small_uniform_refinement_grids_by_angle_addition_equal_the_direct_sums():
    """explained_sum_of_squares on a 9-point uniform grid (angle addition from the first frequency) equals the
    direct least-squares sums of _ls_terms to rounding, and picks the same maximum."""
    rng = np.random.default_rng(7)
    t = 0.1 * np.arange(40_000)
    v = rng.standard_normal((t.size, 3)) + 0.05 * np.sin(2 * np.pi * 0.4 * t + 0.3)[:, None]
    grid = 0.4 + np.linspace(-1.0 / t[-1], 1.0 / t[-1], 9)
    a, b, yc, ys = spectral._ls_terms(t, v, grid)
    direct = np.sum(a * yc + b * ys, axis=1)
    ess = spectral.explained_sum_of_squares(t, v, grid)
    np.testing.assert_allclose(ess, direct, rtol=1e-10)
    assert int(np.argmax(ess)) == int(np.argmax(direct))


def test_a_single_line_is_reported_with_its_joint_fit():
    """find_lines' one line is its first fit, which equals the joint fit at its frequency bit for bit."""
    from processing.signal.spectral_lines import fit_sinusoids

    rng = np.random.default_rng(8)
    t = 3.0 + 0.1 * np.arange(30_000)
    x = 0.01 * rng.standard_normal((t.size, 2)) + np.outer(np.sin(2 * np.pi * 0.37 * t), [1.0, 0.5])
    (line,), _ = find_lines(t, x, min_freq_hz=0.01)
    joint = fit_sinusoids(t, x, [line.fit.freq_hz])[0]
    for name in ("freq_hz", "t0_s", "cos_coef", "sin_coef", "mean", "amplitude"):
        assert np.array_equal(getattr(line.fit, name), getattr(joint, name)), name
