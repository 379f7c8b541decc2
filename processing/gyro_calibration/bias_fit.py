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

Honest covariance (beyond 003). With white gyro noise of angle random walk N (rad/sqrt(s)) per gyro
axis the integrated model error is eps(t) = R(U_t)^T eta(t), eta a Wiener process in the frame R at t0
with increments of covariance R(U) R_RG diag(N²) R_RG^T R(U)^T dt (the same eq. 7 with the noise as
forcing). The residuals at the true x are e = nu - eps' (nu the star-tracker noise in sensor axes,
eps' = R(q_RS)^T eps), so the estimate's covariance is the sandwich
C^-1 J^T W Cov(a) W J C^-1 with Cov(a) = 1/4 (diag(sigma_st²) + Cov(eps')), computed in O(N P²) from
cumulative sums (the random-walk covariance min(t, t') structure). The star-tracker variances
sigma_st² per tracker and axis are the residual mean squares minus the expected contribution of the
gyro noise (diag of (I - H) Cov(eps') (I - H)^T, H the hat matrix, also O(N)), divided by
1 - P / (3 N). N is given, or estimated from the gyro rates (:func:`estimate_gyro_arw`).

Mounting (beyond 003, which found it "gave clearly wrong Q" on short arcs): optionally three more
parameters mu, a small rotation of the gyro axes, q_RG' = exp(mu) o q_RG. mu only enters through
mu x Omega, so on a near-constant rate (Earth pointing) it is indistinguishable from Delta (and its
component along Omega is unobservable): :class:`MountingEstimate` says so (sigma, condition number,
correlations) and the fit falls back to the given mounting instead of returning a wrong one.

Times are float64 seconds from any epoch; angles rad, rates rad/s; quaternions scalar first, Hamilton,
q_AB maps B to A coordinates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.gyro_calibration.propagation import (
    GyroPropagationError,
    Propagation,
    mrp_pseudo_derivatives,
    propagate,
)
from processing.units import RAD_PER_ARCSEC

__all__ = [
    "RAD_PER_ARCSEC",
    "MOUNTING_SIGMA_MAX_RAD",
    "GyroBiasFit",
    "GyroBiasFitError",
    "MountingEstimate",
    "estimate_gyro_arw",
    "fit_gyro_bias",
    "fit_subintervals",
    "subinterval_edges",
]

MOUNTING_SIGMA_MAX_RAD = 60.0 * RAD_PER_ARCSEC
"""A mounting estimate is reported only when every component's honest sigma is below this (1 arcmin)."""
MOUNTING_CONDITION_MAX = 1e12
"""... and the correlation-scaled normal matrix is better conditioned than this."""
SIGMA_FLOOR = 1e-12
"""Floor on sigma_w in the convergence test (noise-free data), in the units of a (half radians)."""

FloatArray = NDArray[np.float64]
PARAMETER_NAMES = ("z1", "z2", "z3", "delta1", "delta2", "delta3")
MOUNTING_NAMES = ("mu1", "mu2", "mu3")


class GyroBiasFitError(ValueError):
    """Bad input to the gyro offset fit: shapes, too few samples, no overlap of the two time grids."""


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
    iterations, converged, status; condition_number of the scaled normal matrix;
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

    @property
    def delta_sigma_R_rad_s(self) -> FloatArray:
        """Honest sigma of Delta (3,) rad/s, R axes."""
        return self.sigma[3:6]

    @property
    def delta_covariance_R(self) -> FloatArray:
        """Honest covariance of Delta (3, 3) (rad/s)², R axes."""
        return self.covariance[3:6, 3:6]


# ---------------------------------------------------------------------------------------------------
# Helpers.


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


def _cross(v: FloatArray) -> FloatArray:
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _quat_rows(q: ArrayLike, m: int, name: str) -> FloatArray:
    a = np.asarray(q, dtype=np.float64)
    if a.shape == (4,):
        a = np.broadcast_to(a, (m, 4))
    if a.shape != (m, 4):
        raise GyroBiasFitError(f"{name} must have shape (4,) or ({m}, 4), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise GyroBiasFitError(f"{name} must be finite")
    return rotations.quat_normalize(a)


def _scaled_inverse(c: FloatArray) -> tuple[FloatArray, float]:
    """C^-1 via the correlation-scaled matrix, and the condition number of that scaled matrix."""
    s = 1.0 / np.sqrt(np.diag(c))
    cs = c * s[:, None] * s[None, :]
    cond = float(np.linalg.cond(cs))
    return np.linalg.inv(cs) * s[:, None] * s[None, :], cond


# ---------------------------------------------------------------------------------------------------
# The model evaluation: residuals and Jacobian at x.


@dataclass(frozen=True)
class _Problem:
    t_g: FloatArray  # (N,) gyro times from t0
    w_R: FloatArray  # (N, 3) rates in R with the given mounting
    t_st: FloatArray  # (M,) sorted star-tracker times
    q_meas: FloatArray  # (M, 4) q_IS
    q_RS: FloatArray  # (M, 4)
    rot_RS_T: FloatArray  # (M, 3, 3) R(q_RS)^T
    weights: FloatArray  # (3,)
    scheme: int
    mounting: bool


@dataclass(frozen=True)
class _Eval:
    a: FloatArray  # (M, 3)
    jac: FloatArray  # (M, 3, P)
    phi: float
    prop: Propagation
    q_model: FloatArray  # (M, 4) q_IR at the samples
    psi: FloatArray  # (M, 3, P) pseudo-derivatives, R axes at t_n


def _evaluate(pb: _Problem, z: FloatArray, delta: FloatArray, q_mu: FloatArray, jacobian: bool = True) -> _Eval:
    w_rot = pb.w_R if not pb.mounting else rotations.quat_rotate(q_mu, pb.w_R)
    omega = w_rot + delta
    rate_jac = None
    if pb.mounting and jacobian:
        rate_jac = np.concatenate([np.broadcast_to(np.eye(3), (pb.t_g.size, 3, 3)), -_cross(w_rot)], axis=2)
    prop = propagate(pb.t_g, omega, pb.t_st, scheme=pb.scheme, rate_jacobian=rate_jac, derivatives=jacobian)
    p0 = rotations.mrp_to_quat(z)
    q_model = rotations.quat_multiply(p0, prop.u_out)  # q_IR(t_n), |.| = |U| (scheme 1 drifts)
    r = rotations.quat_multiply(rotations.quat_conjugate(pb.q_meas), rotations.quat_multiply(q_model, pb.q_RS))
    r = np.where(r[:, :1] < 0.0, -r, r)
    a = -r[:, 1:]
    phi = float(np.sum(pb.weights * a * a))
    if not jacobian:
        empty = np.zeros((a.shape[0], 3, 0))
        return _Eval(a=a, jac=empty, phi=phi, prop=prop, q_model=q_model, psi=empty)
    psi_z = np.swapaxes(prop.rot_out, -1, -2) @ mrp_pseudo_derivatives(z)  # (M, 3, 3)
    psi = np.concatenate([psi_z, prop.psi_out], axis=2)  # (M, 3, P), R axes at t_n
    psi_s = pb.rot_RS_T @ psi  # sensor axes
    # da/dx = -1/2 vec(r o psi) = -1/2 (r0 psi + r_vec x psi)
    jac = -0.5 * (r[:, :1, None] * psi_s + np.cross(r[:, None, 1:], np.swapaxes(psi_s, 1, 2)).swapaxes(1, 2))
    return _Eval(a=a, jac=jac, phi=phi, prop=prop, q_model=q_model, psi=psi)


def _linear_step(ev: _Eval, dx: FloatArray, weights: FloatArray) -> _Eval:
    """The evaluation after a negligible step dx, to first order: a + J dx, q o (1, psi dx / 2)."""
    a = ev.a + ev.jac @ dx
    q_model = rotations.quat_multiply(ev.q_model, rotations.rotvec_to_quat(ev.psi @ dx))
    return replace(ev, a=a, phi=float(np.sum(weights * a * a)), q_model=q_model)


def _normal_equations(ev: _Eval, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    jw = ev.jac * w[None, :, None]
    c = np.einsum("nip,niq->pq", jw, ev.jac)
    d = -np.einsum("nip,ni->p", jw, ev.a)
    return c, d


# ---------------------------------------------------------------------------------------------------
# Honest covariance.


def _honest(
    pb: _Problem,
    ev: _Eval,
    c_inv: FloatArray,
    sensor: NDArray[np.int64],
    n_sensors: int,
    arw_G: FloatArray,
    q_RG: FloatArray,
    t0: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """(covariance (P, P), residual rms (S, 3), gyro part of it (S, 3), star-tracker sigma (S, 3)), rad.

    See the module docstring. Everything in e = 2a units (radians) except the returned covariance.
    """
    m, _, p = ev.jac.shape
    w = pb.weights
    e = 2.0 * ev.a
    rot_u = ev.prop.rot_out  # R(U_n): R axes at t_n -> R axes at t0
    k_mat = pb.rot_RS_T @ np.swapaxes(rot_u, 1, 2)  # (M, 3, 3): eta (t0 frame) -> sensor axes at t_n
    # Random-walk increments Lambda_i over (t_{i-1}, t_i], t_{-1} = t0: dt R(U_i) Sigma_R R(U_i)^T.
    r_rg = rotations.quat_to_dcm(q_RG)
    sigma_R = r_rg @ np.diag(arw_G**2) @ r_rg.T
    dt = np.diff(np.concatenate([[t0], pb.t_st]))
    lam = dt[:, None, None] * (rot_u @ sigma_R @ np.swapaxes(rot_u, 1, 2))
    gamma = np.cumsum(lam, axis=0)  # Cov(eta_n) = Gamma_n
    f = np.swapaxes(ev.jac * w[None, :, None], 1, 2) @ k_mat  # (M, P, 3) = J^T W K
    s_rev = np.cumsum(f[::-1], axis=0)[::-1]  # S_i = sum_{n >= i} F_n
    b_rw = np.einsum("nij,njk,nlk->il", s_rev, lam, s_rev)  # J^T W L W J
    # Expected gyro part of the residual mean squares: diag of L - 2 H L + H L H^T.
    diag_l = np.einsum("nij,njk,nik->ni", k_mat, gamma, k_mat)
    s_after = np.concatenate([s_rev[1:], np.zeros((1, p, 3))], axis=0)  # sum_{m > n} F_m
    inner = np.cumsum(f @ gamma, axis=0) + s_after @ gamma  # (M, P, 3)
    jc = ev.jac @ c_inv  # (M, 3, P)
    hl = np.einsum("nip,npk,njk->nij", jc, inner, k_mat)
    hlh = np.einsum("nip,pq,njq->nij", jc, b_rw, jc)
    rw_ms = diag_l - 2.0 * np.einsum("nii->ni", hl) + np.einsum("nii->ni", hlh)

    counts = np.maximum(np.bincount(sensor, minlength=n_sensors), 1).astype(float)
    ms = np.zeros((n_sensors, 3))
    rw = np.zeros((n_sensors, 3))
    np.add.at(ms, sensor, e * e)
    np.add.at(rw, sensor, rw_ms)
    ms /= counts[:, None]
    rw = np.maximum(rw / counts[:, None], 0.0)
    dof = max(1.0 - p / (3.0 * m), 1e-3)
    var_st = np.maximum(ms - rw, 0.0) / dof
    b_w = np.einsum("nip,ni,niq->pq", ev.jac * w[None, :, None], var_st[sensor], ev.jac * w[None, :, None])
    cov = 0.25 * c_inv @ (b_w + b_rw) @ c_inv
    return 0.5 * (cov + cov.T), np.sqrt(ms), np.sqrt(rw), np.sqrt(var_st)


# ---------------------------------------------------------------------------------------------------
# The fit.


def _prepare(
    t_gyro_s: ArrayLike,
    w_G: ArrayLike,
    t_st_s: ArrayLike,
    q_IS: ArrayLike,
    q_RG: ArrayLike,
    q_RS: ArrayLike | None,
    sensor_index: ArrayLike | None,
    weights: ArrayLike,
    scheme: int,
    mounting: bool,
) -> tuple[_Problem, NDArray[np.int64], NDArray[np.int64], int, float, FloatArray]:
    tg = np.asarray(t_gyro_s, dtype=np.float64)
    wg = np.asarray(w_G, dtype=np.float64)
    if tg.ndim != 1 or tg.size < 2 or wg.shape != (tg.size, 3):
        raise GyroBiasFitError(f"need t_gyro_s (N,) and w_G (N, 3), N >= 2, got {tg.shape} and {wg.shape}")
    if not (np.all(np.isfinite(tg)) and np.all(np.isfinite(wg))):
        raise GyroBiasFitError("gyro times and rates must be finite")
    if not np.all(np.diff(tg) > 0):
        raise GyroBiasFitError("gyro times must be strictly increasing")
    ts = np.asarray(t_st_s, dtype=np.float64)
    if ts.ndim != 1:
        raise GyroBiasFitError(f"t_st_s must have shape (M,), got {ts.shape}")
    m = ts.size
    qm = np.asarray(q_IS, dtype=np.float64)
    if qm.shape != (m, 4) or not np.all(np.isfinite(qm)) or not np.all(np.isfinite(ts)):
        raise GyroBiasFitError(f"q_IS must be finite with shape ({m}, 4), got {qm.shape}")
    wts = np.asarray(weights, dtype=np.float64)
    if wts.shape != (3,) or not np.all(wts > 0) or not np.all(np.isfinite(wts)):
        raise GyroBiasFitError(f"weights must be 3 positive numbers, got {weights!r}")
    if scheme not in (1, 2):
        raise GyroBiasFitError(f"scheme must be 1 or 2, got {scheme!r}")
    n_par = 9 if mounting else 6
    if 3 * m <= n_par:
        raise GyroBiasFitError(f"need more than {n_par // 3} star-tracker samples, got {m}")
    if ts.min() < tg[0] or ts.max() > tg[-1]:
        raise GyroBiasFitError(
            f"star-tracker samples [{ts.min()}, {ts.max()}] s must lie within the gyro samples "
            f"[{tg[0]}, {tg[-1]}] s"
        )
    sens = np.zeros(m, dtype=np.int64) if sensor_index is None else np.asarray(sensor_index).astype(np.int64)
    if sens.shape != (m,) or (m and sens.min() < 0):
        raise GyroBiasFitError(f"sensor_index must be (M,) integers >= 0, got shape {sens.shape}")
    n_sensors = int(sens.max()) + 1 if m else 1
    q_rs = _quat_rows(np.array([1.0, 0.0, 0.0, 0.0]) if q_RS is None else q_RS, m, "q_RS")
    q_rg = rotations.quat_normalize(np.asarray(q_RG, dtype=np.float64))

    order = np.argsort(ts, kind="stable")
    ts, qm, q_rs, sens_sorted = ts[order], qm[order], q_rs[order], sens[order]
    k0 = int(np.searchsorted(tg, ts[0], side="right")) - 1
    k1 = max(int(np.searchsorted(tg, ts[-1], side="left")), k0 + 1)
    t0 = float(tg[k0])
    w_R = rotations.quat_rotate(q_rg, wg[k0 : k1 + 1])
    pb = _Problem(
        t_g=tg[k0 : k1 + 1] - t0,
        w_R=w_R,
        t_st=ts - t0,
        q_meas=rotations.quat_normalize(qm),
        q_RS=q_rs,
        rot_RS_T=np.swapaxes(rotations.quat_to_dcm(q_rs), 1, 2),
        weights=wts,
        scheme=int(scheme),
        mounting=mounting,
    )
    return pb, order, sens_sorted, n_sensors, t0, q_rg


def _initial_guess(pb: _Problem) -> tuple[FloatArray, FloatArray]:
    """z from the first sample; Delta from the gyro-vs-tracker relative rotations of consecutive samples.

    d_n = rotvec((U_n^-1 U_{n+1})^-1 o m_n^-1 m_{n+1}) ~ int Delta dt (m_n = q_n o q_RS^-1), whose sum
    telescopes the tracker noise: Delta0 = sum d_n / (t_M - t_1).
    """
    meas = rotations.quat_multiply(pb.q_meas, rotations.quat_conjugate(pb.q_RS))  # q_IR measured
    z0 = rotations.quat_to_mrp(rotations.quat_canonical(meas[0]))
    ev = _evaluate(pb, z0, np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), jacobian=False)
    u = rotations.quat_normalize(ev.prop.u_out)
    model_rel = rotations.quat_multiply(rotations.quat_conjugate(u[:-1]), u[1:])
    meas_rel = rotations.quat_multiply(rotations.quat_conjugate(meas[:-1]), meas[1:])
    d = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(model_rel), meas_rel))
    span = pb.t_st[-1] - pb.t_st[0]
    delta0 = np.sum(d, axis=0) / span if span > 0 else np.zeros(3)
    return z0, delta0


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
    pb, order, sens, n_sensors, t0, q_rg = _prepare(
        t_gyro_s, w_G, t_st_s, q_IS, q_RG, q_RS, sensor_index, weights, scheme, estimate_mounting
    )
    if gyro_arw_rad_sqrt_s is None:
        arw = estimate_gyro_arw(t_gyro_s, w_G)
    else:
        arw = np.broadcast_to(np.asarray(gyro_arw_rad_sqrt_s, dtype=np.float64), (3,)).copy()
        if not np.all(np.isfinite(arw)) or np.any(arw < 0):
            raise GyroBiasFitError(f"gyro_arw_rad_sqrt_s must be >= 0, got {gyro_arw_rad_sqrt_s!r}")
    try:
        fit = _solve(pb, order, sens, n_sensors, t0, q_rg, arw, max_iterations, tolerance, mounting_sigma_max_rad)
    except GyroPropagationError as exc:  # pragma: no cover - inputs are checked above
        raise GyroBiasFitError(str(exc)) from exc
    if not estimate_mounting:
        return fit
    assert fit.mounting is not None
    if fit.mounting.determinable:
        return fit
    fixed = _solve(
        replace(pb, mounting=False), order, sens, n_sensors, t0, q_rg, arw, max_iterations, tolerance,
        mounting_sigma_max_rad,
    )
    return replace(fixed, mounting=fit.mounting)


def _solve(
    pb: _Problem,
    order: NDArray[np.int64],
    sens: NDArray[np.int64],
    n_sensors: int,
    t0: float,
    q_rg: FloatArray,
    arw: FloatArray,
    max_iterations: int,
    tolerance: float,
    mounting_sigma_max_rad: float,
) -> GyroBiasFit:
    m = pb.t_st.size
    n_par = 9 if pb.mounting else 6
    z, delta = _initial_guess(pb)
    q_mu = np.array([1.0, 0.0, 0.0, 0.0])
    ev = _evaluate(pb, z, delta, q_mu)
    converged = False
    status = f"not converged in {max_iterations} iterations"
    iterations = 0
    while iterations < max_iterations:
        iterations += 1
        c, d = _normal_equations(ev, pb.weights)
        c_inv, _ = _scaled_inverse(c)
        dx = c_inv @ d
        sigma_w = max(np.sqrt(ev.phi / (3 * m - n_par)), SIGMA_FLOOR)
        if np.all(np.abs(dx) <= tolerance * sigma_w * np.sqrt(np.diag(c_inv))):
            # negligible step: take it to first order rather than paying for another evaluation
            z, delta = z + dx[:3], delta + dx[3:6]
            if pb.mounting:
                q_mu = rotations.quat_multiply(rotations.rotvec_to_quat(dx[6:9]), q_mu)
            ev = _linear_step(ev, dx, pb.weights)
            converged, status = True, "converged"
            break
        step = 1.0
        for _ in range(30):
            z_new = z + step * dx[:3]
            if z_new @ z_new > 1.0:  # stay on the MRP set with |z| <= 1 (the shadow set is the same rotation)
                z_new = -z_new / (z_new @ z_new)
            delta_new = delta + step * dx[3:6]
            q_mu_new = q_mu
            if pb.mounting:
                q_mu_new = rotations.quat_multiply(rotations.rotvec_to_quat(step * dx[6:9]), q_mu)
            ev_new = _evaluate(pb, z_new, delta_new, q_mu_new)
            if ev_new.phi <= ev.phi * (1.0 + 1e-12) + 1e-300:
                break
            step *= 0.5
        else:
            status = "stopped: no step decreases Phi"
            break
        z, delta, q_mu, ev = z_new, delta_new, q_mu_new, ev_new

    c, _ = _normal_equations(ev, pb.weights)
    c_inv, cond = _scaled_inverse(c)
    sigma_w = float(np.sqrt(ev.phi / (3 * m - n_par)))
    cov_paper = sigma_w**2 * c_inv
    q_rg_used = rotations.quat_multiply(q_mu, q_rg) if pb.mounting else q_rg
    cov, rms, rms_gyro, st_sigma = _honest(pb, ev, c_inv, sens, n_sensors, arw, q_rg_used, 0.0)
    sigma = np.sqrt(np.diag(cov))
    x = np.concatenate([z, delta] + ([rotations.quat_to_rotvec(q_mu)] if pb.mounting else []))

    mounting = None
    if pb.mounting:
        with np.errstate(divide="ignore", invalid="ignore"):
            corr = np.nan_to_num(cov / np.outer(sigma, sigma))
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
        mounting = MountingEstimate(
            determinable=determinable,
            reason=reason,
            rotvec_R_rad=x[6:9].copy() if determinable else None,
            estimate_rad=x[6:9].copy(),
            sigma_rad=sig_mu,
            sigma_paper_rad=np.sqrt(np.diag(cov_paper))[6:9],
            condition_number=cond,
            max_abs_correlation=max_corr,
            correlation=corr,
        )

    inverse = np.empty_like(order)
    inverse[order] = np.arange(order.size)
    p0 = rotations.mrp_to_quat(z)
    return GyroBiasFit(
        t0_s=t0,
        q_IR0=rotations.quat_canonical(p0),
        initial_mrp=z.copy(),
        delta_R_rad_s=delta.copy(),
        q_RG=q_rg_used,
        parameter_names=PARAMETER_NAMES + (MOUNTING_NAMES if pb.mounting else ()),
        x=x,
        covariance=cov,
        covariance_paper=cov_paper,
        sigma=sigma,
        sigma_paper=np.sqrt(np.diag(cov_paper)),
        sigma_unit_weight=sigma_w,
        phi=ev.phi,
        residuals_rad=(2.0 * ev.a)[inverse],
        q_IR_model=rotations.quat_canonical(rotations.quat_normalize(ev.q_model))[inverse],
        sensor_index=sens[inverse],
        n_samples=np.bincount(sens, minlength=n_sensors),
        residual_rms_rad=rms,
        residual_rms_gyro_rad=rms_gyro,
        star_tracker_sigma_rad=st_sigma,
        gyro_arw_rad_sqrt_s=arw,
        iterations=iterations,
        converged=converged,
        status=status,
        condition_number=cond,
        mounting=mounting,
    )


# ---------------------------------------------------------------------------------------------------
# Sub-intervals (003 §2.4, figs. 15-16).


def subinterval_edges(
    start_s: float,
    end_s: float,
    *,
    splits: Sequence[int] = (2, 4),
    window_s: float | None = None,
    step_s: float | None = None,
) -> FloatArray:
    """(K, 2) [start, end] s of sub-intervals: each n in ``splits`` cuts [start, end] into n equal parts
    (003 §2.4: halves, quarters), then sliding windows of window_s every step_s (default window_s/2)."""
    if end_s <= start_s:
        raise GyroBiasFitError(f"end_s must exceed start_s, got [{start_s}, {end_s}]")
    parts = []
    for n in splits:
        if int(n) < 1:
            raise GyroBiasFitError(f"splits must be >= 1, got {n}")
        e = np.linspace(start_s, end_s, int(n) + 1)
        parts.append(np.column_stack([e[:-1], e[1:]]))
    if window_s is not None:
        step = window_s / 2.0 if step_s is None else step_s
        if window_s <= 0 or step <= 0:
            raise GyroBiasFitError(f"window_s and step_s must be > 0, got {window_s}, {step}")
        starts = np.arange(start_s, end_s - window_s + 1e-9 * window_s, step)
        parts.append(np.column_stack([starts, starts + window_s]))
    return np.concatenate(parts) if parts else np.zeros((0, 2))


def fit_subintervals(
    t_gyro_s: ArrayLike,
    w_G: ArrayLike,
    t_st_s: ArrayLike,
    q_IS: ArrayLike,
    edges_s: ArrayLike,
    *,
    q_RS: ArrayLike | None = None,
    sensor_index: ArrayLike | None = None,
    min_samples: int = 10,
    **kwargs: object,
) -> list[GyroBiasFit | None]:
    """:func:`fit_gyro_bias` on each [start, end] row of edges_s (K, 2) s (003 §2.4, offsets drifting).

    Star-tracker samples with start <= t <= end are used; a sub-interval with fewer than min_samples of
    them gives None. Other keyword arguments go to :func:`fit_gyro_bias` (pass gyro_arw_rad_sqrt_s so that
    every sub-interval uses the same noise level).
    """
    ts = np.asarray(t_st_s, dtype=np.float64)
    qm = np.asarray(q_IS, dtype=np.float64)
    m = ts.size
    q_rs = None if q_RS is None else np.broadcast_to(np.asarray(q_RS, dtype=np.float64), (m, 4))
    sens = None if sensor_index is None else np.asarray(sensor_index)
    out: list[GyroBiasFit | None] = []
    for a, b in np.asarray(edges_s, dtype=np.float64).reshape(-1, 2):
        sel = (ts >= a) & (ts <= b)
        if np.count_nonzero(sel) < min_samples:
            out.append(None)
            continue
        out.append(
            fit_gyro_bias(
                t_gyro_s, w_G, ts[sel], qm[sel],
                q_RS=None if q_rs is None else q_rs[sel],
                sensor_index=None if sens is None else sens[sel],
                **kwargs,  # type: ignore[arg-type]
            )
        )
    return out
