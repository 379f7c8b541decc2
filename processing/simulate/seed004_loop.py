"""The closed loop of the seed-004 simulator (processing.simulate.seed004), step by step: the sensors
measure the true attitude, the on-board filter (004's EKF or the MEKF, or the truth) estimates it,
the energy or averaged-LQR controller sets the dipole held over the step, and RK4 propagates the truth
(004 eqs. 1-3) through the step. A sequential algorithm: one Python iteration per control step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from processing.attitude.rigid_body import RigidBody004, dcm_BO_columns, q_OB_from_roll_pitch_yaw_004
from processing.gyroless.ekf import FilterTuning
from processing.gyroless.filtering import FILTERS, FilterKind, initial_covariance, triad_q_OB
from processing.units import RAD_PER_DEG

__all__ = ["Environment004", "History", "LoopSetup", "Sensors004", "closed_loop", "rotvec", "unit"]


def rotvec(q: tuple[float, ...]) -> tuple[float, float, float]:
    """Rotation vector (rad) of a unit quaternion (4 floats), angle in [0, pi]."""
    q0, q1, q2, q3 = q
    if q0 < 0.0:
        q0, q1, q2, q3 = -q0, -q1, -q2, -q3
    s = math.sqrt(q1 * q1 + q2 * q2 + q3 * q3)
    k = 2.0 * math.atan2(s, q0) / s if s > 1e-12 else 2.0 / q0
    return (k * q1, k * q2, k * q3)


def unit(v: NDArray) -> NDArray:
    """v / |v| along the last axis."""
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass(frozen=True)
class Environment004:
    """Orbit and environment on the step grid (K): circular orbit r_I, v_I, r_E, v_E (K, 3), dcm_IO
    (K, 3, 3), field B_O (K, 3) nT, Sun direction s_O (K, 3), sunlit fraction and sun-sensor visibility
    (K,); mean motion w0, inclination, RAAN, semi-major axis."""

    r_I: NDArray
    v_I: NDArray
    r_E: NDArray
    v_E: NDArray
    dcm_IO: NDArray
    B_O: NDArray
    s_O: NDArray
    sunlit: NDArray
    sun_visible: NDArray
    w0: float
    inc: float
    raan: float
    a_m: float


@dataclass(frozen=True)
class Sensors004:
    """Sensor frames (q_BM, q_BS canonical; dcm_MB, dcm_SB) and the per-step noise drawn up front, so
    that it does not depend on the controller: magnetometer noise (K, 3) nT, Sun-direction noise
    rotations (K, 3, 3), and the field the magnetometer sees with the model error (K, 3) nT."""

    q_BM: NDArray
    q_BS: NDArray
    dcm_MB: NDArray
    dcm_SB: NDArray
    mag_noise: NDArray
    R_sun_noise: NDArray
    B_O_meas: NDArray


@dataclass(frozen=True)
class LoopSetup:
    """What the closed loop needs: the body, inertia, grid and step, the environment and sensors, the
    disturbance (amplitude and its value at the first substep of every step), the controller, the
    on-board estimator and its noise settings, the gains and the dipole limit."""

    body: RigidBody004
    J: NDArray
    t_s: NDArray
    step_s: float
    substeps: int
    w0: float
    env: Environment004
    sensors: Sensors004
    tau_all: NDArray
    amp: NDArray
    controller: str
    estimator: str
    tuning: FilterTuning
    magnetometer_noise_nT: float
    sigma_s: float
    energy_beta: float
    energy_alpha: float
    K_gain: NDArray | None
    max_dipole_A_m2: float | None


@dataclass(frozen=True)
class History:
    """The closed loop per step (K): true q_OB, w_BI^B, the dipole held over the step, the on-board
    q_OB and w_BO, the magnetometer (K, 3) nT and sun-sensor (K, 3, NaN when absent) samples."""

    q: NDArray
    w: NDArray
    mu: NDArray
    q_est: NDArray
    w_est: NDArray
    b_M: NDArray
    s_S: NDArray


@dataclass(frozen=True)
class Measurement:
    """One step's measurements: magnetometer b_M (nT, frame M), the measured field in B (T) and its
    norm, the sun-sensor sample s_S and its direction in B (None when not visible)."""

    b_M: NDArray
    B_B_T: NDArray
    B_norm: float
    s_S: NDArray | None
    s_B: NDArray | None


def _measure(loop: LoopSetup, k: int, cols: tuple[tuple[float, ...], ...], ident_M: bool) -> Measurement:
    """Magnetometer and Sun sensor at t_k from the true attitude (columns of dcm_BO)."""
    sen = loop.sensors
    c1, c2, c3 = cols
    bx, by, bz = sen.B_O_meas[k].tolist()
    b_B_true = np.array([bx * c1[0] + by * c2[0] + bz * c3[0], bx * c1[1] + by * c2[1] + bz * c3[1],
                         bx * c1[2] + by * c2[2] + bz * c3[2]])
    b_M = (b_B_true if ident_M else sen.dcm_MB @ b_B_true) + sen.mag_noise[k].tolist()
    B_B_meas_T = (b_M if ident_M else sen.dcm_MB.T @ b_M) * 1e-9
    B_norm = math.sqrt(float(B_B_meas_T @ B_B_meas_T))
    if not loop.env.sun_visible[k]:
        return Measurement(b_M, B_B_meas_T, B_norm, None, None)
    sx, sy, sz = loop.env.s_O[k].tolist()
    s_true = np.array([sx * c1[0] + sy * c2[0] + sz * c3[0], sx * c1[1] + sy * c2[1] + sz * c3[1],
                       sx * c1[2] + sy * c2[2] + sz * c3[2]])
    s_S = sen.dcm_SB @ (sen.R_sun_noise[k] @ s_true)
    return Measurement(b_M, B_B_meas_T, B_norm, s_S, sen.dcm_SB.T @ s_S)


def _onboard_filter(loop: LoopSetup, k: int, est: Any, m: Measurement, b_O_unit: NDArray,
                    prev_torque_B: NDArray) -> Any:
    """The on-board filter after the update at t_k: initialised (TRIAD) at the first step, else
    predicted over the step with last step's control torque."""
    w0, s_O = loop.w0, loop.env.s_O
    b_B_unit = m.B_B_T / m.B_norm
    sigma_b = max(loop.magnetometer_noise_nT, 1.0) * 1e-9 / m.B_norm
    if est is None:
        q_init = (triad_q_OB(b_O_unit[k], s_O[k], b_B_unit, m.s_B) if m.s_B is not None
                  else np.array([1.0, 0.0, 0.0, 0.0]))
        c2i = np.array(dcm_BO_columns(tuple(q_init))[1])
        attitude_sigma_rad = (10 if m.s_B is not None else 60) * RAD_PER_DEG
        P0 = initial_covariance(cast(FilterKind, loop.estimator), q_init, attitude_sigma_rad, 2e-3, 1e-5)
        est = FILTERS[loop.estimator](loop.J, q_init, -w0 * c2i, P0, loop.tuning)
    else:
        est.predict(loop.step_s, w0, w0 * w0, prev_torque_B)
    est.update(b_B_unit, b_O_unit[k], sigma_b, m.s_B, s_O[k] if m.s_B is not None else None, loop.sigma_s)
    return est


