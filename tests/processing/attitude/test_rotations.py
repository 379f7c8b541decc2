"""Tests of processing.attitude.rotations: golden values from scipy, the papers' formulas written out by hand,
and hypothesis properties (round trips and invariants). CCSDS ADM 2.0 values: test_rotations_ccsds.py; shapes,
broadcasting, errors and the per-component forms: test_rotations_shapes.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial.transform import Rotation

from processing.attitude import rotations as rot

from .rotations_support import (
    Q_RANDOM,
    Q_SPECIAL,
    SPECIAL,
    V_RANDOM,
    N,
    _unit,
    assert_angles_close,
    assert_same_rotation,
    scipy_euler,
    scipy_rot,
)

# ---------------------------------------------------------------- golden tests against scipy


@pytest.mark.parametrize("qs", [Q_RANDOM, Q_SPECIAL], ids=["random", "special"])
class TestAgainstScipy:
    def test_product(self, qs):
        p = np.roll(qs, 1, axis=0)
        assert_allclose(
            rot.quat_multiply(p, qs), (scipy_rot(p) * scipy_rot(qs)).as_quat(scalar_first=True), rtol=0, atol=1e-15
        )

    def test_rotate(self, qs):
        v = V_RANDOM[: len(qs)]
        assert_allclose(rot.quat_rotate(qs, v), scipy_rot(qs).apply(v), rtol=0, atol=1e-14)

    def test_dcm(self, qs):
        dcm = scipy_rot(qs).as_matrix()
        assert_allclose(rot.quat_to_dcm(qs), dcm, rtol=0, atol=1e-15)
        q = rot.dcm_to_quat(dcm)
        assert np.all(q[:, 0] >= 0.0)
        assert_same_rotation(q, scipy_rot(qs).as_quat(canonical=True, scalar_first=True), atol=1e-15)

    def test_rotvec(self, qs):
        r_scipy = scipy_rot(qs).as_rotvec()
        r = rot.quat_to_rotvec(qs)
        assert_allclose(np.linalg.norm(r, axis=-1), np.linalg.norm(r_scipy, axis=-1), rtol=1e-14, atol=4e-15)
        not_180 = rot.quat_angle(qs) < math.pi - 1e-9  # at exactly 180 deg +-rotvec are both right
        assert_allclose(r[not_180], r_scipy[not_180], rtol=1e-14, atol=4e-15)
        assert_same_rotation(rot.rotvec_to_quat(r_scipy), qs, atol=1e-15)

    def test_mrp(self, qs):
        sigma = rot.quat_to_mrp(qs)
        assert np.all(np.linalg.norm(sigma, axis=-1) <= 1.0 + 1e-15)
        not_180 = rot.quat_angle(qs) < math.pi - 1e-9
        # scipy's as_mrp uses the same sign convention: sigma = q_vec / (1 + q0) with q0 >= 0
        assert_allclose(sigma[not_180], scipy_rot(qs[not_180]).as_mrp(), rtol=1e-14, atol=1e-15)
        assert_same_rotation(rot.mrp_to_quat(sigma), Rotation.from_mrp(sigma).as_quat(scalar_first=True), 1e-15)

    def test_pitch_yaw_roll_is_intrinsic_yzx(self, qs):
        angles = scipy_euler(qs, "YZX")  # uppercase: intrinsic, (pitch, yaw, roll)
        q_OB = rot.quat_from_pitch_yaw_roll(*angles.T)
        assert_allclose(
            q_OB, Rotation.from_euler("YZX", angles).as_quat(canonical=True, scalar_first=True), rtol=0, atol=1e-15
        )
        assert_angles_close(np.stack(rot.pitch_yaw_roll_from_quat(qs), axis=-1), angles, atol=1e-14)

    def test_angles_002_is_intrinsic_zyx(self, qs):
        dcm_BO = scipy_rot(qs).as_matrix().swapaxes(-1, -2)  # qs taken as q_OB
        yaw, pitch, roll = scipy_euler(qs, "ZYX").T
        assert_allclose(rot.dcm_from_angles_002(pitch, yaw, roll), dcm_BO, rtol=0, atol=2e-15)
        assert_angles_close(np.stack(rot.angles_002_from_dcm(dcm_BO)), [pitch, yaw, roll], atol=1e-14)


def test_angle_between_and_normalisation_match_scipy():
    q2 = np.roll(Q_RANDOM, 3, axis=0)
    expected = (scipy_rot(Q_RANDOM).inv() * scipy_rot(q2)).magnitude()
    assert_allclose(rot.angle_between(Q_RANDOM, q2), expected, rtol=0, atol=1e-14)
    scaled = Q_RANDOM * np.linspace(0.01, 100.0, N)[:, None]  # non-unit inputs are normalised
    assert_allclose(rot.quat_to_dcm(scaled), scipy_rot(Q_RANDOM).as_matrix(), rtol=0, atol=1e-15)
    assert_allclose(rot.quat_rotate(scaled, V_RANDOM), scipy_rot(Q_RANDOM).apply(V_RANDOM), rtol=0, atol=1e-14)


def test_special_values():
    assert_array_equal(rot.quat_to_dcm(SPECIAL["x180"]), np.diag([1.0, -1.0, -1.0]))
    assert_array_equal(rot.dcm_to_quat(np.diag([-1.0, 1.0, -1.0])), SPECIAL["y180"])
    assert_array_equal(rot.dcm_to_quat(np.diag([-1.0, -1.0, 1.0])), SPECIAL["z180"])
    assert_array_equal(rot.quat_to_rotvec(SPECIAL["identity_negative"]), np.zeros(3))
    # 180 deg about -x: the canonical quaternion (first non-zero component positive) is +x
    assert_array_equal(rot.quat_canonical(SPECIAL["minus_x180"]), SPECIAL["x180"])
    assert_allclose(rot.quat_to_rotvec(SPECIAL["minus_x180"]), [math.pi, 0.0, 0.0], rtol=1e-15)
    assert_array_equal(rot.quat_to_mrp(SPECIAL["minus_x180"]), [1.0, 0.0, 0.0])
    assert rot.quat_angle(SPECIAL["diag180"]) == math.pi
    assert_allclose(rot.quat_rotate(SPECIAL["z90"], [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=1e-15)


def test_tiny_angles_keep_relative_precision():
    axis = _unit([1.0, -2.0, 3.0])
    for theta in (1e-12, 1e-8, 1e-4, 1e-3):
        q = rot.rotvec_to_quat(theta * axis)
        assert_allclose(rot.quat_to_rotvec(q), theta * axis, rtol=1e-15)
        assert_allclose(rot.quat_angle(q), theta, rtol=1e-15)
        assert_allclose(rot.angle_between(SPECIAL["identity"], q), theta, rtol=1e-15)
        assert_allclose(4.0 * np.linalg.norm(rot.quat_to_mrp(q)), theta, rtol=max(theta**2 / 40, 1e-15))
    # an acos form would give 0 or ~2e-8 here
    assert_allclose(rot.angle_between(SPECIAL["z90"], rot.quat_multiply(SPECIAL["z90"], q)), 1e-3, rtol=1e-12)
    assert_array_equal(rot.rotvec_to_quat(np.zeros(3)), SPECIAL["identity"])
    assert_allclose(rot.dcm_to_quat(rot.quat_to_dcm(SPECIAL["tiny_1e-12"])), SPECIAL["tiny_1e-12"], atol=1e-16)


# ---------------------------------------------------------------- the papers' definitions


def _turn_frame(sequence):
    """Axes (columns, in the start frame) after successive turns about axes of the current frame,
    by Rodrigues' formula written out here (independent of the module under test)."""
    axes = np.eye(3)
    for axis_index, angle in sequence:
        k = axes[:, axis_index]
        kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        turn = np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx
        axes = turn @ axes
    return axes


