"""Attitude-independent magnetometer calibration from |B| matching (TWOSTEP of Alonso & Shuster 2002).

Model (processing.magnetometer.model): B_meas = (I + D) B_true + b + C mu_B + n, D symmetric. The
attitude is unknown, but |B_true| is known from the field model (IGRF-14 along the GNSS orbit), so each
sample gives one scalar equation

    r_k(p) = |(I + D)^-1 (B_meas_k - b - C mu_k)| - |B_ref_k| = e_k,

with p = (b (3), D_xx D_yy D_zz, D_xy D_xz D_yz [, C (9, row-major: row = magnetometer axis, column =
dipole axis)]): 9 parameters, 18 with the coupling. A rotation of the sensor leaves |B| unchanged, so
only the symmetric part of I + D is estimable (the antisymmetric part belongs to the mounting q_BM).

Steps:

1. Linear (centred) first step, as TWOSTEP's: (H - b)^T A (H - b) = |B_ref|^2 is linear in
   (A (6), A b (3), b^T A b (1)); A = (I + D)^-2 gives D = A^(-1/2) - I and b. Used only as the start
   (it weights the samples by |B|^2 and ignores the constraint between its 10 unknowns); when A is not
   positive definite (a degenerate arc) the start is p = 0.
2. Gauss-Newton on r_k with the analytic Jacobian (below), a weak Gaussian prior on p (sigma 1e4 nT,
   0.1, 100 nT/(A m^2); it only keeps the undeterminable directions bounded: its weight in a
   determined parameter is (sigma/prior)^2 < 1e-3), step halving when the cost rises.
3. Outliers: samples with |r| > ``outlier_sigma`` x the MAD-based sigma are dropped and the fit repeated once.

Noise model of the |B| residual: e_k = u_k^T (I + D)^-1 n_k + (field-model error) + O(|n|^2/|B|),
u_k the unit corrected field; for isotropic white sensor noise sigma_n this is white with variance
sigma_n^2 |(I + D)^-1 u_k|^2 ~= sigma_n^2 (the second-order term is a bias of sigma_n^2/|B|, 0.25 nT
for 100 nT at 40 000 nT, neglected). The field-model error (crustal and external fields; IGRF's own
error) adds a slowly varying term along the orbit. Hence:

- covariance = s^2 (J^T J + s^2 P^-1)^-1 with s^2 the residual variance (RSS / (N - p)), P the prior;
- whiteness: Ljung-Box statistic of the first ``whiteness_lags`` residual autocorrelations against
  chi2(lags); when it fails, the covariance is inflated by the long-run variance factor
  1 + 2 sum_k (1 - k/(L+1)) rho_k (Bartlett window over ``correlation_window_s``), and the result says so;
- chi-square: when the sensor noise is stated, (N - p) s^2 / (sigma_n^2 |(I+D)^-1 u|^2 + sigma_f^2) is
  compared with chi2(N - p) (two-sided, ``test_level``).

Observability: the information matrix F = J^T J / s^2 in units of the per-parameter tolerances
(``max_*_sigma``): its singular values relative to the largest are reported, directions below
``rank_rtol`` are the numerical null space, and a parameter whose marginal sigma exceeds its tolerance
(or that lies in the null space) is not observable. A short arc or a near-constant field direction in
the sensor frame leaves D and b (and C without dipole variation) undetermined: |B| then only fixes the
field along one direction.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.estimation.chi2 import chi2_cdf, chi2_sf
from processing.magnetometer.model import OFF_DIAGONAL, MagnetometerErrors

__all__ = ["CalibrationSettings", "MagnetometerCalibration", "MagnetometerCalibrationError", "PARAMETER_NAMES",
           "calibrate_magnetometer", "field_residual_nT", "ljung_box", "long_run_variance_factor"]

_AXES = "xyz"
PARAMETER_NAMES: tuple[str, ...] = (
    *(f"bias_{a}_nT" for a in _AXES), *(f"scale_factor_error_{a}" for a in _AXES),
    *(f"non_orthogonality_{_AXES[i]}{_AXES[j]}_rad" for i, j in OFF_DIAGONAL),
    *(f"coupling_{a}{m}_nT_per_A_m2" for a in _AXES for m in _AXES),
)
"""Names of the parameter vector (the last 9, the coupling, only with ``estimate_coupling``)."""

_PRIOR_SIGMA = np.array([1e4] * 3 + [0.1] * 6 + [100.0] * 9)


class MagnetometerCalibrationError(ValueError):
    """Inputs the calibration cannot use (shapes, too few samples, non-finite values)."""


@dataclass(frozen=True)
class CalibrationSettings:
    """Settings of :func:`calibrate_magnetometer` (module docstring). Units in the names."""

    estimate_coupling: bool = False
    magnetometer_noise_nT: float | None = None  # stated sensor noise (1 sigma per axis): chi-square test if given
    field_model_error_nT: float = 0.0  # added in quadrature to the expected residual variance
    # tolerances: a parameter whose sigma exceeds them is not observable (50 nT of bias or 0.5 % of scale on a
    # 20 000-50 000 nT field turn the measured direction by at most ~0.15 deg and ~0.3 deg)
    max_bias_sigma_nT: float = 50.0
    max_scale_sigma: float = 5e-3  # for the scale-factor errors and the non-orthogonality (rad)
    max_coupling_sigma_nT_per_A_m2: float = 10.0
    rank_rtol: float = 1e-9
    max_iterations: int = 30
    outlier_sigma: float | None = 6.0
    whiteness_lags: int = 20
    correlation_window_s: float = 600.0
    test_level: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("max_bias_sigma_nT", "max_scale_sigma", "max_coupling_sigma_nT_per_A_m2", "test_level"):
            if not getattr(self, name) > 0:
                raise MagnetometerCalibrationError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.magnetometer_noise_nT is not None and not self.magnetometer_noise_nT > 0:
            raise MagnetometerCalibrationError(f"magnetometer_noise_nT must be > 0, got {self.magnetometer_noise_nT}")
        if self.whiteness_lags < 1 or self.max_iterations < 1:
            raise MagnetometerCalibrationError("whiteness_lags and max_iterations must be >= 1")

    def tolerances(self, n_params: int) -> NDArray[np.float64]:
        t = np.array([self.max_bias_sigma_nT] * 3 + [self.max_scale_sigma] * 6
                     + [self.max_coupling_sigma_nT_per_A_m2] * 9)
        return t[:n_params]


@dataclass(frozen=True)
class MagnetometerCalibration:
    """Result of :func:`calibrate_magnetometer`.

    errors: the estimated model (parameters that are not observable set to zero); estimate, sigma (p,),
    covariance (p, p) in the order of ``parameter_names``; observable (p,) bool; singular_values (p,)
    of the tolerance-scaled information matrix relative to the largest; residual_before_nT /
    residual_after_nT (N,): |B_meas| - |B_ref| and the fitted r_k; used (N,) False for outliers;
    residual_sigma_nT: s; iterations, converged; chi2 (statistic, dof, p-value) or None;
    whiteness_statistic, whiteness_dof, whiteness_p; rho (lags,); inflation (>= 1, applied to the
    covariance when the whiteness test failed, else 1); long_run_factor (computed either way).
    """

    errors: MagnetometerErrors
    parameter_names: tuple[str, ...]
    estimate: NDArray[np.float64]
    sigma: NDArray[np.float64]
    covariance: NDArray[np.float64]
    observable: NDArray[np.bool_]
    singular_values: NDArray[np.float64]
    residual_before_nT: NDArray[np.float64]
    residual_after_nT: NDArray[np.float64]
    used: NDArray[np.bool_]
    residual_sigma_nT: float
    iterations: int
    converged: bool
    chi2: tuple[float, int, float] | None
    whiteness_statistic: float
    whiteness_dof: int
    whiteness_p: float
    rho: NDArray[np.float64]
    inflation: float
    long_run_factor: float
    notes: list[str] = field(default_factory=list)

    @property
    def complete(self) -> bool:
        return bool(np.all(self.observable) and self.converged)

    @property
    def white(self) -> bool:
        return bool(self.inflation == 1.0)


def field_residual_nT(B_meas_M_nT: NDArray[np.float64], B_ref_norm_nT: NDArray[np.float64],
                      errors: MagnetometerErrors | None = None,
                      mu_B_A_m2: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """|corrected B_meas| - |B_ref| (N,) nT; errors None: the raw |B_meas| - |B_ref|."""
    B = B_meas_M_nT if errors is None else errors.correct(B_meas_M_nT, mu_B_A_m2)
    return np.asarray(np.linalg.norm(B, axis=-1) - B_ref_norm_nT, dtype=np.float64)


def _unpack(p: NDArray[np.float64]) -> MagnetometerErrors:
    C = p[9:18].reshape(3, 3) if p.size > 9 else np.zeros((3, 3))
    D = np.diag(p[3:6])
    for (i, j), v in zip(OFF_DIAGONAL, p[6:9], strict=True):
        D[i, j] = D[j, i] = v
    return MagnetometerErrors(p[0:3].copy(), D, C)


def _residual_and_jacobian(p: NDArray[np.float64], H: NDArray[np.float64], ref: NDArray[np.float64],
                           mu: NDArray[np.float64] | None, noise_var: float = 0.0,
                           ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """r (N,), dr/dp (N, p) and the errors-in-variables term E[J^T e] (p,) for sensor noise variance
    noise_var [nT^2]: x = M y, y = H - b - C mu, M = (I + D)^-1; dr = -w^T (db + dD x + dC mu), w = M u,
    u = x/|x|.

    The residual is taken about its noise mean, r = |x| - |B_ref| - noise_var/|x| (the second-order term
    of |x + M n|). The D columns of J contain x, hence the noise M n, which correlates with e = w^T n:
    E[dr/dD_ij e] = -noise_var (w_i (M w)_j + w_j (M w)_i) (i != j), -noise_var w_i (M w)_i (i = j).
    Without this correction the fit is biased by ~noise_var/|B|^2, amplified in weakly determined
    directions (2-3 sigma on a nadir-pointing orbit)."""
    e = _unpack(p)
    M = np.linalg.inv(np.eye(3) + e.D)
    y = H - e.bias_nT
    if mu is not None:
        y = y - _apply(e.coupling_nT_per_A_m2, mu)
    x = _apply(M, y)
    nx = np.sqrt(np.einsum("ki,ki->k", x, x))
    w = _apply(M, x / nx[:, None])  # M u
    J = np.empty((H.shape[0], p.size))
    J[:, 0:3] = -w
    J[:, 3:6] = -w * x
    for k, (i, j) in enumerate(OFF_DIAGONAL):
        J[:, 6 + k] = -(w[:, i] * x[:, j] + w[:, j] * x[:, i])
    if p.size > 9:
        assert mu is not None
        J[:, 9:18] = -(w[:, :, None] * mu[:, None, :]).reshape(-1, 9)
    eiv = np.zeros(p.size)
    if noise_var > 0:
        Mw = _apply(M, w)
        eiv[3:6] = -noise_var * np.sum(w * Mw, axis=0)
        for k, (i, j) in enumerate(OFF_DIAGONAL):
            eiv[6 + k] = -noise_var * float(np.sum(w[:, i] * Mw[:, j] + w[:, j] * Mw[:, i]))
        return nx - ref - noise_var / nx, J, eiv
    return nx - ref, J, eiv


def _apply(A: NDArray[Any], v: NDArray[Any]) -> NDArray[np.float64]:
    """A v for every row v (N, 3) of v: (N, 3); einsum (no threaded BLAS on tall, thin arrays)."""
    return np.asarray(np.einsum("ij,kj->ki", A, v), dtype=np.float64)


def _tmul(J: NDArray[np.float64], r: NDArray[np.float64]) -> NDArray[np.float64]:
    """J^T r by einsum."""
    return np.asarray(np.einsum("ki,k->i", J, r), dtype=np.float64)


def _ss(r: NDArray[np.float64]) -> float:
    """r^T r by einsum."""
    return float(np.einsum("k,k->", r, r))


def _gram(J: NDArray[np.float64]) -> NDArray[np.float64]:
    """J^T J by einsum: OpenBLAS's threaded gemm is ~100x slower on tall (N, 18) matrices on a busy machine."""
    return np.asarray(np.einsum("ki,kj->ij", J, J), dtype=np.float64)