def _dipole(loop: LoopSetup, q_est: tuple[float, ...], w_bo: tuple[float, ...],
            m: Measurement) -> tuple[float, float, float]:
    """The controller's dipole (A m^2, held over the step; 004 eq. 6 or 7), saturated if a limit is set."""
    Bx, By, Bz = float(m.B_B_T[0]), float(m.B_B_T[1]), float(m.B_B_T[2])
    mu: tuple[float, float, float]
    if loop.controller == "energy":
        sgn = 1.0 if q_est[0] >= 0.0 else -1.0
        vx = loop.energy_beta * w_bo[0] + loop.energy_alpha * sgn * q_est[1]
        vy = loop.energy_beta * w_bo[1] + loop.energy_alpha * sgn * q_est[2]
        vz = loop.energy_beta * w_bo[2] + loop.energy_alpha * sgn * q_est[3]
        mu = (vy * Bz - vz * By, vz * Bx - vx * Bz, vx * By - vy * Bx)
    elif loop.controller == "lqr":
        assert loop.K_gain is not None
        th = rotvec(q_est)
        u_t = -loop.K_gain @ np.array([th[0], w_bo[0], th[1], w_bo[1], th[2], w_bo[2]])
        ux, uy, uz = float(u_t[0]) / m.B_norm, float(u_t[1]) / m.B_norm, float(u_t[2]) / m.B_norm
        mu = (uy * Bz - uz * By, uz * Bx - ux * Bz, ux * By - uy * Bx)
    else:
        mu = (0.0, 0.0, 0.0)
    limit = loop.max_dipole_A_m2
    if limit is not None:
        peak = max(abs(mu[0]), abs(mu[1]), abs(mu[2]))
        if peak > limit:
            mu = (mu[0] * (limit / peak), mu[1] * (limit / peak), mu[2] * (limit / peak))
    return mu


