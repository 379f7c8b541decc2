"""Orbital reference frames built from a position/velocity state.

Two definitions are in use by the papers, and both are needed:

``*_003`` -- paper 003 §1.6 (Meteor-M): axis 3 along the radius vector (away from the Earth),
axis 2 along the orbital angular momentum r x v, axis 1 = axis 2 x axis 3 completes the right-handed
triad ("transversal": perpendicular to the radius, in the orbit plane, on the side of the velocity).

``*_lvlh_004`` -- paper 004 (microsatellite EKF): X0 "along the velocity", Z0 towards the Earth's
centre, Y0 completes the right-handed triad, so Y0 = -(r x v)/|r x v| (minus the orbit normal) and
w_OI = (0, -w0, 0). For a non-circular orbit the velocity is not perpendicular to the radius; here X0
is defined as Y0 x Z0, the unit transversal (local horizontal in the orbit plane, on the side of the
velocity), *not* the unit velocity vector: the two differ by the flight-path angle (at most about
e radians). In terms of the 003 axes: X0 = axis 1, Y0 = -axis 2, Z0 = -axis 3.

Matrices are returned as ``dcm_IO`` whose columns are the O axes expressed in the frame of the
input state, so that ``v_I = dcm_IO @ v_O`` (and ``q_IO`` likewise maps O coordinates to I
coordinates). The construction is purely geometric: given an Earth-fixed state (r_E, v_E, with v_E
the velocity relative to the rotating frame) the same functions return dcm_EO of the orbital frame
built from the Earth-relative velocity, which is what 003 §1.6 does with the GNSS data. Note that
this is a different frame from the one built from the inertial velocity: the Earth-relative orbit
normal is turned about the radius (in yaw) by about (w_e / n) sin i cos u, up to ~4 deg in LEO. The
frame letter of the result is the frame letter of the input, and the choice of velocity is the
caller's (for the orbital angular momentum of 003 §1.6 transform the GNSS state to inertial first).

Degenerate states (r = 0 or r parallel to v) give NaN rows; no exception is raised for them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations


class OrbitalFrameInputError(ValueError):
    """Position/velocity arrays of the wrong shape."""


def _unit(x: NDArray) -> NDArray:
    norm = np.linalg.norm(x, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = x / norm
    return np.where(norm > 0.0, out, np.nan)


def _check_state(r: ArrayLike, v: ArrayLike) -> tuple[NDArray, NDArray]:
    r_arr = np.asarray(r, dtype=float)
    v_arr = np.asarray(v, dtype=float)
    if r_arr.shape[-1:] != (3,) or v_arr.shape[-1:] != (3,):
        raise OrbitalFrameInputError(
            f"expected position and velocity of shape (..., 3), got {r_arr.shape} and {v_arr.shape}"
        )
    try:
        np.broadcast_shapes(r_arr.shape, v_arr.shape)
    except ValueError as exc:
        raise OrbitalFrameInputError(
            f"position shape {r_arr.shape} and velocity shape {v_arr.shape} do not broadcast"
        ) from exc
    return r_arr, v_arr


def _axes_003(r_I: ArrayLike, v_I: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
    r, v = _check_state(r_I, v_I)
    e3 = _unit(r)
    e2 = _unit(np.cross(r, v))
    e1 = np.cross(e2, e3)
    return e1, e2, e3


def dcm_IO_003(r_I: ArrayLike, v_I: ArrayLike) -> NDArray:
    """Orbital frame of 003 §1.6 as dcm_IO, shape (..., 3, 3).

    r_I, v_I : (..., 3) position [m] and velocity [m/s] in any frame I (inertial or Earth-fixed).
    Columns: axis 1 = axis 2 x axis 3 (transversal), axis 2 = (r x v)/|r x v| (orbit normal),
    axis 3 = r/|r| (radial, outwards). v_I = dcm_IO @ v_O.
    """
    e1, e2, e3 = _axes_003(r_I, v_I)
    return np.stack([e1, e2, e3], axis=-1)


def q_IO_003(r_I: ArrayLike, v_I: ArrayLike) -> NDArray:
    """Quaternion q_IO (..., 4), scalar first, canonical q0 >= 0, of the 003 §1.6 orbital frame."""
    return rotations.dcm_to_quat(dcm_IO_003(r_I, v_I))


def dcm_IO_lvlh_004(r_I: ArrayLike, v_I: ArrayLike) -> NDArray:
    """Orbital (LVLH) frame of paper 004 as dcm_IO, shape (..., 3, 3).

    r_I, v_I : (..., 3) position [m] and velocity [m/s] in any frame I (inertial or Earth-fixed).
    Columns: X0 = Y0 x Z0 (unit transversal; equals the unit velocity only for circular orbits),
    Y0 = -(r x v)/|r x v| (minus the orbit normal), Z0 = -r/|r| (nadir). v_I = dcm_IO @ v_O.
    """
    e1, e2, e3 = _axes_003(r_I, v_I)
    return np.stack([e1, -e2, -e3], axis=-1)


def q_IO_lvlh_004(r_I: ArrayLike, v_I: ArrayLike) -> NDArray:
    """Quaternion q_IO (..., 4), scalar first, canonical q0 >= 0, of the paper-004 LVLH frame."""
    return rotations.dcm_to_quat(dcm_IO_lvlh_004(r_I, v_I))