def _linear_start(H: NDArray[np.float64], ref: NDArray[np.float64], n_params: int) -> NDArray[np.float64]:
    """TWOSTEP-like linear first step (module docstring, step 1); zeros when it is degenerate."""
    p = np.zeros(n_params)
    s0 = float(np.mean(ref))
    h = (H - H.mean(axis=0)) / s0  # centred for conditioning; the centre goes into the bias below
    c0 = H.mean(axis=0) / s0
    t = (ref / s0) ** 2
    A_cols = [h[:, 0] ** 2, h[:, 1] ** 2, h[:, 2] ** 2, 2 * h[:, 0] * h[:, 1], 2 * h[:, 0] * h[:, 2],
              2 * h[:, 1] * h[:, 2]]
    X = np.column_stack([*A_cols, -2 * h, np.ones(h.shape[0])])
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    Xs = X / scale
    try:  # normal equations of the column-scaled problem (10 x 10): an SVD of X is 20x slower
        sol = np.linalg.solve(_gram(Xs), _tmul(Xs, t)) / scale
    except np.linalg.LinAlgError:
        return p
    A = np.array([[sol[0], sol[3], sol[4]], [sol[3], sol[1], sol[5]], [sol[4], sol[5], sol[2]]])
    lam, V = np.linalg.eigh(A)
    if not np.all(lam > 0):
        return p
    b_h = np.linalg.solve(A, sol[6:9])  # centred, normalised
    D = (V / np.sqrt(lam)) @ V.T - np.eye(3)
    if not np.all(np.isfinite(D)) or np.max(np.abs(D)) > 0.3:
        return p
    p[0:3] = (b_h + c0) * s0
    p[3:6] = np.diag(D)
    p[6:9] = [D[i, j] for i, j in OFF_DIAGONAL]
    return p


