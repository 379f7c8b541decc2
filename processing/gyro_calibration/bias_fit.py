"""Gyro offsets and attitude by Gauss-Newton with variational equations (003 §2.1-2.4).

Model (003 §2.1, §2.4). Work in a reference star-tracker frame R (003's x1x2x3): the measured gyro
rates w_G are turned into R (003 §2.4: Omega = Q^-1 o w o Q) and corrected by constant offsets Delta,
w' = R(q_RG) w_G + Delta (eq. 5), and q' = 1/2 q o w' is integrated on the gyro grid from q(t0) = p(z),
z the (modified) Rodrigues parameters of the attitude q_IR at t0 (003 §2.2). A star tracker j with
q_RSj (identity for the reference one) is modelled as q_ISj(t) = q(t) o q_RSj. Residuals
(a0, a) = 1 - q_n^-1 o q(t_n) o q_RSj (eq. 6's a_{i,n}, in the axes of tracker j; the sign of q_n is
taken so that a0 is small) enter the weighted functional Phi = sum_n sum_i w_i a_{i,n}² (eq. 6),
weights (1, 1, 0.2) by default (boresight x3 noise 5-10x the others). e = 2a is the small rotation
from the model to the measurement (003's delta theta_n), reported as residuals.

Gauss-Newton (003 §2.2) on x = (z1, z2, z3, Delta1..3): C dx = d, c_kj = sum w_i da_i/dx_k da_i/dx_j,
d_k = -sum w_i a_i da_i/dx_k, the derivatives from the pseudo-derivatives of eq. 7 (processing.
gyro_propagation, schemes 1 and 2 of §2.3), da/dx_k = -vec(q_n^-1 o 1/2 q o psi_k o q_RSj). Columns are
scaled before solving. Convergence: every correction below ``tolerance`` times the parameter's sigma
(the last, negligible step is applied to first order); a step that raises Phi is halved.
sigma_w = sqrt(Phi / (3 N - P)) (003: sqrt(Phi/(3(N-2))), P = 6) and the paper's covariance
sigma_w² C^-1 are kept as ``*_paper``.

Honest covariance (beyond 003): the sandwich with the integrated gyro noise of angle random walk N per
axis (processing.gyro_calibration.bias_fit_covariance); N is given, or estimated from the gyro rates
(:func:`estimate_gyro_arw`).

Residual consistency (beyond 003): Gauss-Newton converging says nothing about whether the model fits. Per
tracker and sensor axis the residual mean square is compared with what the noise explains: the star-tracker
variance from the differences of consecutive residuals (E (e_{n+1} - e_n)² = 2 sigma_st² + N² dt, which a
smooth systematic misfit hardly raises) times (1 - P/3M), plus the expected gyro-noise part. A ratio above
``RESIDUAL_CONSISTENCY_MAX`` (residual rms twice the noise) leaves ``converged`` false with the reason in
``status`` (wrong quaternion convention or mounting, a time-tag offset, offsets that drift).

Mounting (beyond 003, which found it "gave clearly wrong Q" on short arcs): optionally three more
parameters mu, a small rotation of the gyro axes, q_RG' = exp(mu) o q_RG. mu only enters through
mu x Omega, so on a near-constant rate (Earth pointing) it is indistinguishable from Delta (and its
component along Omega is unobservable): :class:`MountingEstimate` says so (sigma, condition number,
correlations) and the fit falls back to the given mounting instead of returning a wrong one.

Times are float64 seconds from any epoch; angles rad, rates rad/s; quaternions scalar first, Hamilton,
q_AB maps B to A coordinates.

Steps of :func:`fit_gyro_bias`, one function each: 1. checked inputs sorted by time, in the frame R
(processing.gyro_calibration.bias_fit_inputs.prepare); 2. first guess and Gauss-Newton iteration with step
halving (processing.gyro_calibration.bias_fit_model.gauss_newton); 3. paper and honest covariances
(:func:`_covariance`); 4. observability of the mounting (:func:`_mounting_estimate`); 5. the result in
input order (:func:`_fit_result`). The model (residuals, Jacobian, normal equations) and the iteration
are in processing.gyro_calibration.bias_fit_model, the sub-interval fits of 003 §2.4 in
processing.gyro_calibration.subintervals.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.gyro_calibration.bias_fit_covariance import honest_covariance
from processing.gyro_calibration.bias_fit_inputs import GyroBiasFitError, Prepared, prepare
from processing.gyro_calibration.bias_fit_model import (
    GaussNewton,
    State,
    gauss_newton,
    normal_equations,
    scaled_inverse,
)
from processing.gyro_calibration.propagation import GyroPropagationError
from processing.units import RAD_PER_ARCSEC

__all__ = [
    "MOUNTING_SIGMA_MAX_RAD",
    "GyroBiasFit",
    "GyroBiasFitError",
    "MountingEstimate",
    "estimate_gyro_arw",
    "fit_gyro_bias",
]

MOUNTING_SIGMA_MAX_RAD = 60.0 * RAD_PER_ARCSEC
"""A mounting estimate is reported only when every component's honest sigma is below this (1 arcmin)."""
MOUNTING_CONDITION_MAX = 1e12
"""... and the correlation-scaled normal matrix is better conditioned than this."""
RESIDUAL_CONSISTENCY_MAX = 4.0
"""Residual mean square over the one the noise explains, above which the fit is not converged (rms 2x)."""
RESIDUAL_FLOOR_RAD = 1e-3 * RAD_PER_ARCSEC
"""Added in quadrature to both sides of that ratio, so that noise-free data (truncation errors only) pass."""

