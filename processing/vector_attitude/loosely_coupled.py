"""Loosely coupled attitude from the antenna axis and the magnetometer (002, eqs. 10-14; Kramlikh 2008).

The GNSS antenna lies along the body axis X1. Row 1 of 002's matrix (3) (our dcm_BO, see
processing.attitude.rotations.dcm_from_angles_002) is the X1 axis in the orbital frame O,
(cos J cos psi, cos J sin psi, -sin J), so the antenna direction a_O from visibility (eqs. 5-7) gives
the first approximation of pitch and yaw:

    J0 = -asin(a_z),  psi0 = atan2(a_y, a_x).

Stage 1 (eqs. 11-12): refine (J, psi) so that the first magnetometer component matches,
rho(J, psi) = h_x1 - (cos J cos psi h_x2 + cos J sin psi h_y2 - sin J h_z2) = 0 (first row of eq. 10,
i.e. of matrix (3) applied to the model field h_2 in O). One equation in two unknowns: the minimum
of Phi = rho^2 (eq. 11) is a whole curve, and the Hessian of Phi there has rank one, so Newton's
method on the gradient system (12) is singular. We take its well-posed limit, the minimum-norm
Newton (Gauss-Newton) step for rho = 0, the norm measured on the sphere of X1 directions
(dJ^2 + cos^2 J dpsi^2): dJ = -rho a11 / (a11^2 + a12^2), dpsi = rho a12 / (cos J (a11^2 + a12^2)),
since grad(rho) = (a11, -cos J a12) with a11, a12 of eq. 13. It converges to (nearly) the point of
the curve nearest to the antenna direction: the antenna is kept as far as the magnetometer allows.

Stage 2 (eqs. 13-14): roll in closed form from the second and third rows,
h_y1 = a11 sin phi + a12 cos phi, h_z1 = -a12 sin phi + a11 cos phi with
a11 = sin J cos psi h_x2 + sin J sin psi h_y2 + cos J h_z2, a12 = -sin psi h_x2 + cos psi h_y2,
sin phi = (h_y1 a22 - h_z1 a12) / (a11^2 + a12^2), cos phi = (h_z1 a11 - h_y1 a21) / (a11^2 + a12^2)
with a21 = -a12, a22 = a11. These are the rows of matrix (3); eq. (10) as printed carries minus signs
on the h_z2 terms of rows 2 and 3 that contradict (3) and orthogonality, and the code follows (3).

Measured and model fields are used as unit vectors (the magnitudes differ by the field-model error).
An antenna on another body axis a_B is handled through the body frame B' whose X1' is a_B (the
shortest rotation taking a_B to X1); the angles returned are those of B'.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations

MAX_ITERATIONS = 20
TOLERANCE = 1e-12
RHO_ACCEPT = 1e-9
"""Largest |rho| (unit vectors) at which stage 1 counts as converged."""
MIN_GRADIENT = 1e-9
"""Below this |grad rho| the field is along the antenna axis: pitch/yaw cannot be refined."""
MIN_ROLL_DENOMINATOR = 1e-6
"""a11^2 + a12^2 below this: the field is along X1 and the roll is undetermined."""


class LooselyCoupledError(ValueError):
    """Inputs of the wrong shape."""


@dataclass(frozen=True)
class LooselyCoupledResult:
    """q_BO (T, 4) (dcm_BO = matrix (3)); pitch/yaw/roll_rad (T,) of the antenna frame B' (of B when
    the antenna is X1); iterations (T,) Newton steps; residual (T,) |rho| at the end (unit vectors);
    ok (T,) converged and roll determined (q NaN where not)."""

    q_BO: NDArray[np.float64]
    pitch_rad: NDArray[np.float64]
    yaw_rad: NDArray[np.float64]
    roll_rad: NDArray[np.float64]
    iterations: NDArray[np.int64]
    residual: NDArray[np.float64]
    ok: NDArray[np.bool_]


def q_antenna_frame(antenna_B: ArrayLike) -> NDArray[np.float64]:
    """q_B'B (4,) of the shortest rotation taking the unit antenna axis a_B to X1' = (1, 0, 0)."""
    a = np.asarray(antenna_B, dtype=np.float64)
    a = a / np.linalg.norm(a)
    x = np.array([1.0, 0.0, 0.0])
    c = float(a @ x)
    if c < -1.0 + 1e-12:
        return np.array([0.0, 0.0, 0.0, 1.0])  # 180 deg about z
    axis = np.cross(a, x)
    q = np.concatenate([[1.0 + c], axis])
    return q / np.linalg.norm(q)


def loosely_coupled(antenna_O: ArrayLike, field_B: ArrayLike, field_O: ArrayLike, antenna_B: ArrayLike = (1, 0, 0),
                    ) -> LooselyCoupledResult:
    """Attitude q_BO from the antenna direction in O, the measured field in B and the model field in O.

    antenna_O: (T, 3) antenna axis in the orbital frame of 002 (eqs. 5-7); field_B: (T, 3) measured
    field in the body frame (any unit); field_O: (T, 3) model field in O (002 eq. 2 dipole or IGRF);
    antenna_B: (3,) antenna axis in the body frame (002: X1). 002 eqs. 10-14, see the module docstring.
    """
    a_O = np.asarray(antenna_O, dtype=np.float64)
    hb = np.asarray(field_B, dtype=np.float64)
    ho = np.asarray(field_O, dtype=np.float64)
    if a_O.ndim != 2 or a_O.shape[1] != 3 or hb.shape != a_O.shape or ho.shape != a_O.shape:
        raise LooselyCoupledError(f"expected antenna_O, field_B, field_O of shape (T, 3); got {a_O.shape}, "
                                  f"{hb.shape}, {ho.shape}")
    q_Bp_B = q_antenna_frame(antenna_B)
    with np.errstate(invalid="ignore", divide="ignore"):
        a_O = a_O / np.linalg.norm(a_O, axis=1, keepdims=True)
        h1 = rotations.quat_rotate(q_Bp_B, hb / np.linalg.norm(hb, axis=1, keepdims=True))
        h2 = ho / np.linalg.norm(ho, axis=1, keepdims=True)
    hx2, hy2, hz2 = h2[:, 0], h2[:, 1], h2[:, 2]
    hx1, hy1, hz1 = h1[:, 0], h1[:, 1], h1[:, 2]
    pitch = -np.arcsin(np.clip(a_O[:, 2], -1.0, 1.0))
    yaw = np.arctan2(a_O[:, 1], a_O[:, 0])
    iterations = np.zeros(a_O.shape[0], dtype=np.int64)
    rho = np.full(a_O.shape[0], np.nan)
    active = np.isfinite(pitch) & np.isfinite(hx1) & np.isfinite(hx2)
    for _ in range(MAX_ITERATIONS):
        cj, sj, cy, sy = np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
        rho = hx1 - (cj * cy * hx2 + cj * sy * hy2 - sj * hz2)
        a11 = sj * cy * hx2 + sj * sy * hy2 + cj * hz2  # d rho / d J
        a12 = -sy * hx2 + cy * hy2
        g2 = a11 * a11 + a12 * a12  # |grad rho|^2 in the metric of the sphere, dJ^2 + cos^2 J dpsi^2
        step = active & (np.abs(rho) > TOLERANCE) & (g2 > MIN_GRADIENT**2) & (np.abs(cj) > MIN_GRADIENT)
        if not np.any(step):
            break
        with np.errstate(invalid="ignore", divide="ignore"):
            k = np.where(step, rho / np.where(step, g2, 1.0), 0.0)
            pitch = pitch - k * a11
            yaw = yaw + np.where(step, k * a12 / np.where(step, cj, 1.0), 0.0)
        iterations += step
    cj, sj, cy, sy = np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    rho = hx1 - (cj * cy * hx2 + cj * sy * hy2 - sj * hz2)
    a11 = sj * cy * hx2 + sj * sy * hy2 + cj * hz2
    a12 = -sy * hx2 + cy * hy2
    a21, a22 = -a12, a11
    den = a11 * a11 + a12 * a12
    with np.errstate(invalid="ignore", divide="ignore"):
        s_phi = (hy1 * a22 - hz1 * a12) / den  # eq. 14
        c_phi = (hz1 * a11 - hy1 * a21) / den
    roll = np.arctan2(s_phi, c_phi)
    ok = active & (den > MIN_ROLL_DENOMINATOR) & (np.abs(rho) <= RHO_ACCEPT)
    dcm_BpO = rotations.dcm_from_angles_002(pitch, yaw, roll)
    q_BpO = rotations.dcm_to_quat(np.where(ok[:, None, None], dcm_BpO, np.eye(3)))
    q_BO = rotations.quat_canonical(rotations.quat_multiply(rotations.quat_conjugate(q_Bp_B), q_BpO))
    q_BO = np.where(ok[:, None], q_BO, np.nan)
    return LooselyCoupledResult(q_BO=q_BO, pitch_rad=pitch, yaw_rad=yaw, roll_rad=roll, iterations=iterations,
                                residual=np.abs(rho), ok=ok)
