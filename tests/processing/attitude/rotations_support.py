"""Shared inputs and checks of the processing.attitude.rotations tests: random and special quaternions, scipy
as the outside reference, and rotation/angle comparisons independent of the module under test."""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy.spatial.transform import Rotation

RNG_SEED = 20240601
N = 1000
_RNG = np.random.default_rng(RNG_SEED)
Q_RANDOM = _RNG.normal(size=(N, 4))  # normalised Gaussian 4-vectors: uniform random rotations
Q_RANDOM /= np.linalg.norm(Q_RANDOM, axis=-1, keepdims=True)
V_RANDOM = _RNG.normal(scale=3.0, size=(N, 3))


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _q_axis_angle(axis, angle):
    """Hand-built quaternion (cos(a/2), sin(a/2) n), independent of the module under test."""
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * _unit(axis)])


SPECIAL = {
    "identity": np.array([1.0, 0.0, 0.0, 0.0]),
    "identity_negative": np.array([-1.0, 0.0, 0.0, 0.0]),
    "x180": np.array([0.0, 1.0, 0.0, 0.0]),
    "y180": np.array([0.0, 0.0, 1.0, 0.0]),
    "z180": np.array([0.0, 0.0, 0.0, 1.0]),
    "minus_x180": np.array([0.0, -1.0, 0.0, 0.0]),
    "diag180": np.concatenate([[0.0], _unit([1.0, 1.0, 1.0])]),
    "z90": _q_axis_angle([0, 0, 1], math.pi / 2),
    "tiny_1e-12": _q_axis_angle([1.0, -2.0, 3.0], 1e-12),
    "near180_179.9999deg": _q_axis_angle([-2.0, 1.0, 0.5], math.radians(179.9999)),
}
Q_SPECIAL = np.array(list(SPECIAL.values()))


def scipy_rot(q):
    return Rotation.from_quat(q, scalar_first=True)


def scipy_euler(q, seq):
    """scipy's Euler angles; at gimbal lock (z90 for YZX) scipy warns and, like us, sets the third to 0."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "Gimbal lock detected", UserWarning)
        return scipy_rot(q).as_euler(seq)


def assert_angles_close(a, b, atol):
    """Angles equal modulo 2 pi (scipy returns -pi or pi at the boundary)."""
    diff = np.remainder(np.asarray(a) - np.asarray(b) + np.pi, 2 * np.pi) - np.pi
    assert np.all(np.abs(diff) <= atol), f"max error {np.abs(diff).max():.3g} > {atol:g}"


def assert_same_rotation(q1, q2, atol=1e-14):
    """q1 == +-q2 row by row."""
    q1, q2 = np.broadcast_arrays(np.asarray(q1, dtype=float), np.asarray(q2, dtype=float))
    err = np.minimum(np.abs(q1 - q2).max(axis=-1), np.abs(q1 + q2).max(axis=-1))
    assert np.all(err <= atol), f"max error {err.max():.3g} > {atol:g}"