FloatArray = NDArray[np.float64]
PARAMETER_NAMES = ("z1", "z2", "z3", "delta1", "delta2", "delta3")
MOUNTING_NAMES = ("mu1", "mu2", "mu3")


@dataclass(frozen=True)
class MountingEstimate:
    """Observability of the gyro-to-reference mounting correction mu (q_RG' = exp(mu) o q_RG), rad.

    determinable: whether the data fix mu (every sigma_rad <= the threshold and the scaled normal matrix
    condition number <= MOUNTING_CONDITION_MAX); reason: one sentence; rotvec_R_rad (3,): the estimate,
    None when not determinable (the fit then keeps the given mounting); sigma_rad / sigma_paper_rad (3,):
    honest / paper sigmas of the 9-parameter fit; condition_number of its correlation-scaled normal
    matrix; max_abs_correlation between a mu component and any other parameter; correlation (9, 9)
    in the order z1..z3, delta1..3, mu1..3 (honest covariance).
    """

    determinable: bool
    reason: str
    rotvec_R_rad: FloatArray | None
    estimate_rad: FloatArray
    sigma_rad: FloatArray
    sigma_paper_rad: FloatArray
    condition_number: float
    max_abs_correlation: float
    correlation: FloatArray


@dataclass(frozen=True)
class GyroBiasFit:
    """Result of :func:`fit_gyro_bias`. M star-tracker samples (input order), S trackers, P parameters.

    t0_s: epoch of the initial attitude (a gyro node at or before the first star-tracker sample);
    q_IR0 (4,): attitude of the reference frame at t0, canonical; initial_mrp (3,) its MRP z (003 §2.2);
    delta_R_rad_s (3,): offsets Delta in R (w' = w_gyro + Delta, 003 eq. 5; Delta = -bias);
    q_RG (4,): gyro-to-reference rotation used (corrected when the mounting was estimated);
    parameter_names, x (P,), covariance (P, P) honest, covariance_paper (P, P) = sigma_w² C^-1,
    sigma / sigma_paper (P,); sigma_unit_weight (003's sigma_w), phi (eq. 6);
    residuals_rad (M, 3): e = 2a, model -> measurement rotation in each sample's sensor axes;
    q_IR_model (M, 4): fitted attitude of R at the samples; sensor_index (M,);
    n_samples (S,); residual_rms_rad (S, 3); residual_rms_gyro_rad (S, 3): expected contribution of the
    integrated gyro noise to those rms; star_tracker_sigma_rad (S, 3): noise of each tracker with that
    contribution removed; gyro_arw_rad_sqrt_s (3,) per gyro axis, used for the honest covariance;
    iterations; converged: Gauss-Newton converged AND the residuals are consistent with the noise; status
    says why not; residual_consistency (S, 3): residual mean square over the one the noise explains (module
    docstring; ~1 when the model fits); condition_number of the scaled normal matrix;
    mounting: :class:`MountingEstimate` when it was asked for, else None.
    """

    t0_s: float
    q_IR0: FloatArray
    initial_mrp: FloatArray
    delta_R_rad_s: FloatArray
    q_RG: FloatArray
    parameter_names: tuple[str, ...]
    x: FloatArray
    covariance: FloatArray
    covariance_paper: FloatArray
    sigma: FloatArray
    sigma_paper: FloatArray
    sigma_unit_weight: float
    phi: float
    residuals_rad: FloatArray
    q_IR_model: FloatArray
    sensor_index: NDArray[np.int64]
    n_samples: NDArray[np.int64]
    residual_rms_rad: FloatArray
    residual_rms_gyro_rad: FloatArray
    star_tracker_sigma_rad: FloatArray
    gyro_arw_rad_sqrt_s: FloatArray
    iterations: int
    converged: bool
    status: str
    condition_number: float
    mounting: MountingEstimate | None
    residual_consistency: FloatArray

    @property
    def delta_sigma_R_rad_s(self) -> FloatArray:
        """Honest sigma of Delta (3,) rad/s, R axes."""
        return self.sigma[3:6]

    @property
    def delta_covariance_R(self) -> FloatArray:
        """Honest covariance of Delta (3, 3) (rad/s)², R axes."""
        return self.covariance[3:6, 3:6]