@pytest.mark.parametrize("angles", [(0.1, 0.2, 0.3), (-2.5, 1.2, 3.0), (0.007, 0.021, -0.004)])
def test_pitch_yaw_roll_follow_paper_003_definition(angles):
    """003 §1.6: O is turned into B by alpha about axis 2, beta about the new axis 3, gamma about the
    resulting axis 1; the columns of dcm_OB are B's axes in O."""
    alpha, beta, gamma = angles
    body_axes_O = _turn_frame([(1, alpha), (2, beta), (0, gamma)])
    q_OB = rot.quat_from_pitch_yaw_roll(alpha, beta, gamma)
    assert_allclose(rot.quat_to_dcm(q_OB), body_axes_O, atol=1e-15)
    assert_allclose(rot.pitch_yaw_roll_from_quat(q_OB), angles, rtol=0, atol=1e-15)


def test_paper_002_matrix_3_and_quaternion_form_4():
    pitch, yaw, roll = 0.1, 0.2, 0.3  # J, psi, phi
    cJ, sJ, cy, sy, cf, sf = (f(a) for a in (pitch, yaw, roll) for f in (math.cos, math.sin))
    m3 = np.array(
        [  # 002 eq. (3), M_X1X2 (orbital -> body), entry by entry
            [cJ * cy, cJ * sy, -sJ],
            [sf * sJ * cy - cf * sy, sf * sJ * sy + cf * cy, sf * cJ],
            [cf * sJ * cy + sf * sy, cf * sJ * sy - sf * cy, cf * cJ],
        ]
    )
    dcm_BO = rot.dcm_from_angles_002(pitch, yaw, roll)
    assert_allclose(dcm_BO, m3, rtol=0, atol=1e-16)
    assert_allclose(dcm_BO.T, _turn_frame([(2, yaw), (1, pitch), (0, roll)]), atol=1e-15)
    q_BO = rot.quat_from_angles_002(pitch, yaw, roll)
    assert_allclose(q_BO, rot.dcm_to_quat(m3), rtol=0, atol=1e-16)
    v0, v1, v2, v3 = rot.quat_conjugate(q_BO)  # the paper's v is q_OB
    m4 = np.array(
        [  # 002 eq. (4), with its misprint 2(v2 v3 - v1 v1) read as 2(v2 v3 - v0 v1)
            [v0**2 + v1**2 - v2**2 - v3**2, 2 * (v1 * v2 + v0 * v3), 2 * (v1 * v3 - v0 * v2)],
            [2 * (v1 * v2 - v0 * v3), v0**2 + v2**2 - v1**2 - v3**2, 2 * (v0 * v1 + v2 * v3)],
            [2 * (v0 * v2 + v1 * v3), 2 * (v2 * v3 - v0 * v1), v0**2 + v3**2 - v2**2 - v1**2],
        ]
    )
    assert_allclose(m4, m3, rtol=0, atol=1e-15)
    assert_allclose(rot.angles_002_from_dcm(m3), (pitch, yaw, roll), rtol=0, atol=1e-15)


