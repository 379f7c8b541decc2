"""Magnetic attitude controllers of paper 004: the energy law (eq. 6) and the averaged LQR (eq. 7).

Both command a magnetorquer dipole mu^B [A m^2] from the estimated attitude q_OB (processing.attitude.rigid_body
conventions) and rate w_BO^B, and the field B^B measured on board [T] (the torque mu x B can only be
perpendicular to B).

- Energy law (004, eq. 6): mu = beta w_BO x B + alpha eps x B, eps the vector part of q_OB (q0 >= 0).
  Then tau = mu x B = -|B|^2 (I - b b^T)(beta w_BO + alpha eps): damping plus a restoring term.
  004's gains: beta = 1e8, alpha = 1e6 (B in tesla).
- Averaged LQR (004, eq. 7): v_n = -K x_n with x = (phi, phi', theta, theta', psi, psi') the angles and
  rates of the linearised system about the orbital orientation (here the components of the rotation
  vector of q_OB and of w_BO), u = mu~ and mu = (mu~ x B) / |B|, so the torque is
  tau = -|B| (I - b b^T) mu~ = M(B) mu~. The discrete model x_n+1 = Phi x_n + Gamma_n u_n is
  time-varying through B(t); 004 replaces Gamma_n by its orbit average Gamma_bar = (1/N) sum Gamma_n
  and solves the discrete algebraic Riccati equation
      Phi^T P Phi - P - Phi^T P Gamma_bar (Gamma_bar^T P Gamma_bar + R)^-1 Gamma_bar^T P Phi + Q = 0,
  K = (R + Gamma_bar^T P Gamma_bar)^-1 Gamma_bar^T P Phi. 004's weights: R = diag(100, 100, 0.1),
  Q = (0.1 pi / 180)^-2 I6, T_s = 1 s.
  The continuous linear model is the Jacobian of 004 eq. (1)-(2) about q_OB = 1, w_BO = 0 (gravity
  gradient with n^2 = w0^2 on a circular orbit and the gyroscopic coupling of the rotating frame),
  discretised exactly (zero-order hold) with the matrix exponential.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from processing.attitude.rigid_body import RigidBody004, dcm_BO_columns

__all__ = [
    "ENERGY_ALPHA_004",
    "ENERGY_BETA_004",
    "LQR_Q_004",
    "LQR_R_004",
    "AveragedLQR",
    "design_averaged_lqr",
    "energy_law_dipole",
    "lqr_dipole",
    "linearised_model_004",
    "lqr_state",
    "saturate_dipole",
]

ENERGY_BETA_004 = 1e8
"""beta of 004 eq. (6) [A m^2 / (rad/s T)]."""
ENERGY_ALPHA_004 = 1e6
"""alpha of 004 eq. (6) [A m^2 / T]."""
LQR_R_004 = (100.0, 100.0, 0.1)
"""Diagonal of the control weight R of 004 (on mu~, A m^2)."""
LQR_Q_004 = (0.1 * math.pi / 180.0) ** -2
"""Scalar of the state weight Q = LQR_Q_004 I6 of 004 (angles in rad, rates in rad/s)."""


def energy_law_dipole(
    q_OB: ArrayLike, omega_BO_B: ArrayLike, B_B_T: ArrayLike, *, beta: float = ENERGY_BETA_004,
    alpha: float = ENERGY_ALPHA_004,
) -> NDArray:
    """Dipole mu^B [A m^2] of the energy law (004, eq. 6), vectorised: q (..., 4), w_BO (..., 3) rad/s, B (..., 3) T."""
    q = np.asarray(q_OB, dtype=np.float64)
    eps = np.where(q[..., :1] < 0.0, -q[..., 1:], q[..., 1:])
    B = np.asarray(B_B_T, dtype=np.float64)
    return beta * np.cross(np.asarray(omega_BO_B, dtype=np.float64), B) + alpha * np.cross(eps, B)


def saturate_dipole(mu_A_m2: ArrayLike, max_A_m2: float | None) -> NDArray:
    """Scale each dipole (..., 3) so that no component exceeds max_A_m2 (direction kept); None: no limit."""
    mu = np.asarray(mu_A_m2, dtype=np.float64)
    if max_A_m2 is None:
        return mu
    peak = np.max(np.abs(mu), axis=-1, keepdims=True)
    return mu * np.minimum(1.0, max_A_m2 / np.where(peak > 0.0, peak, 1.0))


def linearised_model_004(J: ArrayLike, w0_rad_s: float) -> tuple[NDArray, NDArray]:
    """Continuous linear model x' = A x + B_tau tau of 004 eq. (1)-(2) about the orbital orientation.

    x = (phi, phi', theta, theta', psi, psi') (rotation-vector components of q_OB and of w_BO, interleaved
    as in 004); tau [N m] in B. Jacobian by central differences of the nonlinear model (exact to ~1e-9
    relative). Returns A (6, 6), B_tau (6, 3).
    """
    body = RigidBody004.from_inertia(J)
    n2 = w0_rad_s**2

    def g(z: NDArray) -> NDArray:
        th, w_bo = z[0:3], z[3:6]
        ang = float(np.linalg.norm(th))
        k = math.sin(0.5 * ang) / ang if ang > 0 else 0.5
        q = (math.cos(0.5 * ang), k * th[0], k * th[1], k * th[2])
        c2 = np.array(dcm_BO_columns(q)[1])
        w_bi = w_bo - w0_rad_s * c2
        dq, dw = body.derivative(q, tuple(w_bi), w0_rad_s, n2, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                 (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        th_dot = 2.0 * np.array(dq[1:]) / q[0]  # d(2 q_vec / q0)/dt at q_vec ~ 0 (Gibbs-like, exact to 1st order)
        w_bo_dot = np.array(dw) - w0_rad_s * np.cross(w_bo, c2)
        return np.concatenate([th_dot, w_bo_dot])

    eps = 1e-7
    A6 = np.zeros((6, 6))
    for i in range(6):
        dz = np.zeros(6)
        dz[i] = eps
        A6[:, i] = (g(dz) - g(-dz)) / (2 * eps)
    B6 = np.zeros((6, 3))
    B6[3:6] = np.diag([1.0 / body.Jx, 1.0 / body.Jy, 1.0 / body.Jz])
    order = [0, 3, 1, 4, 2, 5]  # (th1, w1, th2, w2, th3, w3)
    return A6[np.ix_(order, order)], B6[order]


@dataclass(frozen=True)
class AveragedLQR:
    """Averaged LQR of 004 eq. (7): gain K (3, 6) on x = (phi, phi', theta, theta', psi, psi'),
    discrete model Phi (6, 6), averaged input matrix Gamma_bar (6, 3), Riccati solution P (6, 6),
    step T_s [s], closed-loop spectral radius of Phi - Gamma_bar K."""

    K: NDArray
    Phi: NDArray
    Gamma_bar: NDArray
    P: NDArray
    step_s: float
    spectral_radius: float


def design_averaged_lqr(
    J: ArrayLike,
    w0_rad_s: float,
    B_O_T: ArrayLike,
    *,
    step_s: float = 1.0,
    Q: ArrayLike | float = LQR_Q_004,
    R: ArrayLike = LQR_R_004,
) -> AveragedLQR:
    """Design the averaged LQR of 004 eq. (7).

    B_O_T: (N, 3) field [T] in the orbital frame over (about) one orbit; at the design point B^B = B^O,
    so Gamma_n = Gamma_tau M(B_n), M(B) = -|B| (I - b b^T), averaged over the N samples.
    Q: scalar (times I6) or (6,)/(6, 6); R: (3,) or (3, 3). Returns :class:`AveragedLQR`.
    """
    A, Bt = linearised_model_004(J, w0_rad_s)
    M = np.zeros((6 + 3, 6 + 3))
    M[:6, :6], M[:6, 6:] = A * step_s, Bt * step_s
    E = scipy.linalg.expm(M)
    Phi, Gamma_tau = E[:6, :6], E[:6, 6:]
    b = np.asarray(B_O_T, dtype=np.float64)
    if b.ndim != 2 or b.shape[1] != 3 or b.shape[0] < 1:
        raise ValueError(f"B_O_T must have shape (N, 3) with N >= 1, got {b.shape}")
    mag = np.linalg.norm(b, axis=1)
    u = b / mag[:, None]
    m_avg = np.mean(-mag[:, None, None] * (np.eye(3) - u[:, :, None] * u[:, None, :]), axis=0)
    Gamma_bar = Gamma_tau @ m_avg
    Qm = np.asarray(Q, dtype=np.float64)
    Qm = Qm * np.eye(6) if Qm.ndim == 0 else (np.diag(Qm) if Qm.ndim == 1 else Qm)
    Rm = np.asarray(R, dtype=np.float64)
    Rm = np.diag(Rm) if Rm.ndim == 1 else Rm
    P = scipy.linalg.solve_discrete_are(Phi, Gamma_bar, Qm, Rm)
    K = np.linalg.solve(Rm + Gamma_bar.T @ P @ Gamma_bar, Gamma_bar.T @ P @ Phi)
    rho = float(np.max(np.abs(np.linalg.eigvals(Phi - Gamma_bar @ K))))
    return AveragedLQR(K=K, Phi=Phi, Gamma_bar=Gamma_bar, P=P, step_s=step_s, spectral_radius=rho)


def lqr_state(q_OB: ArrayLike, omega_BO_B: ArrayLike) -> NDArray:
    """x = (phi, phi', theta, theta', psi, psi') (..., 6) from q_OB (..., 4) and w_BO (..., 3)."""
    from processing.attitude.rotations import quat_to_rotvec

    th = quat_to_rotvec(q_OB)
    w = np.asarray(omega_BO_B, dtype=np.float64)
    return np.stack([th[..., 0], w[..., 0], th[..., 1], w[..., 1], th[..., 2], w[..., 2]], axis=-1)


def lqr_dipole(lqr: AveragedLQR, q_OB: ArrayLike, omega_BO_B: ArrayLike, B_B_T: ArrayLike) -> NDArray:
    """Dipole mu^B = (mu~ x B)/|B| with mu~ = -K x (004, eq. 7); vectorised, B in T. Returns (..., 3) A m^2."""
    u = -np.einsum("ij,...j->...i", lqr.K, lqr_state(q_OB, omega_BO_B))
    B = np.asarray(B_B_T, dtype=np.float64)
    return np.cross(u, B) / np.linalg.norm(B, axis=-1, keepdims=True)