# ---------------------------------------------------------------------------------------------------
# Helpers and step 1: the inputs.


def estimate_gyro_arw(t_s: ArrayLike, w: ArrayLike) -> FloatArray:
    """Angle random walk N (3,) rad/sqrt(s) per axis of white rate noise, from the gyro samples alone.

    t_s (N,) s, w (N, 3) rad/s. For white noise of std sigma the second differences have variance
    6 sigma²; the smooth motion contributes (h² w'')² (for 003's 0.4 Hz, 7.5"/s mirror vibration
    at 10 Hz: 0.06 % of a 1.5"/s noise variance). N = sigma sqrt(h), h the median step: the
    variance of the integrated noise grows as N² t. Needs N >= 8 samples.
    """
    t = np.asarray(t_s, dtype=np.float64)
    wa = np.asarray(w, dtype=np.float64)
    if t.ndim != 1 or wa.shape != (t.size, 3) or t.size < 8:
        raise GyroBiasFitError(f"need t_s (N,) and w (N, 3) with N >= 8, got {t.shape} and {wa.shape}")
    d2 = np.diff(wa, n=2, axis=0)
    sigma = np.sqrt(np.mean(d2 * d2, axis=0) / 6.0)
    return sigma * np.sqrt(float(np.median(np.diff(t))))


def fit_gyro_bias(
    t_gyro_s: ArrayLike,
    w_G: ArrayLike,
    t_st_s: ArrayLike,
    q_IS: ArrayLike,
    *,
    q_RG: ArrayLike = (1.0, 0.0, 0.0, 0.0),
    q_RS: ArrayLike | None = None,
    sensor_index: ArrayLike | None = None,
    weights: ArrayLike = (1.0, 1.0, 0.2),
    scheme: int = 2,
    gyro_arw_rad_sqrt_s: float | ArrayLike | None = None,
    estimate_mounting: bool = False,
    mounting_sigma_max_rad: float = MOUNTING_SIGMA_MAX_RAD,
    max_iterations: int = 20,
    tolerance: float = 1e-2,
) -> GyroBiasFit:
    """Fit the initial attitude and the gyro offsets Delta to star-tracker quaternions (003 §2.1-2.4).

    t_gyro_s (N,) strictly increasing s; w_G (N, 3) measured rates rad/s in the gyro frame G;
    t_st_s (M,) s, q_IS (M, 4) star-tracker quaternions (sensor -> inertial), any order, within the
    gyro span; q_RG (4,): gyro -> reference frame R (003 §2.4: R = the star tracker x1x2x3, so
    q_RG = q_SB o q_BG); q_RS (4,) or (M, 4): each sample's sensor -> R (None: identity, one tracker);
    sensor_index (M,) ints for per-tracker statistics (several trackers are fitted jointly);
    weights (3,) of eq. 6 in each sensor's axes; scheme 1 or 2 of 003 §2.3;
    gyro_arw_rad_sqrt_s: angle random walk per gyro axis (scalar or (3,)), None = estimated from w_G by
    :func:`estimate_gyro_arw` (pass it explicitly when w_G has been smoothed); 0 gives a white-noise
    sandwich covariance. estimate_mounting: add mu (3) and report :class:`MountingEstimate`; when mu is
    not determinable the returned fit is the 6-parameter one with the given q_RG. Convergence: every
    proposed correction below ``tolerance`` times the parameter's paper sigma (sigma_w sqrt(C^-1_kk), the
    smallest sigma reported; the honest one is ~15x larger with 003's gyro noise); that last step is applied
    to first order. Returns :class:`GyroBiasFit`; raises :class:`GyroBiasFitError` on bad input.
    """
    prep = prepare(t_gyro_s, w_G, t_st_s, q_IS, q_RG, q_RS, sensor_index, weights, scheme, estimate_mounting)
    if gyro_arw_rad_sqrt_s is None:
        arw = estimate_gyro_arw(t_gyro_s, w_G)
    else:
        arw = np.broadcast_to(np.asarray(gyro_arw_rad_sqrt_s, dtype=np.float64), (3,)).copy()
        if not np.all(np.isfinite(arw)) or np.any(arw < 0):
            raise GyroBiasFitError(f"gyro_arw_rad_sqrt_s must be >= 0, got {gyro_arw_rad_sqrt_s!r}")
    try:
        fit = _solve(prep, arw, max_iterations, tolerance, mounting_sigma_max_rad)
    except GyroPropagationError as exc:  # pragma: no cover - inputs are checked above
        raise GyroBiasFitError(str(exc)) from exc
    if not estimate_mounting:
        return fit
    assert fit.mounting is not None
    if fit.mounting.determinable:
        return fit
    fixed = _solve(replace(prep, pb=replace(prep.pb, mounting=False)), arw, max_iterations, tolerance,
                   mounting_sigma_max_rad)
    return replace(fixed, mounting=fit.mounting)