def test_gimbal_lock_behaviour():
    # 003: yaw = +-90 deg; roll is set to 0 and pitch carries alpha + gamma (or alpha - gamma)
    for yaw, pitch_expected in ((math.pi / 2, 0.5), (-math.pi / 2, 0.1)):
        q = rot.quat_from_pitch_yaw_roll(0.3, yaw, 0.2)
        pitch, yaw_out, roll = rot.pitch_yaw_roll_from_quat(q)
        assert (yaw_out, roll) == (yaw, 0.0)
        assert_allclose(pitch, pitch_expected, atol=1e-15)
        assert_same_rotation(rot.quat_from_pitch_yaw_roll(pitch, yaw_out, roll), q, atol=1e-15)
    # 002: pitch = +-90 deg; roll is set to 0 and yaw carries psi - phi (or psi + phi)
    for pitch, yaw_expected in ((math.pi / 2, 0.1), (-math.pi / 2, 0.5)):
        out = rot.angles_002_from_dcm(rot.dcm_from_angles_002(pitch, 0.3, 0.2))
        assert (out[0], out[2]) == (pitch, 0.0)
        assert_allclose(out[1], yaw_expected, atol=1e-15)
    # scipy warns at the lock and makes the same choice (third angle = 0)
    with pytest.warns(UserWarning, match="Gimbal lock"):
        expected = scipy_rot(SPECIAL["z90"]).as_euler("YZX")
    assert_allclose(rot.pitch_yaw_roll_from_quat(SPECIAL["z90"]), expected, atol=1e-15)
    # just off the lock the angles are ill-conditioned but still rebuild the rotation
    q = rot.quat_from_pitch_yaw_roll(0.3, math.pi / 2 - 1e-9, 0.2)
    assert_same_rotation(rot.quat_from_pitch_yaw_roll(*rot.pitch_yaw_roll_from_quat(q)), q, atol=1e-15)


# ---------------------------------------------------------------- MRP shadow sets


def test_mrp_shadow_and_switch():
    sigma = rot.quat_to_mrp(Q_RANDOM)
    shadow = rot.mrp_shadow(sigma)
    assert_allclose(np.linalg.norm(shadow, axis=-1) * np.linalg.norm(sigma, axis=-1), 1.0, rtol=1e-15)
    assert_allclose(rot.mrp_to_quat(shadow), -rot.mrp_to_quat(sigma), rtol=0, atol=1e-15)  # -q
    assert_allclose(rot.mrp_switch(shadow), sigma, rtol=0, atol=1e-15)
    assert_array_equal(rot.mrp_switch(sigma), sigma)  # |sigma| <= 1: untouched
    assert_array_equal(rot.mrp_switch(np.zeros(3)), np.zeros(3))
    # |sigma| == 0 has its shadow at infinity: NaN rows, no warning
    assert_array_equal(np.isnan(rot.mrp_shadow([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0]])), [[1, 1, 1], [0, 0, 0]])
    assert_array_equal(rot.mrp_shadow([0.5, 0.0, 0.0]), [-2.0, 0.0, 0.0])