def _residual_only(p: NDArray[np.float64], H: NDArray[np.float64], ref: NDArray[np.float64],
                   mu: NDArray[np.float64] | None, noise_var: float) -> NDArray[np.float64]:
    """r (N,) of :func:`_residual_and_jacobian` without the Jacobian (for the step control)."""
    e = _unpack(p)
    y = H - e.bias_nT
    if mu is not None:
        y = y - _apply(e.coupling_nT_per_A_m2, mu)
    x = _apply(np.linalg.inv(np.eye(3) + e.D), y)
    nx = np.sqrt(np.einsum("ki,ki->k", x, x))
    return np.asarray(nx - ref - noise_var / nx, dtype=np.float64)


def _gauss_newton(p0: NDArray[np.float64], H: NDArray[np.float64], ref: NDArray[np.float64],
                  mu: NDArray[np.float64] | None, max_iterations: int, noise_var: float | None,
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float, int, bool]:
    """Gauss-Newton with the weak prior on the bias-corrected estimating equation J^T r - E[J^T e] = 0
    (:func:`_residual_and_jacobian`); noise_var None: the residual variance. The step is halved only when
    the cost rises by more than 10 (chi-square units): the corrected root is not the cost's minimum, but
    within a few units of it. Returns p, r, J, s^2, iterations, converged."""
    prior_w = 1.0 / _PRIOR_SIGMA[: p0.size] ** 2
    p = p0.copy()
    r = _residual_only(p, H, ref, mu, 0.0)
    n_dof = max(r.size - p.size, 1)
    s2 = max(_ss(r) / n_dof, 1e-12)

    def nv() -> float:
        return s2 if noise_var is None else noise_var

    r, J, eiv = _residual_and_jacobian(p, H, ref, mu, nv())
    converged = False
    it = 0
    while it < max_iterations:
        it += 1
        N = _gram(J) / s2 + np.diag(prior_w)
        g = (_tmul(J, r) - eiv) / s2 + prior_w * p
        dp = -np.linalg.solve(N, g)
        c0 = _ss(r) / s2 + float(np.sum(prior_w * p * p))
        step = 1.0
        while True:
            p_new = p + step * dp
            r_new = _residual_only(p_new, H, ref, mu, nv())
            if _ss(r_new) / s2 + float(np.sum(prior_w * p_new * p_new)) <= c0 + 10.0 or step < 1e-3:
                break
            step *= 0.5
        p = p_new
        s2 = max(_ss(r_new) / n_dof, 1e-12)
        r, J, eiv = _residual_and_jacobian(p, H, ref, mu, nv())
        sig = np.sqrt(np.diag(np.linalg.inv(N)))
        if np.all(np.abs(step * dp) < 1e-4 * sig):
            converged = True
            break
    return p, r, J, s2, it, converged