def _solve(
    prep: Prepared, arw: FloatArray, max_iterations: int, tolerance: float, mounting_sigma_max_rad: float
) -> GyroBiasFit:
    """Steps 2-5 on prepared inputs with the angle random walk arw (3,) rad/sqrt(s)."""
    gn = gauss_newton(prep.pb, max_iterations, tolerance)
    cov = _covariance(prep, gn.state, arw, gn.normal_matrix)
    mounting = _mounting_estimate(cov, gn.x, mounting_sigma_max_rad) if prep.pb.mounting else None
    return _fit_result(prep, gn, cov, arw, mounting)


# ---------------------------------------------------------------------------------------------------
# Steps 3-5: covariances, mounting observability, the result.


@dataclass(frozen=True)
class _Covariance:
    """Step 3: paper covariance sigma_w^2 C^-1 and honest covariance (P, P), honest sigmas (P,), sigma_w,
    the condition number of the scaled normal matrix, the gyro mounting used, and per tracker (S, 3) the
    residual rms, its expected gyro part and the star-tracker noise."""

    paper: FloatArray
    honest: FloatArray
    sigma: FloatArray
    sigma_w: float
    condition_number: float
    q_rg: FloatArray
    rms: FloatArray
    rms_gyro: FloatArray
    st_sigma: FloatArray


def _covariance(prep: Prepared, st: State, arw: FloatArray, c: FloatArray | None) -> _Covariance:
    """Step 3: the paper's covariance and the honest sandwich (module docstring) at the final iterate; c: its
    normal matrix when Gauss-Newton formed it already (the same sums), else None."""
    pb = prep.pb
    n_par = 9 if pb.mounting else 6
    if c is None:
        c, _ = normal_equations(st.ev, pb.weights)
    c_inv, cond = scaled_inverse(c)
    sigma_w = float(np.sqrt(st.ev.phi / (3 * pb.t_st.size - n_par)))
    q_rg_used = rotations.quat_multiply(st.q_mu, prep.q_rg) if pb.mounting else prep.q_rg
    cov, rms, rms_gyro, st_sigma = honest_covariance(pb, st.ev, c_inv, prep.sens, prep.n_sensors, arw, q_rg_used, 0.0)
    return _Covariance(paper=sigma_w**2 * c_inv, honest=cov, sigma=np.sqrt(np.diag(cov)), sigma_w=sigma_w,
                       condition_number=cond, q_rg=q_rg_used, rms=rms, rms_gyro=rms_gyro, st_sigma=st_sigma)


def _mounting_estimate(cov: _Covariance, x: FloatArray, mounting_sigma_max_rad: float) -> MountingEstimate:
    """Step 4: whether the data determine mu (honest sigmas and conditioning), with the reasons if not."""
    sigma, cond = cov.sigma, cov.condition_number
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = np.nan_to_num(cov.honest / np.outer(sigma, sigma))
    sig_mu = sigma[6:9]
    max_corr = float(np.max(np.abs(corr[6:9, :6])))
    reasons = []
    if np.any(sig_mu > mounting_sigma_max_rad):
        reasons.append(
            f"mounting sigma {np.round(sig_mu / RAD_PER_ARCSEC, 1).tolist()} arcsec exceeds "
            f"{mounting_sigma_max_rad / RAD_PER_ARCSEC:.1f} arcsec"
        )
    if cond > MOUNTING_CONDITION_MAX:
        reasons.append(f"normal matrix condition number {cond:.3g} exceeds {MOUNTING_CONDITION_MAX:.0e}")
    determinable = not reasons
    reason = (
        "mounting determined by the rate variations in the data"
        if determinable
        else "mounting not determinable from these data (rates too nearly constant: mu x Omega is "
        f"indistinguishable from the offsets, max |correlation| {max_corr:.6f}): " + "; ".join(reasons)
    )
    return MountingEstimate(
        determinable=determinable,
        reason=reason,
        rotvec_R_rad=x[6:9].copy() if determinable else None,
        estimate_rad=x[6:9].copy(),
        sigma_rad=sig_mu,
        sigma_paper_rad=np.sqrt(np.diag(cov.paper))[6:9],
        condition_number=cond,
        max_abs_correlation=max_corr,
        correlation=corr,
    )


