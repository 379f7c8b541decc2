"""processing.attitude.rotations: every public function on scalars and arrays alike, broadcasting, bad input, and
the per-component forms pinned bit for bit against the vector forms (and scipy)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from processing.attitude import rotations as rot
from processing.attitude.rotations import RotationValueError

from .rotations_support import Q_RANDOM, Q_SPECIAL, V_RANDOM, scipy_rot

# ---------------------------------------------------------------- shapes and errors

_Q = Q_RANDOM[:12]
_V = V_RANDOM[:12]
_A = np.linspace(-3.0, 3.0, 12)
_DCM = scipy_rot(_Q).as_matrix()
VECTORISED = {
    "quat_multiply": (rot.quat_multiply, (_Q, np.roll(_Q, 1, axis=0))),
    "quat_conjugate": (rot.quat_conjugate, (_Q,)),
    "quat_normalize": (rot.quat_normalize, (3.0 * _Q,)),
    "quat_canonical": (rot.quat_canonical, (np.concatenate([-_Q[:8], Q_SPECIAL[:4]]),)),
    "quat_rotate": (rot.quat_rotate, (_Q, _V)),
    "quat_to_dcm": (rot.quat_to_dcm, (_Q,)),
    "dcm_to_quat": (rot.dcm_to_quat, (_DCM,)),
    "quat_from_axis_angle": (rot.quat_from_axis_angle, (_V, _A)),
    "rotvec_to_quat": (rot.rotvec_to_quat, (_V,)),
    "quat_to_rotvec": (rot.quat_to_rotvec, (_Q,)),
    "quat_to_mrp": (rot.quat_to_mrp, (_Q,)),
    "mrp_to_quat": (rot.mrp_to_quat, (_V,)),
    "mrp_shadow": (rot.mrp_shadow, (_V,)),
    "mrp_switch": (rot.mrp_switch, (_V / 5.0,)),
    "quat_angle": (rot.quat_angle, (_Q,)),
    "angle_between": (rot.angle_between, (_Q, np.roll(_Q, 1, axis=0))),
    "skew": (rot.skew, (_V,)),
    "quat_from_pitch_yaw_roll": (rot.quat_from_pitch_yaw_roll, (_A, _A / 2, -_A)),
    "pitch_yaw_roll_from_quat": (rot.pitch_yaw_roll_from_quat, (_Q,)),
    "dcm_from_angles_002": (rot.dcm_from_angles_002, (_A / 2, _A, -_A)),
    "quat_from_angles_002": (rot.quat_from_angles_002, (_A / 2, _A, -_A)),
    "angles_002_from_dcm": (rot.angles_002_from_dcm, (_DCM,)),
    "quat_from_ccsds": (rot.quat_from_ccsds, (_Q,)),
    "quat_to_ccsds": (rot.quat_to_ccsds, (_Q,)),
}


def test_every_public_function_is_covered():
    assert set(VECTORISED) == set(rot.__all__) - {"RotationValueError"}


@pytest.mark.parametrize("name", sorted(VECTORISED))
def test_scalar_and_array_inputs_agree(name):
    func, args = VECTORISED[name]
    batch = func(*args)
    batch_2d = func(*(np.stack([a, a]) for a in args))  # an extra leading dimension
    for i in range(len(args[0])):
        single = func(*(a[i] for a in args))
        assert_allclose(single, _row(batch, i), rtol=0, atol=1e-15)
    assert_allclose(_row(batch_2d, 1), batch, rtol=0, atol=0)


def _row(result, i):
    if isinstance(result, tuple):
        return tuple(np.asarray(r)[i] for r in result)
    return result[i]


def test_broadcasting():
    assert_allclose(rot.quat_rotate(_Q[0], _V), rot.quat_rotate(np.tile(_Q[0], (12, 1)), _V), atol=0)
    assert_allclose(rot.quat_multiply(_Q[:, None, :], _Q[None, :3, :])[:, 2], rot.quat_multiply(_Q, _Q[2]), atol=0)
    assert rot.quat_from_axis_angle([0, 0, 1], _A).shape == (12, 4)
    assert rot.quat_from_pitch_yaw_roll(_A, 0.0, 0.0).shape == (12, 4)
    assert rot.quat_to_dcm(_Q.reshape(3, 4, 4)).shape == (3, 4, 3, 3)


@pytest.mark.parametrize(
    ("func", "args", "match"),
    [
        (rot.quat_multiply, (np.zeros((5, 3)), _Q[0]), r"p must have shape \(\.\.\., 4\), got \(5, 3\)"),
        (rot.quat_multiply, (np.ones((2, 4)), np.ones((3, 4))), r"p and q must have broadcastable"),
        (rot.quat_rotate, (_Q[0], np.zeros(4)), r"v_B must have shape \(\.\.\., 3\), got \(4,\)"),
        (rot.quat_to_dcm, (np.zeros((5, 3)),), r"q_AB must have shape \(\.\.\., 4\), got \(5, 3\)"),
        (rot.dcm_to_quat, (np.eye(4),), r"dcm_AB must have shape \(\.\.\., 3, 3\), got \(4, 4\)"),
        (rot.dcm_to_quat, (np.zeros(9),), r"dcm_AB must have shape \(\.\.\., 3, 3\), got \(9,\)"),
        (rot.quat_from_axis_angle, (np.zeros(4), 1.0), r"axis must have shape \(\.\.\., 3\), got \(4,\)"),
        (rot.quat_from_axis_angle, (np.ones((2, 3)), np.ones(3)), r"axis and angle_rad must have broadcast"),
        (rot.rotvec_to_quat, ([1.0, 2.0],), r"rotvec_rad must have shape \(\.\.\., 3\), got \(2,\)"),
        (rot.mrp_to_quat, (np.zeros((2, 4)),), r"sigma must have shape \(\.\.\., 3\), got \(2, 4\)"),
        (rot.skew, (1.0,), r"v must have shape \(\.\.\., 3\), got \(\)"),
        (rot.pitch_yaw_roll_from_quat, (np.zeros(3),), r"q_OB must have shape \(\.\.\., 4\), got \(3,\)"),
        (rot.angles_002_from_dcm, (np.zeros((3, 4)),), r"dcm_BO must have shape \(\.\.\., 3, 3\), got \(3, 4\)"),
        (rot.quat_from_ccsds, (np.zeros(5),), r"q_scalar_last must have shape \(\.\.\., 4\), got \(5,\)"),
        (rot.quat_from_pitch_yaw_roll, (np.zeros(2), np.zeros(3), 0.0), r"must have broadcastable"),
        (rot.quat_normalize, (np.zeros(4),), r"q must have non-zero norm"),
        (rot.quat_to_dcm, ([[1, 0, 0, 0], [0, 0, 0, 0]],), r"q_AB must have non-zero norm.*1 of 2 rows.*\(1,\)"),
        (rot.quat_from_axis_angle, (np.zeros(3), 1.0), r"axis must have non-zero norm"),
        (rot.angle_between, (_Q[0], np.zeros(4)), r"q_AB2 must have non-zero norm"),
    ],
)
def test_bad_input_raises(func, args, match):
    with pytest.raises(RotationValueError, match=match):
        func(*args)
    assert issubclass(RotationValueError, ValueError)


@pytest.mark.parametrize("shapes", [((4,), (4,)), ((500, 4), (4,)), ((1, 4), (300, 4)), ((7, 1, 4), (5, 4))])
def test_quat_multiply_is_the_vector_form_bit_for_bit(shapes):
    """The per-component product gives the same bits as s = p0 q0 - p_v . q_v, v = p0 q_v + q0 p_v + p_v x q_v
    (numpy's sum and cross), for broadcast shapes, and agrees with scipy's composition."""
    rng = np.random.default_rng(5)
    p, q = rng.normal(size=shapes[0]), rng.normal(size=shapes[1])
    p0, pv, q0, qv = p[..., :1], p[..., 1:], q[..., :1], q[..., 1:]
    vector_form = np.concatenate([p0 * q0 - np.sum(pv * qv, axis=-1, keepdims=True),
                                  p0 * qv + q0 * pv + np.cross(pv, qv)], axis=-1)
    got = rot.quat_multiply(p, q)
    assert got.shape == vector_form.shape
    assert np.array_equal(got, vector_form)
    pu, qu = p / np.linalg.norm(p, axis=-1, keepdims=True), q / np.linalg.norm(q, axis=-1, keepdims=True)
    ref = (Rotation.from_quat(np.broadcast_to(pu, got.shape).reshape(-1, 4), scalar_first=True)
           * Rotation.from_quat(np.broadcast_to(qu, got.shape).reshape(-1, 4), scalar_first=True))
    np.testing.assert_allclose(rot.quat_canonical(rot.quat_multiply(pu, qu)).reshape(-1, 4),
                               rot.quat_canonical(ref.as_quat(scalar_first=True)), atol=1e-14)


@pytest.mark.parametrize("shape", [(4,), (3000, 4), (5, 7, 4)])
def test_quat_to_dcm_is_the_stacked_formula_bit_for_bit(shape):
    """Written element by element, the matrix has the bits of the nested-list form stacked, and is scipy's matrix."""
    q = np.random.default_rng(7).normal(size=shape)
    u = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(u, -1, 0)
    rows = [[1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)]]
    stacked = np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)
    got = rot.quat_to_dcm(q)
    assert got.shape == (*shape[:-1], 3, 3) and got.flags.c_contiguous
    assert np.array_equal(got, stacked)
    ref = Rotation.from_quat(u.reshape(-1, 4), scalar_first=True).as_matrix()
    np.testing.assert_allclose(got.reshape(-1, 3, 3), ref, atol=1e-15)


