"""Attitude dynamics of paper 004 (gravity-gradient + magnetic microsatellite) in its orbital frame.

Frames (DESIGN.md): O = orbital frame of 004 (X0 along the velocity, Z0 to the Earth's centre, Y0 =
-orbit normal; :func:`processing.frames.orbital.dcm_IO_lvlh_004`), B = body (principal axes).
The paper's quaternion q (orientation of B relative to O, "R_O^B in q") is our q_OB: the paper's
matrix R_O^B, which maps O coordinates to B coordinates, equals dcm_BO = R(q_OB)^T, and its
kinematics q' = 1/2 q o (0, w_BO) is ours. Its columns c1, c2, c3 are the O axes in B coordinates
(c3 = nadir in B).

Model (004, eqs. 1-3):
    J w' + w x (J w) = tau_g + tau_m + tau_d,   w = w_BI^B (absolute body rate, in B)
    q_OB' = 1/2 q_OB o (0, w_BO),   w_BO = w_BI - dcm_BO w_OI^O,   w_OI^O = (0, -w0, 0)
    tau_g = 3 n^2 c3 x (J c3)   (n^2 = mu / r^3; = w0^2 on a circular orbit)
    tau_m = mu x B^B             (magnetorquer dipole mu [A m^2], field B [T], both in B)
Measurements (004, eq. 4): B^mes = dcm_BO B^orb + n, S^mes = dcm_BO S^orb + n.
Sun direction in the orbital frame (004, eq. 5): S^orb = dcm_OI(u, i, Omega) S^ECI.
Angles: roll phi, pitch theta, yaw psi of the 3-2-1 sequence O -> B (yaw about Z0, pitch about the
new Y, roll about the resulting X): dcm_BO = R1(phi) R2(theta) R3(psi) (the sequence of the matrix
(3) of paper 002, implemented in processing.attitude.rotations). 004 does not state its sequence; for its
small steady-state angles all sequences agree to second order.

Vectorised functions take arrays with components last. :class:`RigidBody004` is the per-step
integrator used inside the sequential loops (filters, closed-loop simulator): plain Python floats,
because numpy's per-call overhead dominates for 3- and 4-vectors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.units import MU_EARTH_M3_S2

__all__ = [
    "DISTURBANCE_004_N_M",
    "INERTIA_004_KG_M2",
    "RigidBody004",
    "dcm_OI_004",
    "gravity_gradient_torque_B",
    "magnetic_torque_B",
    "measurement_model_B",
    "omega_BO_B",
    "q_OB_from_roll_pitch_yaw_004",
    "rigid_body_derivative",
    "roll_pitch_yaw_004",
    "sun_direction_O_004",
]

INERTIA_004_KG_M2 = (51.44, 51.48, 0.76)
"""Principal moments of inertia of the 004 microsatellite with the boom deployed [kg m^2]."""
DISTURBANCE_004_N_M = (3e-6, -5e-6, 9.8e-7)
"""Amplitudes of the 004 disturbance tau_d = A sin(w0 t) [N m] (body axes)."""

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def _inertia(J: ArrayLike) -> NDArray:
    j = np.asarray(J, dtype=np.float64)
    if j.shape == (3,):
        j = np.diag(j)
    if j.shape != (3, 3):
        raise ValueError(f"inertia must be (3,) principal moments or a (3, 3) matrix, got shape {j.shape}")
    return j


def gravity_gradient_torque_B(q_OB: ArrayLike, J: ArrayLike, n2_rad2_s2: ArrayLike) -> NDArray:
    """Gravity-gradient torque 3 n^2 c3 x (J c3) [N m] in B (004, eq. 2).

    q_OB: (..., 4); J: (3,) or (3, 3) kg m^2; n2_rad2_s2: (...) = mu / r^3 [rad^2/s^2]. Returns (..., 3).
    """
    c3 = rotations.quat_rotate(rotations.quat_conjugate(q_OB), np.array([0.0, 0.0, 1.0]))
    jc3 = np.einsum("ij,...j->...i", _inertia(J), c3)
    return 3.0 * np.asarray(n2_rad2_s2, dtype=np.float64)[..., None] * np.cross(c3, jc3)


def magnetic_torque_B(mu_B_A_m2: ArrayLike, B_B_T: ArrayLike) -> NDArray:
    """Magnetorquer torque mu x B [N m] (004, eq. 3); mu (..., 3) A m^2, B (..., 3) T, both in B."""
    return np.cross(np.asarray(mu_B_A_m2, dtype=np.float64), np.asarray(B_B_T, dtype=np.float64))


def omega_BO_B(omega_BI_B: ArrayLike, q_OB: ArrayLike, omega_OI_O: ArrayLike) -> NDArray:
    """Rate of B relative to O, in B: w_BI - dcm_BO w_OI^O (004, eq. 1). All (..., 3) rad/s, q (..., 4)."""
    return np.asarray(omega_BI_B, dtype=np.float64) - rotations.quat_rotate(rotations.quat_conjugate(q_OB),
                                                                            omega_OI_O)


def measurement_model_B(q_OB: ArrayLike, v_O: ArrayLike) -> NDArray:
    """Reference vector seen in B: dcm_BO v_O (004, eq. 4, without the noise). (..., 4), (..., 3) -> (..., 3)."""
    return rotations.quat_rotate(rotations.quat_conjugate(q_OB), v_O)


def rigid_body_derivative(
    q_OB: ArrayLike, omega_BI_B: ArrayLike, torque_B_N_m: ArrayLike, J: ArrayLike, omega_OI_O: ArrayLike
) -> tuple[NDArray, NDArray]:
    """Time derivatives (q_OB', w_BI') of 004 eq. (1) for a given total torque (..., 3) [N m] in B.

    Returns ((..., 4), (..., 3)); w_OI_O (..., 3) is the orbital frame's rate, (0, -w0, 0) in 004.
    """
    j = _inertia(J)
    w = np.asarray(omega_BI_B, dtype=np.float64)
    jw = np.einsum("ij,...j->...i", j, w)
    w_dot = np.linalg.solve(j, (np.asarray(torque_B_N_m) - np.cross(w, jw))[..., None])[..., 0]
    w_bo = omega_BO_B(w, q_OB, omega_OI_O)
    zero = np.zeros(w_bo.shape[:-1] + (1,))
    q_dot = 0.5 * rotations.quat_multiply(q_OB, np.concatenate([zero, w_bo], axis=-1))
    return q_dot, w_dot


def dcm_OI_004(u_rad: ArrayLike, inc_rad: ArrayLike, raan_rad: ArrayLike) -> NDArray:
    """dcm_OI (..., 3, 3) of the 004 orbital frame from circular-orbit elements (004, eq. 5).

    Rows: X0 = transversal (along the velocity), Y0 = -orbit normal, Z0 = -radius, each in I
    coordinates; u the argument of latitude, Omega the right ascension of the ascending node in the
    inertial frame I. (Our copy of 004 prints eq. 5 garbled; this is its content, checked against
    processing.frames.orbital.dcm_IO_lvlh_004.)
    """
    u, i, o = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (u_rad, inc_rad, raan_rad)))
    cu, su, ci, si, co, so = np.cos(u), np.sin(u), np.cos(i), np.sin(i), np.cos(o), np.sin(o)
    radial = np.stack([co * cu - so * ci * su, so * cu + co * ci * su, si * su], axis=-1)
    transversal = np.stack([-co * su - so * ci * cu, -so * su + co * ci * cu, si * cu], axis=-1)
    normal = np.stack([so * si, -co * si, ci], axis=-1)
    return np.stack([transversal, -normal, -radial], axis=-2)


def sun_direction_O_004(u_rad: ArrayLike, inc_rad: ArrayLike, raan_rad: ArrayLike, s_I: ArrayLike) -> NDArray:
    """Sun unit vector in the 004 orbital frame: S^orb = dcm_OI(u, i, Omega) S^ECI (004, eq. 5). (..., 3)."""
    return np.einsum("...ij,...j->...i", dcm_OI_004(u_rad, inc_rad, raan_rad), np.asarray(s_I, dtype=np.float64))


def roll_pitch_yaw_004(q_OB: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
    """Roll phi, pitch theta, yaw psi [rad] of q_OB (3-2-1 from O to B, see module docstring).

    q_OB: (..., 4). Returns three (...) arrays; pitch in [-pi/2, pi/2], roll and yaw in (-pi, pi].
    """
    dcm_BO = rotations.quat_to_dcm(rotations.quat_conjugate(q_OB))
    pitch, yaw, roll = rotations.angles_002_from_dcm(dcm_BO)
    return roll, pitch, yaw


def q_OB_from_roll_pitch_yaw_004(roll_rad: ArrayLike, pitch_rad: ArrayLike, yaw_rad: ArrayLike) -> NDArray:
    """Canonical q_OB (..., 4) of roll, pitch, yaw [rad] (inverse of :func:`roll_pitch_yaw_004`)."""
    return rotations.quat_canonical(rotations.quat_conjugate(
        rotations.quat_from_angles_002(pitch_rad, yaw_rad, roll_rad)))


def mean_motion_sq(r_m: float) -> float:
    """n^2 = mu / r^3 [rad^2/s^2] for an orbit radius r [m]."""
    return MU_EARTH_M3_S2 / r_m**3


# ----------------------------------------------------------------------------------------------
# Scalar per-step integrator (plain floats).


def dcm_BO_columns(q: Quat) -> tuple[Vec3, Vec3, Vec3]:
    """Columns c1, c2, c3 of dcm_BO = R(q_OB)^T (the O axes in B) of a unit quaternion."""
    q0, q1, q2, q3 = q
    return (
        (1.0 - 2.0 * (q2 * q2 + q3 * q3), 2.0 * (q1 * q2 - q0 * q3), 2.0 * (q1 * q3 + q0 * q2)),
        (2.0 * (q1 * q2 + q0 * q3), 1.0 - 2.0 * (q1 * q1 + q3 * q3), 2.0 * (q2 * q3 - q0 * q1)),
        (2.0 * (q1 * q3 - q0 * q2), 2.0 * (q2 * q3 + q0 * q1), 1.0 - 2.0 * (q1 * q1 + q2 * q2)),
    )


@dataclass(frozen=True)
class RigidBody004:
    """Per-step model of 004 eq. (1)-(3) on plain floats: principal inertia (Jx, Jy, Jz) [kg m^2].

    ``derivative`` and ``rk4_step`` take q = q_OB (4 floats), w = w_BI^B (3 floats, rad/s), the
    orbital rate w0 [rad/s] (w_OI^O = (0, -w0, 0)), n2 = mu/r^3 [rad^2/s^2] and torques that are
    constant over the step: tau_B [N m] in B, tau_O [N m] in O (rotated into B with the attitude, e.g.
    the disturbance estimated in O), a dipole mu_B [A m^2] acting on a field B_O [T] given in O (so
    the magnetic torque follows the attitude); B_O may vary linearly over the step (B_O0 -> B_O1).
    """

    Jx: float
    Jy: float
    Jz: float

    @classmethod
    def from_inertia(cls, J: ArrayLike) -> RigidBody004:
        j = _inertia(J)
        off = np.abs(j - np.diag(np.diag(j))).max()
        if off > 1e-9 * np.abs(j).max():
            raise ValueError(f"004 model needs principal body axes (diagonal inertia); off-diagonal {off:g} kg m^2")
        if np.any(np.diag(j) <= 0):
            raise ValueError(f"principal moments must be > 0, got {np.diag(j).tolist()}")
        return cls(float(j[0, 0]), float(j[1, 1]), float(j[2, 2]))

    def derivative(
        self, q: Quat, w: Vec3, w0: float, n2: float, tau_B: Vec3, tau_O: Vec3, mu_B: Vec3, B_O: Vec3
    ) -> tuple[Quat, Vec3]:
        """(q_OB', w_BI') of 004 eq. (1) with the torques of eqs. (2), (3) plus tau_B and dcm_BO tau_O."""
        jx, jy, jz = self.Jx, self.Jy, self.Jz
        q0, q1, q2, q3 = q
        wx, wy, wz = w
        (c1x, c1y, c1z), (c2x, c2y, c2z), (c3x, c3y, c3z) = dcm_BO_columns(q)
        # gravity gradient 3 n^2 c3 x (J c3)
        k = 3.0 * n2
        tx = k * (jz - jy) * c3y * c3z + tau_B[0]
        ty = k * (jx - jz) * c3z * c3x + tau_B[1]
        tz = k * (jy - jx) * c3x * c3y + tau_B[2]
        # torques given in O, rotated into B
        ox, oy, oz = tau_O
        if ox or oy or oz:
            tx += ox * c1x + oy * c2x + oz * c3x
            ty += ox * c1y + oy * c2y + oz * c3y
            tz += ox * c1z + oy * c2z + oz * c3z
        mx, my, mz = mu_B
        if mx or my or mz:
            bx_o, by_o, bz_o = B_O
            bx = bx_o * c1x + by_o * c2x + bz_o * c3x
            by = bx_o * c1y + by_o * c2y + bz_o * c3y
            bz = bx_o * c1z + by_o * c2z + bz_o * c3z
            tx += my * bz - mz * by
            ty += mz * bx - mx * bz
            tz += mx * by - my * bx
        # Euler's equations for principal axes: J w' = tau - w x J w
        dwx = (tx - (jz - jy) * wy * wz) / jx
        dwy = (ty - (jx - jz) * wz * wx) / jy
        dwz = (tz - (jy - jx) * wx * wy) / jz
        # w_BO = w_BI - dcm_BO (0, -w0, 0) = w_BI + w0 c2
        px, py, pz = wx + w0 * c2x, wy + w0 * c2y, wz + w0 * c2z
        dq = (
            0.5 * (-q1 * px - q2 * py - q3 * pz),
            0.5 * (q0 * px + q2 * pz - q3 * py),
            0.5 * (q0 * py + q3 * px - q1 * pz),
            0.5 * (q0 * pz + q1 * py - q2 * px),
        )
        return dq, (dwx, dwy, dwz)

    def rk4_step(
        self,
        q: Quat,
        w: Vec3,
        dt: float,
        w0: float,
        n2: float,
        tau_B: Vec3 = (0.0, 0.0, 0.0),
        tau_O: Vec3 = (0.0, 0.0, 0.0),
        mu_B: Vec3 = (0.0, 0.0, 0.0),
        B_O0: Vec3 = (0.0, 0.0, 0.0),
        B_O1: Vec3 | None = None,
    ) -> tuple[Quat, Vec3]:
        """One classical Runge-Kutta step of length dt [s]; the quaternion is renormalised at the end."""
        b1 = B_O0 if B_O1 is None else B_O1
        bm = (0.5 * (B_O0[0] + b1[0]), 0.5 * (B_O0[1] + b1[1]), 0.5 * (B_O0[2] + b1[2]))
        f = self.derivative
        h2 = 0.5 * dt
        q0, q1, q2, q3 = q
        wx, wy, wz = w
        a1, k1 = f(q, w, w0, n2, tau_B, tau_O, mu_B, B_O0)
        a2, k2 = f((q0 + h2 * a1[0], q1 + h2 * a1[1], q2 + h2 * a1[2], q3 + h2 * a1[3]),
                   (wx + h2 * k1[0], wy + h2 * k1[1], wz + h2 * k1[2]), w0, n2, tau_B, tau_O, mu_B, bm)
        a3, k3 = f((q0 + h2 * a2[0], q1 + h2 * a2[1], q2 + h2 * a2[2], q3 + h2 * a2[3]),
                   (wx + h2 * k2[0], wy + h2 * k2[1], wz + h2 * k2[2]), w0, n2, tau_B, tau_O, mu_B, bm)
        a4, k4 = f((q0 + dt * a3[0], q1 + dt * a3[1], q2 + dt * a3[2], q3 + dt * a3[3]),
                   (wx + dt * k3[0], wy + dt * k3[1], wz + dt * k3[2]), w0, n2, tau_B, tau_O, mu_B, b1)
        h6 = dt / 6.0
        n0 = q0 + h6 * (a1[0] + 2.0 * (a2[0] + a3[0]) + a4[0])
        n1 = q1 + h6 * (a1[1] + 2.0 * (a2[1] + a3[1]) + a4[1])
        n2_ = q2 + h6 * (a1[2] + 2.0 * (a2[2] + a3[2]) + a4[2])
        n3 = q3 + h6 * (a1[3] + 2.0 * (a2[3] + a3[3]) + a4[3])
        norm = math.sqrt(n0 * n0 + n1 * n1 + n2_ * n2_ + n3 * n3)
        return (n0 / norm, n1 / norm, n2_ / norm, n3 / norm), (
            wx + h6 * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]),
            wy + h6 * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]),
            wz + h6 * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2]),
        )
