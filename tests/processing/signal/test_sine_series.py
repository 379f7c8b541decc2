"""Tests of the 003 §1.3 sine-series smoother (processing.signal.sine_series).

Reference: the dense weighted least-squares solution computed independently here with
``numpy.linalg.lstsq`` (SVD, LAPACK gelsd) on the explicit design [1, tau, sin(pi m tau)].
"""

import numpy as np
import pytest

from processing.signal.sine_series import (
    SineSeriesError,
    SineSeriesSolver,
    fit_sine_series,
    harmonics_path,
    is_uniform,
    select_harmonics,
    sine_series_design,
)
from processing.signal.sine_series_fit import SineSeriesFit

N = 401
H_S = 3.0


def _uniform_data(k: int = 3, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = 17.0 + H_S * np.arange(N)
    slow = np.column_stack([np.sin(t / 150.0 + i) + 1e-4 * t * (i - 1) for i in range(k)])
    return t, 1e-2 * slow + 1e-5 * rng.standard_normal((N, k))


def _dense_reference(t, y, m, weights=None):
    a = sine_series_design(t, m, t[0], t[-1] - t[0])
    sw = np.ones_like(t) if weights is None else np.sqrt(weights)
    coef = np.linalg.lstsq(a * sw[:, None], y * (sw[:, None] if y.ndim == 2 else sw), rcond=None)[0]
    return coef, a @ coef


@pytest.mark.parametrize("m", [0, 1, 7, 60, 200, N - 3])
def test_dst_route_equals_general_route_and_dense_reference(m):
    t, y = _uniform_data()
    dst = fit_sine_series(t, y, m, method="dst")
    gen = fit_sine_series(t, y, m, method="lstsq")
    coef, fitted = _dense_reference(t, y, m)
    scale = np.max(np.abs(y))
    assert dst.method == "dst" and gen.method == "lstsq"
    np.testing.assert_allclose(dst.fitted, gen.fitted, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(dst.fitted, fitted, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(gen.fitted, fitted, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(dst.sine, coef[2:], rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(dst.const, coef[0] - 0.0, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(dst.slope * dst.span_s, coef[1], rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(dst.rss, gen.rss, rtol=1e-8, atol=1e-20)


def test_weighted_general_route_equals_dense_weighted_reference_with_gaps():
    t, y = _uniform_data()
    keep = np.ones(N, dtype=bool)
    keep[[5, 6, 7, 100, 101, 250]] = False
    w = np.linspace(0.5, 2.0, keep.sum())
    fit = fit_sine_series(t[keep], y[keep], 40, weights=w)
    _, fitted = _dense_reference(t[keep], y[keep], 40, w)
    assert fit.method == "lstsq"
    np.testing.assert_allclose(fit.fitted, fitted, rtol=0, atol=1e-10 * np.max(np.abs(y)))
    resid = y[keep] - fitted
    np.testing.assert_allclose(fit.rss, np.sum(w[:, None] * resid**2, axis=0), rtol=1e-9)


def test_equal_weights_keep_the_dst_route_and_the_solution():
    t, y = _uniform_data()
    a = fit_sine_series(t, y, 30)
    b = fit_sine_series(t, y, 30, weights=np.full(N, 4.0))
    assert a.method == b.method == "dst"
    np.testing.assert_allclose(a.fitted, b.fitted, atol=1e-14)


def test_exact_series_is_recovered_and_evaluated_with_its_derivative():
    t = np.linspace(-5.0, 295.0, 301)
    span = t[-1] - t[0]
    sine = np.zeros(12)
    sine[[0, 3, 11]] = [0.3, -0.2, 0.05]

    def f(tt):
        tau = (tt - t[0]) / span
        return 1.5 - 0.01 * (tt - t[0]) + np.sin(np.pi * np.outer(tau, np.arange(1, 13))) @ sine

    def df(tt):
        tau = (tt - t[0]) / span
        m = np.arange(1, 13)
        return -0.01 + np.cos(np.pi * np.outer(tau, m)) @ (sine * np.pi * m / span)

    fit = fit_sine_series(t, f(t), 12)
    np.testing.assert_allclose(fit.sine, sine, atol=1e-13)
    np.testing.assert_allclose(fit.const, 1.5, atol=1e-13)
    np.testing.assert_allclose(fit.slope, -0.01, atol=1e-15)
    tt = np.linspace(t[0], t[-1], 1001)
    assert fit.evaluate(tt).shape == (1001,)
    np.testing.assert_allclose(fit.evaluate(tt), f(tt), atol=1e-13)
    np.testing.assert_allclose(fit.derivative(tt), df(tt), atol=1e-15)
    np.testing.assert_allclose(fit.evaluate(t), fit.fitted, atol=1e-14)
    assert fit.const.shape == fit.slope.shape == fit.rss.shape == () and fit.fitted.shape == (301,)
    assert fit.evaluate(np.float64(t[3])).shape == ()
    assert fit.cutoff_hz == pytest.approx(12 / (2 * span))


def test_vector_and_matrix_inputs_agree_and_keep_their_shapes():
    t, y = _uniform_data(k=2)
    both = fit_sine_series(t, y, 25)
    one = fit_sine_series(t, y[:, 1], 25)
    assert both.evaluate(t).shape == (N, 2) and one.evaluate(t).shape == (N,)
    assert one.sigma.shape == () and both.sigma.shape == (2,)
    np.testing.assert_allclose(one.evaluate(t), both.evaluate(t)[:, 1], atol=1e-15)
    np.testing.assert_allclose(one.residuals(y[:, 1]), y[:, 1] - one.fitted)
    np.testing.assert_allclose(one.sine, both.sine[:, 1], atol=1e-15)
    assert one.dof == N - 27


@pytest.mark.parametrize("method", ["dst", "lstsq"])
def test_harmonics_path_matches_individual_fits(method):
    t, y = _uniform_data()
    path = harmonics_path(t, y, 120, method=method)
    assert path.method == method
    assert path.harmonics.tolist() == list(range(121))
    for m in (0, 1, 33, 120):
        np.testing.assert_allclose(path.rss[m], fit_sine_series(t, y, m).rss, rtol=1e-7)
    assert np.all(np.diff(path.rss, axis=0) <= 1e-20)  # nested models: RSS never increases


@pytest.mark.parametrize("gaps", [False, True])
def test_prepared_solver_reuses_one_factorisation(gaps):
    t, y = _uniform_data()
    keep = np.ones(N, dtype=bool)
    if gaps:
        keep[[30, 31, 200]] = False
    solver = SineSeriesSolver(t[keep], 90)
    assert solver.route == ("lstsq" if gaps else "dst")
    for m in (0, 12, 90):
        one = fit_sine_series(t[keep], y[keep], m)
        np.testing.assert_allclose(solver.fit(y[keep], m).fitted, one.fitted, rtol=0, atol=1e-12)
        a = sine_series_design(t[keep], m, t[keep][0], t[keep][-1] - t[keep][0])
        np.testing.assert_allclose(solver.covariance_diag(m), np.diag(np.linalg.inv(a.T @ a)), rtol=1e-9)
        fit = solver.fit(y[keep], m)
        np.testing.assert_allclose(solver.derivative_at_samples(fit), fit.derivative(t[keep]), rtol=0,
                                   atol=1e-12 * np.max(np.abs(fit.derivative(t[keep]))))
    with pytest.raises(SineSeriesError, match="not made by this solver"):
        solver.derivative_at_samples(fit_sine_series(t[:50], y[:50], 3))
    with pytest.raises(SineSeriesError, match=r"prepared up to 90\) must be in \[0, 90\], got 91"):
        solver.fit(y[keep], 91)
    with pytest.raises(SineSeriesError, match="y must have shape"):
        solver.fit(y, 3) if gaps else solver.fit(y[:-1], 3)


def test_weighted_path_and_covariance():
    t, y = _uniform_data()
    w = np.linspace(1.0, 3.0, N)
    solver = SineSeriesSolver(t, 50, weights=w)
    a = sine_series_design(t, 20, t[0], t[-1] - t[0])
    np.testing.assert_allclose(solver.covariance_diag(20), np.diag(np.linalg.inv(a.T @ (w[:, None] * a))), rtol=1e-9)
    np.testing.assert_allclose(solver.path(y).rss[20], solver.fit(y, 20).rss, rtol=1e-9)
    equal = SineSeriesSolver(t, 50, weights=np.full(N, 2.0))
    assert equal.route == "dst"
    np.testing.assert_allclose(equal.path(y).rss[20], 2.0 * fit_sine_series(t, y, 20).rss, rtol=1e-7)


def test_gcv_selects_the_band_of_the_signal():
    rng = np.random.default_rng(3)
    t = np.arange(600) * 2.0
    tau = (t - t[0]) / (t[-1] - t[0])
    coef = np.zeros(80)
    coef[:15] = rng.uniform(0.5, 1.0, 15)
    y = 0.3 + 0.1 * tau + np.sin(np.pi * np.outer(tau, np.arange(1, 81))) @ coef + 0.01 * rng.standard_normal(600)
    m, path = select_harmonics(t, y, 150)
    assert 15 <= m <= 20
    assert path.score("aic").shape == path.score("bic").shape == (151,)


def test_rank_deficient_design_is_refused_and_the_path_stops_before_it():
    t = np.concatenate([np.arange(0.0, 30.0, 3.0), np.arange(1170.0, 1201.0, 3.0)])  # a 20-min hole
    y = np.sin(t / 100.0)
    with pytest.raises(SineSeriesError, match="rank-deficient"):
        fit_sine_series(t, y, t.size - 2)
    path = harmonics_path(t, y, t.size - 2)
    assert path.harmonics[-1] < t.size - 2


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"t_s": np.arange(5.0), "y": np.ones(4), "harmonics": 1}, r"y must have shape \(5,\)"),
        ({"t_s": np.array([0.0, 2.0, 1.0, 3.0]), "y": np.ones(4), "harmonics": 1}, "strictly increasing"),
        ({"t_s": np.arange(5.0), "y": np.ones(5), "harmonics": 4}, r"N - 2 = 3\) must be in \[0, 3\], got 4"),
        ({"t_s": np.arange(5.0), "y": np.ones(5), "harmonics": 1.5}, "integer"),
        ({"t_s": np.arange(2.0), "y": np.ones(2), "harmonics": 0}, "at least 3 samples"),
        ({"t_s": np.array([0.0, 1.0, 3.0, 4.0]), "y": np.ones(4), "harmonics": 1, "method": "dst"}, "uniform"),
        ({"t_s": np.arange(5.0), "y": np.ones(5), "harmonics": 1, "weights": -np.ones(5)}, ">= 0"),
        ({"t_s": np.arange(5.0), "y": np.ones(5), "harmonics": 1, "method": "fft"}, "method must be"),
        ({"t_s": np.arange(5.0), "y": np.array([1, 2, np.nan, 4, 5.0]), "harmonics": 1}, "finite"),
    ],
)
def test_bad_inputs_say_what_was_expected(kwargs, match):
    with pytest.raises(SineSeriesError, match=match):
        fit_sine_series(**kwargs)


def test_is_uniform_tolerates_nanosecond_rounding_only():
    t = (np.round((0.037 + 3.0 * np.arange(400)) * 1e9) / 1e9).astype(float)
    assert is_uniform(t)
    t_jitter = t.copy()
    t_jitter[10] += 1e-6
    assert not is_uniform(t_jitter)
    assert not is_uniform(np.delete(t, 50))


def test_gram_route_matches_the_dense_gram_and_falls_back_to_qr() -> None:
    """The general route's Gram matrix (NUFFT sums, Toeplitz minus Hankel) equals A^T W A of the dense design,
    its Cholesky factor gives QR's R, and an ill-conditioned design takes the Householder QR route."""
    import scipy.linalg

    from processing.signal import sine_series as ss
    from processing.signal import sine_series_basis as basis

    rng = np.random.default_rng(5)
    tau = np.sort(rng.uniform(0.0, 1.0, 900))
    w = rng.uniform(0.5, 2.0, tau.size)
    a = ss.sine_series_design(tau, 120, 0.0, 1.0)
    dense = (a * w[:, None]).T @ a
    np.testing.assert_allclose(basis.gram_nufft(tau, w, 120), dense, rtol=0, atol=1e-11 * np.abs(dense).max())
    q, r = basis.gram_factor(a * np.sqrt(w)[:, None], tau, w)
    r_qr = scipy.linalg.qr(a * np.sqrt(w)[:, None], mode="r")[0][:122]
    assert q is None and np.allclose(np.abs(r), np.abs(r_qr), atol=1e-9 * np.abs(r_qr).max())
    gap = np.concatenate([tau[tau < 0.3], tau[tau > 0.7]])  # a wide gap: high harmonics barely determined
    q_gap, _ = basis.gram_factor(ss.sine_series_design(gap, 200, 0.0, 1.0), gap, None)
    assert q_gap is not None
    y = np.sin(7 * tau) + rng.normal(0, 0.01, tau.size)
    solver = ss.SineSeriesSolver(tau, 120, weights=w)
    a = ss.sine_series_design(solver.tau, 120, 0.0, 1.0)  # the solver's tau runs from its first to last sample
    ref = np.linalg.lstsq(a * np.sqrt(w)[:, None], y * np.sqrt(w), rcond=None)[0]
    np.testing.assert_allclose(solver.fit(y, 120).fitted, a @ ref, atol=1e-10)


def test_sine_design_recurrence_matches_numpy() -> None:
    from processing.signal.sine_series import sine_series_design

    tau = np.concatenate([[0.0, 1e-9], np.sort(np.random.default_rng(1).uniform(0, 1, 500)), [1 - 1e-9, 1.0]])
    for m in (0, 1, 2, 3, 64, 65, 66, 400):
        ref = np.column_stack([np.ones_like(tau), tau, np.sin(np.pi * tau[:, None] * np.arange(1, m + 1))])
        np.testing.assert_allclose(sine_series_design(tau, m, 0.0, 1.0), ref, rtol=0, atol=1e-11)


def test_evaluation_across_reseeds_and_sample_blocks_is_the_explicit_sum():
    # 70 harmonics (re-seeded at 32 and 64) at 40,000 times (three blocks of samples), 3 components;
    # evaluate_with_derivative (one recurrence pass, used by the gyro comparison) is evaluate + derivative.
    rng = np.random.default_rng(11)
    n_h, t1, span = 70, -3.0, 1200.0
    sine = rng.standard_normal((n_h, 3)) / np.arange(1, n_h + 1)[:, None]
    fit = SineSeriesFit(t1, span, n_h, np.array([0.1, -0.2, 0.3]), np.array([1e-3, 0.0, -2e-3]), sine,
                        np.zeros((5, 3)), np.zeros(3), 5, 0, "dst", False)
    tt = rng.uniform(t1, t1 + span, (200, 200))
    tau = (tt.reshape(-1) - t1) / span
    m = np.arange(1, n_h + 1)
    ref = fit.const + np.outer(tt.reshape(-1) - t1, fit.slope) + np.sin(np.pi * np.outer(tau, m)) @ sine
    ref_d = fit.slope + np.cos(np.pi * np.outer(tau, m)) @ (sine * (np.pi * m / span)[:, None])
    val, der = fit.evaluate_with_derivative(tt)
    assert val.shape == der.shape == (200, 200, 3)
    np.testing.assert_allclose(val.reshape(-1, 3), ref, rtol=0, atol=1e-13)
    np.testing.assert_allclose(der.reshape(-1, 3), ref_d, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(val, fit.evaluate(tt))
    np.testing.assert_array_equal(der, fit.derivative(tt))
    assert fit.evaluate(t1).shape == (3,) and fit.derivative(np.zeros(0)).shape == (0, 3)


@pytest.mark.parametrize("n", [11_931, 8_195])  # N - 1 = 2 x 5 x 1193, 2 x 17 x 241: awkward lengths
def test_chirp_route_of_long_awkward_series_equals_the_dst_and_the_general_route(n):
    """Long series whose 2 (N - 1) is no fast FFT length take the chirp-z sums (CHIRP_MIN_SAMPLES): the same
    coefficients and synthesis as the DST-I to rounding, and the same fit as the general QR route."""
    import scipy.fft

    from processing.signal.sine_series_basis import _use_chirp, dst_coefficients, dst_synthesis

    assert _use_chirp(n, 70)
    rng = np.random.default_rng(3)
    x = rng.standard_normal((n, 3)) + 2.0
    ref = scipy.fft.dst(x[1:-1], type=1, axis=0)[:70] / (n - 1)
    np.testing.assert_allclose(dst_coefficients(x, 70), ref, rtol=0, atol=1e-14 * np.abs(ref).max())
    c = rng.standard_normal((70, 2))
    full = np.zeros((n - 2, 2))
    full[:70] = c
    syn = 0.5 * scipy.fft.dst(full, type=1, axis=0)
    got = dst_synthesis(c, n)
    assert np.all(got[[0, -1]] == 0.0)
    np.testing.assert_allclose(got[1:-1], syn, rtol=0, atol=1e-13 * np.abs(syn).max())
    t = 0.1 * np.arange(n)
    y = np.column_stack([np.sin(t / 40.0), 1e-3 * t]) + 1e-3 * rng.standard_normal((n, 2))
    dst, lsq = fit_sine_series(t, y, 70, method="dst"), fit_sine_series(t, y, 70, method="lstsq")
    assert dst.method == "dst"
    np.testing.assert_allclose(dst.fitted, lsq.fitted, rtol=0, atol=1e-12)
    np.testing.assert_allclose(dst.sine, lsq.sine, rtol=0, atol=1e-12)