@pytest.mark.parametrize("shapes", [((4,), (140_000, 3)), ((300, 4), (300, 3)), ((5, 1, 4), (7, 3))])
def test_quat_rotate_is_the_vector_form_bit_for_bit(shapes):
    """Per component, the rotation has the bits of v + q0 t + u x t, t = 2 u x v (numpy's cross) for broadcast
    shapes (one quaternion rotating a day of rates, as the gyro fit uses it, included), and is scipy's rotation."""
    rng = np.random.default_rng(6)
    q, v = rng.normal(size=shapes[0]), rng.normal(size=shapes[1]) * 1e-3
    u = q / np.linalg.norm(q, axis=-1, keepdims=True)
    t = 2.0 * np.cross(u[..., 1:], v)
    vector_form = v + u[..., :1] * t + np.cross(u[..., 1:], t)
    got = rot.quat_rotate(q, v)
    assert got.shape == vector_form.shape and np.array_equal(got, vector_form)
    full = np.array(np.broadcast_to(u, (*got.shape[:-1], 4))).reshape(-1, 4)
    ref = Rotation.from_quat(full, scalar_first=True).apply(np.array(np.broadcast_to(v, got.shape)).reshape(-1, 3))
    np.testing.assert_allclose(got.reshape(-1, 3), ref, atol=1e-17)
