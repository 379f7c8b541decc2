"""Honest covariance of the gyro offset fit (beyond 003 §2.2): the sandwich with integrated gyro noise.

With white gyro noise of angle random walk N (rad/sqrt(s)) per gyro axis the integrated model error is
eps(t) = R(U_t)^T eta(t), eta a Wiener process in the frame R at t0 with increments of covariance
R(U) R_RG diag(N²) R_RG^T R(U)^T dt (eq. 7 with the noise as forcing). The residuals at the true x are
e = nu - eps' (nu the star-tracker noise in sensor axes, eps' = R(q_RS)^T eps), so the estimate's
covariance is C^-1 J^T W Cov(a) W J C^-1 with Cov(a) = 1/4 (diag(sigma_st²) + Cov(eps')), computed in
O(N P²) from cumulative sums (the min(t, t') structure of the random walk). The star-tracker variances
per tracker and axis are the residual mean squares minus the expected gyro-noise contribution
(diag of (I - H) Cov(eps') (I - H)^T, H the hat matrix, also O(N)), divided by 1 - P / (3 N).
See processing.gyro_calibration.bias_fit for the fit.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from processing.attitude import rotations
from processing.gyro_calibration.bias_fit_model import Evaluation, Problem

__all__ = ["honest_covariance"]

FloatArray = NDArray[np.float64]


def honest_covariance(
    pb: Problem,
    ev: Evaluation,
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
    # J^T W L W J (kept as this einsum, and b_w below too: a BLAS product, 7x faster, reorders the sums, and
    # the near-zero off-diagonal covariances then move by 1e-11 relative, beyond the golden tests' 1e-12)
    b_rw = np.einsum("nij,njk,nlk->il", s_rev, lam, s_rev)
    # Expected gyro part of the residual mean squares: diag of L - 2 H L + H L H^T.
    diag_l = np.einsum("nik,nik->ni", k_mat @ gamma, k_mat)
    s_after = np.concatenate([s_rev[1:], np.zeros((1, p, 3))], axis=0)  # sum_{m > n} F_m
    inner = np.cumsum(f @ gamma, axis=0) + s_after @ gamma  # (M, P, 3)
    jc = (ev.jac.reshape(-1, p) @ c_inv).reshape(m, 3, p)  # (M, 3, P), one product for all samples
    # only the diagonals of H L = jc inner K^T and H L H^T = jc B jc^T enter (without the 6 off-diagonal
    # terms per sample of the full (M, 3, 3) products); first the (M, 3, 3) resp. (3 M, P) matrix products,
    # then the row-wise dot products (4-6x faster than the three-operand einsums; they enter the residual rms
    # and sigma_st, which move by round-off, <= 1e-15 relative)
    hl_diag = np.einsum("nik,nik->ni", jc @ inner, k_mat)
    jc_rows = jc.reshape(-1, p)
    hlh_diag = np.einsum("np,np->n", jc_rows @ b_rw, jc_rows).reshape(m, 3)
    rw_ms = diag_l - 2.0 * hl_diag + hlh_diag

    counts = np.maximum(np.bincount(sensor, minlength=n_sensors), 1).astype(float)
    ms = np.zeros((n_sensors, 3))
    rw = np.zeros((n_sensors, 3))
    np.add.at(ms, sensor, e * e)
    np.add.at(rw, sensor, rw_ms)
    ms /= counts[:, None]
    rw = np.maximum(rw / counts[:, None], 0.0)
    dof = max(1.0 - p / (3.0 * m), 1e-3)
    var_st = np.maximum(ms - rw, 0.0) / dof
    jw = ev.jac * w[None, :, None]
    b_w = np.einsum("nip,ni,niq->pq", jw, var_st[sensor], jw)
    cov = 0.25 * c_inv @ (b_w + b_rw) @ c_inv
    return 0.5 * (cov + cov.T), np.sqrt(ms), np.sqrt(rw), np.sqrt(var_st)