def _propagate_truth(loop: LoopSetup, k: int, q: tuple[float, ...], w: tuple[float, ...],
                     mu: tuple[float, float, float]) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The truth over [t_k, t_k+1): RK4 substeps, field linear within the step, disturbance at midpoints."""
    B0, B1 = (loop.env.B_O[k] * 1e-9).tolist(), (loop.env.B_O[k + 1] * 1e-9).tolist()
    substeps, w0 = loop.substeps, loop.w0
    h = loop.step_s / substeps
    for j in range(substeps):
        tau = loop.tau_all[k].tolist() if j == 0 else (loop.amp * math.sin(w0 * (loop.t_s[k] + (j + 0.5) * h))).tolist()
        fa, fb = j / substeps, (j + 1) / substeps
        Ba = ((1 - fa) * B0[0] + fa * B1[0], (1 - fa) * B0[1] + fa * B1[1], (1 - fa) * B0[2] + fa * B1[2])
        Bb = ((1 - fb) * B0[0] + fb * B1[0], (1 - fb) * B0[1] + fb * B1[1], (1 - fb) * B0[2] + fb * B1[2])
        q, w = loop.body.rk4_step(q, w, h, w0, w0 * w0, tau_B=tuple(tau), mu_B=mu, B_O0=Ba, B_O1=Bb)  # type: ignore
    return q, w


def closed_loop(loop: LoopSetup, initial_angles_deg: tuple[float, float, float],
                 initial_omega_BO_rad_s: tuple[float, float, float]) -> History:
    """The closed loop, step by step (a sequential algorithm): measure, estimate on board, control, propagate."""
    K, w0 = loop.t_s.size, loop.w0
    q = tuple(float(x) for x in q_OB_from_roll_pitch_yaw_004(*(np.asarray(initial_angles_deg) * RAD_PER_DEG)))
    c2 = dcm_BO_columns(q)[1]  # type: ignore[arg-type]
    w = tuple(float(initial_omega_BO_rad_s[i]) - w0 * c2[i] for i in range(3))
    q_hist, w_hist, mu_hist = np.empty((K, 4)), np.empty((K, 3)), np.zeros((K, 3))
    q_est_hist, w_est_hist = np.empty((K, 4)), np.empty((K, 3))
    b_M_all, s_S_all = np.empty((K, 3)), np.full((K, 3), np.nan)
    b_O_unit = unit(loop.env.B_O)
    ident_M = bool(np.allclose(loop.sensors.q_BM, [1.0, 0.0, 0.0, 0.0]))
    est = None
    prev_torque_B = np.zeros(3)
    for k in range(K):
        q_hist[k], w_hist[k] = q, w
        cols = dcm_BO_columns(q)  # type: ignore[arg-type]
        m = _measure(loop, k, cols, ident_M)
        b_M_all[k] = m.b_M
        if m.s_S is not None:
            s_S_all[k] = m.s_S
        if loop.estimator == "truth":
            q_est, w_bo = q, (w[0] + w0 * cols[1][0], w[1] + w0 * cols[1][1], w[2] + w0 * cols[1][2])
        else:
            est = _onboard_filter(loop, k, est, m, b_O_unit, prev_torque_B)
            q_est, w_bo = est.q, est.omega_BO_B(w0)
        q_est_hist[k], w_est_hist[k] = q_est, w_bo
        mu = _dipole(loop, q_est, w_bo, m)
        mu_hist[k] = mu
        Bx, By, Bz = float(m.B_B_T[0]), float(m.B_B_T[1]), float(m.B_B_T[2])
        prev_torque_B = np.array([mu[1] * Bz - mu[2] * By, mu[2] * Bx - mu[0] * Bz, mu[0] * By - mu[1] * Bx])
        if k < K - 1:
            q, w = _propagate_truth(loop, k, q, w, mu)
    return History(q_hist, w_hist, mu_hist, q_est_hist, w_est_hist, b_M_all, s_S_all)
