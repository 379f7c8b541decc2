"""Tests of processing.attitude.rotations: golden values from scipy and CCSDS ADM 2.0, the papers' formulas
written out by hand, and hypothesis properties (round trips and invariants)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial.transform import Rotation

from processing.attitude import rotations as rot
from processing.attitude.rotations import RotationValueError

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


# ---------------------------------------------------------------- CCSDS ADM 2.0
# CCSDS 504.0-B-2 (Attitude Data Messages, Issue 2, January 2024), Annex F, values as transcribed
# in JochimMaene/ccsds-ndm docs/ccsds-books/adm.rst. ADM quaternions are (Q1, Q2, Q3, QC), "from
# frame A to frame B": B's basis vectors are the images of A's under the rotation; M_BA (X_B = M_BA X_A)
# is given in F2.1. Quoted values have 4 decimals, hence the 1e-4 tolerances.


def _m_ba_annex_f21(q):
    q1, q2, q3, qc = q
    return np.array(
        [
            [q1**2 - q2**2 - q3**2 + qc**2, 2 * (q1 * q2 + q3 * qc), 2 * (q1 * q3 - q2 * qc)],
            [2 * (q1 * q2 - q3 * qc), -(q1**2) + q2**2 - q3**2 + qc**2, 2 * (q2 * q3 + q1 * qc)],
            [2 * (q1 * q3 + q2 * qc), 2 * (q2 * q3 - q1 * qc), -(q1**2) - q2**2 + q3**2 + qc**2],
        ]
    )


def test_ccsds_f21_matrix_is_our_dcm_transposed():
    for q_ccsds in rot.quat_to_ccsds(Q_RANDOM[:50]):
        dcm_AB = rot.quat_to_dcm(rot.quat_from_ccsds(q_ccsds))
        assert_allclose(dcm_AB.T, _m_ba_annex_f21(q_ccsds), rtol=0, atol=1e-15)


def test_ccsds_f22_example_90deg_about_z():
    q_ccsds = np.array([0.0, 0.0, 0.7071, 0.7071])  # F2.2: B = A turned +90 deg about Z
    q_AB = rot.quat_from_ccsds(q_ccsds)
    assert_array_equal(q_AB, [0.7071, 0.0, 0.0, 0.7071])
    assert_allclose(rot.quat_to_dcm(q_AB).T, [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], atol=1e-4)  # M_BA
    assert_allclose(rot.quat_rotate(q_AB, [1.0, 0.0, 0.0]), [0, 1, 0], atol=1e-4)  # X_B axis in A
    assert_allclose(rot.quat_rotate(rot.quat_conjugate(q_AB), [1.0, 0.0, 0.0]), [0, -1, 0], atol=1e-4)
    exact = rot.quat_to_ccsds(rot.quat_from_axis_angle([0, 0, 1], math.pi / 2))
    assert_allclose(exact, q_ccsds, atol=5e-5)


def test_ccsds_f54_spin_example():
    """F5.4: SPIN_ALPHA 0, SPIN_DELTA 80, SPIN_ANGLE 45 deg; momentum at declination 70 deg;
    intrinsic turns Z(alpha + 90), X(90 - delta), Z(spin angle) from frame A; nutation 0.01 deg/s,
    spin 1 deg/s, propagated 300 s from frame F (Phi0 = -90, theta = 10, psi0 = -135 deg)."""
    d = math.radians
    ez, ex = [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]

    def zxz(a, b, c):
        parts = [rot.quat_from_axis_angle(ax, ang) for ax, ang in ((ez, a), (ex, b), (ez, c))]
        return rot.quat_multiply(rot.quat_multiply(parts[0], parts[1]), parts[2])

    q_AB = zxz(d(90.0), d(10.0), d(45.0))
    assert_same_rotation(rot.quat_to_ccsds(q_AB), [0.0805, 0.0334, 0.9204, 0.3812], atol=6e-5)
    assert_allclose(rot.quat_rotate(q_AB, ez), [0.1736, 0.0, 0.9848], atol=6e-5)  # spin axis in A
    q_AF = rot.quat_from_ccsds([0.0, 0.1736, 0.0, 0.9848])
    assert_allclose(rot.quat_rotate(q_AF, ez), [0.3420, 0.0, 0.9397], atol=1e-4)  # momentum in A
    q_FB = rot.quat_from_ccsds([-0.0805, -0.0334, 0.9204, 0.3812])
    assert_same_rotation(rot.quat_multiply(q_AF, q_FB), q_AB, atol=2e-4)  # q_AB = q_AF o q_FB
    assert_same_rotation(zxz(d(-90.0), d(10.0), d(-135.0)), q_FB, atol=6e-5)
    q_AB_t = rot.quat_multiply(q_AF, zxz(d(-90.0 + 0.01 * 300), d(10.0), d(-135.0 + 1.0 * 300)))
    assert_same_rotation(rot.quat_to_ccsds(q_AB_t), [0.0584, 0.0650, 0.6263, 0.7747], atol=2e-4)
    assert_allclose(rot.quat_rotate(q_AB_t, ez), [0.1739, -0.0091, 0.9847], atol=2e-4)


def test_ccsds_reorder_round_trip():
    assert_array_equal(rot.quat_to_ccsds([1.0, 2.0, 3.0, 4.0]), [2.0, 3.0, 4.0, 1.0])
    assert_array_equal(rot.quat_from_ccsds(rot.quat_to_ccsds(Q_RANDOM)), Q_RANDOM)


def _m_ba_annex_f32(axes, angles):
    """CCSDS Annex F3.2 written for any axis sequence: M_BA = M3 M2 M1 with frame-rotation matrices."""

    def m(axis, t):
        c, s = math.cos(t), math.sin(t)
        i, j = [k for k in range(3) if k != axis]
        out = np.eye(3)
        out[i, i], out[i, j], out[j, i], out[j, j] = c, s, -s, c
        return out if axis != 1 else out.T  # the Y matrix of F3.2 has -sin at (0, 2)

    m1, m2, m3 = (m(a, t) for a, t in zip(axes, angles, strict=True))
    return m3 @ m2 @ m1


def test_euler_conventions_match_ccsds_annex_f3():
    x, y, z = 0.4, -0.7, 1.9
    assert_allclose(
        _m_ba_annex_f32((0, 1, 2), (x, y, z)),  # the F3.2 example itself
        [[math.cos(z), math.sin(z), 0], [-math.sin(z), math.cos(z), 0], [0, 0, 1]]
        @ np.array([[math.cos(y), 0, -math.sin(y)], [0, 1, 0], [math.sin(y), 0, math.cos(y)]])
        @ np.array([[1, 0, 0], [0, math.cos(x), math.sin(x)], [0, -math.sin(x), math.cos(x)]]),
        atol=1e-15,
    )
    # 003 §1.6 is the ADM sequence 231 from O to B; 002 (3) is the sequence 321 from O to B
    dcm_BO = rot.quat_to_dcm(rot.quat_from_pitch_yaw_roll(x, y, z)).T
    assert_allclose(dcm_BO, _m_ba_annex_f32((1, 2, 0), (x, y, z)), atol=1e-15)
    assert_allclose(rot.dcm_from_angles_002(y, x, z), _m_ba_annex_f32((2, 1, 0), (x, y, z)), atol=1e-15)


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