def ljung_box(x: NDArray[np.float64], lags: int) -> tuple[float, int, float, NDArray[np.float64]]:
    """Ljung-Box statistic Q = N (N + 2) sum_k rho_k^2 / (N - k), k = 1..lags, of x (N,) against
    chi2(lags): (Q, lags, p-value, rho (lags,))."""
    rho = _autocorrelation(x, lags)
    n = x.size
    q = float(n * (n + 2) * np.sum(rho**2 / (n - np.arange(1, lags + 1))))
    return q, lags, float(chi2_sf(q, lags)), rho


def _autocorrelation(x: NDArray[np.float64], lags: int) -> NDArray[np.float64]:
    """rho_1..rho_lags of x (N,) (biased estimator, FFT)."""
    x = x - x.mean()
    n = x.size
    f = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(f * np.conj(f))[: lags + 1]
    return np.asarray(acf[1:] / acf[0], dtype=np.float64) if acf[0] > 0 else np.zeros(lags)


def long_run_variance_factor(x: NDArray[np.float64], window: int) -> float:
    """1 + 2 sum_{k=1}^{L} (1 - k/(L+1)) rho_k (Bartlett), >= 1: the factor by which correlated noise
    raises the variance of a slowly varying regression's estimate over white noise of the same variance."""
    L = int(max(1, min(window, x.size // 4)))
    rho = _autocorrelation(x, L)
    k = np.arange(1, L + 1)
    return float(max(1.0, 1.0 + 2.0 * np.sum((1.0 - k / (L + 1)) * rho)))


def _checked_inputs(B_meas_M_nT: ArrayLike, B_ref_norm_nT: ArrayLike, sample_period_s: float,
                    mu_B_A_m2: ArrayLike | None, st: CalibrationSettings
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None, int]:
    """(H (N, 3), |B_ref| (N,), mu (N, 3) or None, number of parameters) after the checks of shapes, sample
    count and finiteness; raises :class:`MagnetometerCalibrationError`."""
    H = np.asarray(B_meas_M_nT, dtype=np.float64)
    ref = np.asarray(B_ref_norm_nT, dtype=np.float64)
    n_params = 18 if st.estimate_coupling else 9
    if H.ndim != 2 or H.shape[1] != 3 or ref.shape != (H.shape[0],):
        raise MagnetometerCalibrationError(f"expected B_meas_M_nT (N, 3) and B_ref_norm_nT (N,), got {H.shape} "
                                           f"and {ref.shape}")
    mu = None
    if st.estimate_coupling:
        if mu_B_A_m2 is None:
            raise MagnetometerCalibrationError("estimate_coupling needs the magnetorquer dipole mu_B_A_m2 (N, 3)")
        mu = np.asarray(mu_B_A_m2, dtype=np.float64)
        if mu.shape != H.shape:
            raise MagnetometerCalibrationError(f"mu_B_A_m2 must have shape {H.shape}, got {mu.shape}")
    if H.shape[0] < 4 * n_params:
        raise MagnetometerCalibrationError(f"at least {4 * n_params} samples are needed for {n_params} parameters, "
                                           f"got {H.shape[0]}")
    finite = np.all(np.isfinite(H), axis=1) & np.isfinite(ref) & (ref > 0)
    if mu is not None:
        finite &= np.all(np.isfinite(mu), axis=1)
    if not np.all(finite):
        raise MagnetometerCalibrationError(f"{int(np.sum(~finite))} samples are not finite (or |B_ref| <= 0)")
    if not sample_period_s > 0:
        raise MagnetometerCalibrationError(f"sample_period_s must be > 0, got {sample_period_s}")
    return H, ref, mu, n_params


def _fit_with_outliers(p0: NDArray[np.float64], H: NDArray[np.float64], ref: NDArray[np.float64],
                       mu: NDArray[np.float64] | None, n_params: int, st: CalibrationSettings
                       ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float, int, bool,
                                  NDArray[np.bool_]]:
    """Steps 2-3: Gauss-Newton, then once more without the samples beyond ``outlier_sigma`` MAD sigmas.
    Returns p, r, J, s^2, iterations, converged and the samples used (N,)."""
    used = np.ones(H.shape[0], dtype=bool)
    nv = None if st.magnetometer_noise_nT is None else st.magnetometer_noise_nT**2
    p, r, J, s2, iterations, converged = _gauss_newton(p0, H, ref, mu, st.max_iterations, nv)
    if st.outlier_sigma is not None:
        mad = 1.4826 * float(np.median(np.abs(r - np.median(r))))
        out = np.abs(r - np.median(r)) > st.outlier_sigma * mad
        if np.any(out) and np.sum(~out) >= 4 * n_params:
            used = ~out
            mu_u = None if mu is None else mu[used]
            p, r, J, s2, it2, converged = _gauss_newton(p, H[used], ref[used], mu_u, st.max_iterations, nv)
            iterations += it2
    return p, r, J, s2, iterations, converged, used


def _covariance_and_observability(J: NDArray[np.float64], s2: float, inflation: float, n_params: int,
                                  st: CalibrationSettings
                                  ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                                             NDArray[np.bool_]]:
    """Covariance (with the weak prior, inflated), sigmas, relative singular values of the information in
    tolerance units and the observable parameters (sigma within tolerance, outside the null space)."""
    prior_w = 1.0 / _PRIOR_SIGMA[:n_params] ** 2
    N_info = _gram(J) / s2
    cov = np.asarray(np.linalg.inv(N_info + np.diag(prior_w)) * inflation, dtype=np.float64)
    sigma = np.sqrt(np.diag(cov))
    tol = st.tolerances(n_params)
    F_t = N_info * np.outer(tol, tol) / inflation
    sv = np.linalg.svd(F_t, compute_uv=False)
    rel = sv / sv[0] if sv[0] > 0 else np.zeros_like(sv)
    _, V = np.linalg.eigh(F_t)
    lam = np.linalg.eigvalsh(F_t)
    null = lam < st.rank_rtol * max(float(lam[-1]), 1e-300)
    in_null = np.sum(V[:, null] ** 2, axis=1) > 0.01 if np.any(null) else np.zeros(n_params, dtype=bool)
    observable = (sigma <= tol) & ~in_null
    return cov, sigma, rel, observable


def _chi2_test(errors_full: MagnetometerErrors, H: NDArray[np.float64], mu: NDArray[np.float64] | None,
               used: NDArray[np.bool_], r: NDArray[np.float64], n_params: int, noise_nT: float,
               field_model_error_nT: float) -> tuple[float, int, float]:
    """(statistic, dof, two-sided p) of the residuals against the stated magnetometer and field-model noise."""
    x = errors_full.correct(H[used], None if mu is None else mu[used])
    u = x / np.linalg.norm(x, axis=1, keepdims=True)
    Mu = np.linalg.solve(np.eye(3) + errors_full.D, u.T).T
    var = noise_nT**2 * np.sum(Mu**2, axis=1) + field_model_error_nT**2
    stat = float(np.sum(r**2 / var))
    dof = int(r.size - n_params)
    p_two = float(2.0 * min(chi2_cdf(stat, dof), chi2_sf(stat, dof)))
    return stat, dof, p_two


def calibrate_magnetometer(
    B_meas_M_nT: ArrayLike,
    B_ref_norm_nT: ArrayLike,
    *,
    sample_period_s: float,
    mu_B_A_m2: ArrayLike | None = None,
    settings: CalibrationSettings | None = None,
) -> MagnetometerCalibration:
    """Bias, scale factors, non-orthogonality (and magnetorquer coupling) from |B| matching.

    B_meas_M_nT (N, 3) nT measured field in the magnetometer frame; B_ref_norm_nT (N,) nT field-model
    magnitude at the same instants; sample_period_s: the (median) sampling period [s] (lags of the
    whiteness test and the correlation window); mu_B_A_m2 (N, 3) A m^2 dipole held at each sample
    (required with settings.estimate_coupling). Module docstring: model, noise, observability.
    """
    st = CalibrationSettings() if settings is None else settings
    H, ref, mu, n_params = _checked_inputs(B_meas_M_nT, B_ref_norm_nT, sample_period_s, mu_B_A_m2, st)

    notes: list[str] = []
    before = field_residual_nT(H, ref)
    p0 = _linear_start(H, ref, n_params)
    if not np.any(p0):
        notes.append("the linear first step was degenerate (field direction hardly changes): started from zero")
    p, r, J, s2, iterations, converged, used = _fit_with_outliers(p0, H, ref, mu, n_params, st)
    errors_full = _unpack(p)
    after = field_residual_nT(H, ref, errors_full, mu)

    # whiteness and inflation
    lags = int(min(st.whiteness_lags, max(1, r.size // 5)))
    q, dof_w, p_w, rho = ljung_box(r, lags)
    window = int(round(st.correlation_window_s / sample_period_s))
    lrf = long_run_variance_factor(r, window)
    inflation = lrf if p_w < st.test_level else 1.0
    cov, sigma, rel, observable = _covariance_and_observability(J, s2, inflation, n_params, st)

    chi2 = None
    if st.magnetometer_noise_nT is not None:
        chi2 = _chi2_test(errors_full, H, mu, used, r, n_params, st.magnetometer_noise_nT, st.field_model_error_nT)

    est = np.where(observable, p, 0.0)
    return MagnetometerCalibration(
        errors=_unpack(est), parameter_names=PARAMETER_NAMES[:n_params], estimate=p, sigma=sigma, covariance=cov,
        observable=observable, singular_values=rel, residual_before_nT=before, residual_after_nT=after, used=used,
        residual_sigma_nT=float(np.sqrt(s2)), iterations=iterations, converged=converged, chi2=chi2,
        whiteness_statistic=q, whiteness_dof=dof_w, whiteness_p=p_w, rho=rho, inflation=inflation,
        long_run_factor=lrf, notes=notes,
    )