# ---------------------------------------------------------------- hypothesis properties

PROPERTY = settings(max_examples=60, deadline=None, database=None)
unit_float = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
quats = (
    st.tuples(unit_float, unit_float, unit_float, unit_float)
    .map(np.array)
    .filter(lambda q: np.linalg.norm(q) > 1e-3)
    .map(lambda q: q / np.linalg.norm(q))
)
vectors = st.tuples(*[st.floats(-10.0, 10.0, allow_nan=False)] * 3).map(np.array)
angle = st.floats(-math.pi, math.pi, allow_nan=False)


@PROPERTY
@given(quats)
def test_round_trips(q):
    assert_same_rotation(rot.dcm_to_quat(rot.quat_to_dcm(q)), q, atol=1e-15)
    assert_same_rotation(rot.rotvec_to_quat(rot.quat_to_rotvec(q)), q, atol=1e-15)
    assert_same_rotation(rot.mrp_to_quat(rot.quat_to_mrp(q)), q, atol=1e-15)
    if np.linalg.norm(rot.quat_to_mrp(q)) > 1e-6:  # the identity's shadow is NaN (at infinity)
        assert_same_rotation(rot.mrp_to_quat(rot.mrp_shadow(rot.quat_to_mrp(q))), q, atol=1e-14)
    assert_same_rotation(rot.quat_from_pitch_yaw_roll(*rot.pitch_yaw_roll_from_quat(q)), q, atol=1e-15)
    dcm_BO = rot.quat_to_dcm(q)
    assert_allclose(rot.dcm_from_angles_002(*rot.angles_002_from_dcm(dcm_BO)), dcm_BO, atol=2e-15)
    assert_array_equal(rot.quat_canonical(rot.quat_canonical(-q)), rot.quat_canonical(q))


@PROPERTY
@given(angle, st.floats(-math.pi / 2, math.pi / 2), angle)
def test_euler_angle_round_trips(a, b, c):
    out = rot.pitch_yaw_roll_from_quat(rot.quat_from_pitch_yaw_roll(a, b, c))
    assert_same_rotation(rot.quat_from_pitch_yaw_roll(*out), rot.quat_from_pitch_yaw_roll(a, b, c), 1e-15)
    assert_allclose(out[1], b, atol=1e-15)
    dcm_BO = rot.dcm_from_angles_002(a / 2, b, c)
    assert_allclose(rot.dcm_from_angles_002(*rot.angles_002_from_dcm(dcm_BO)), dcm_BO, atol=2e-15)
    assert_allclose(rot.quat_from_angles_002(a / 2, b, c), rot.dcm_to_quat(dcm_BO), atol=1e-15)


@PROPERTY
@given(quats, quats, quats, vectors)
def test_algebra(p, q, r, v):
    assert_allclose(
        rot.quat_multiply(rot.quat_multiply(p, q), r), rot.quat_multiply(p, rot.quat_multiply(q, r)), atol=1e-15
    )
    assert_allclose(np.linalg.norm(rot.quat_multiply(2.0 * p, 0.5 * q)), 1.0, rtol=1e-15)
    assert_allclose(rot.quat_rotate(p, v), rot.quat_to_dcm(p) @ v, atol=1e-14)
    assert_allclose(np.linalg.norm(rot.quat_rotate(p, v)), np.linalg.norm(v), rtol=1e-14, atol=1e-14)
    assert_allclose(rot.quat_rotate(rot.quat_multiply(p, q), v), rot.quat_rotate(p, rot.quat_rotate(q, v)), atol=1e-13)
    assert_allclose(rot.skew(v) @ rot.quat_rotate(q, v), np.cross(v, rot.quat_rotate(q, v)), atol=1e-13)
    ab = rot.angle_between(p, q)
    assert ab == rot.angle_between(q, p)
    assert 0.0 <= ab <= math.pi
    relative = rot.quat_multiply(rot.quat_conjugate(p), q)
    assert_allclose(ab, np.linalg.norm(rot.quat_to_rotvec(relative)), atol=1e-15)