def _fit_result(
    prep: Prepared, gn: GaussNewton, cov: _Covariance, arw: FloatArray, mounting: MountingEstimate | None
) -> GyroBiasFit:
    """Step 5: the result, per-sample arrays back in the input order."""
    st, order, sens = gn.state, prep.order, prep.sens
    inverse = np.empty_like(order)
    inverse[order] = np.arange(order.size)
    consistency = _residual_consistency(prep, 2.0 * st.ev.a, cov, arw)
    converged, status = gn.converged, gn.status
    if converged and np.max(consistency) > RESIDUAL_CONSISTENCY_MAX:
        worst = np.unravel_index(int(np.argmax(consistency)), consistency.shape)
        converged = False
        status = (
            f"not converged: Gauss-Newton converged, but the residual mean square is {float(np.max(consistency)):.3g} "
            f"times what the star-tracker and gyro noise explain (tracker {int(worst[0])}, axis x{int(worst[1]) + 1}; "
            f"at most {RESIDUAL_CONSISTENCY_MAX:g}): the model does not fit (a wrong quaternion convention or "
            "mounting, a time-tag offset, or offsets that drift)"
        )
    return GyroBiasFit(
        t0_s=prep.t0,
        q_IR0=rotations.quat_canonical(rotations.mrp_to_quat(st.z)),
        initial_mrp=st.z.copy(),
        delta_R_rad_s=st.delta.copy(),
        q_RG=cov.q_rg,
        parameter_names=PARAMETER_NAMES + (MOUNTING_NAMES if prep.pb.mounting else ()),
        x=gn.x,
        covariance=cov.honest,
        covariance_paper=cov.paper,
        sigma=cov.sigma,
        sigma_paper=np.sqrt(np.diag(cov.paper)),
        sigma_unit_weight=cov.sigma_w,
        phi=st.ev.phi,
        residuals_rad=(2.0 * st.ev.a)[inverse],
        q_IR_model=rotations.quat_canonical(rotations.quat_normalize(st.ev.q_model))[inverse],
        sensor_index=sens[inverse],
        n_samples=np.bincount(sens, minlength=prep.n_sensors),
        residual_rms_rad=cov.rms,
        residual_rms_gyro_rad=cov.rms_gyro,
        star_tracker_sigma_rad=cov.st_sigma,
        gyro_arw_rad_sqrt_s=arw,
        iterations=gn.iterations,
        converged=converged,
        status=status,
        condition_number=cov.condition_number,
        mounting=mounting,
        residual_consistency=consistency,
    )


def _residual_consistency(prep: Prepared, e: FloatArray, cov: _Covariance, arw: FloatArray) -> FloatArray:
    """(S, 3) residual mean square over sigma_st² (1 - P/3M) + the expected gyro part, sigma_st² from the
    differences of consecutive residuals of each tracker (module docstring). e (M, 3) in time order."""
    pb = prep.pb
    n_par = 9 if pb.mounting else 6
    dof = max(1.0 - n_par / (3.0 * pb.t_st.size), 1e-3)
    r_rg = rotations.quat_to_dcm(cov.q_rg)
    out = np.ones((prep.n_sensors, 3))
    for j in range(prep.n_sensors):
        idx = np.flatnonzero(prep.sens == j)
        if idx.size < 4:
            continue
        t, ej = pb.t_st[idx], e[idx]
        dt = np.diff(t)
        keep = (dt > 0) & (dt <= 1.5 * float(np.median(dt)))
        if np.count_nonzero(keep) < 3:
            continue
        r_sg = rotations.quat_to_dcm(rotations.quat_conjugate(pb.q_RS[idx[0]])) @ r_rg
        arw_S2 = np.einsum("ij,j,ij->i", r_sg, arw**2, r_sg)
        d = np.diff(ej, axis=0)[keep]
        var_st = np.maximum(np.mean(d * d, axis=0) - arw_S2 * float(np.mean(dt[keep])), 0.0) / 2.0
        expected = var_st * dof + cov.rms_gyro[j] ** 2
        out[j] = (np.mean(ej * ej, axis=0) + RESIDUAL_FLOOR_RAD**2) / (expected + RESIDUAL_FLOOR_RAD**2)
    return out
