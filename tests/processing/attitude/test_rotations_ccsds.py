"""processing.attitude.rotations against CCSDS ADM 2.0 (504.0-B-2, Annex F): matrices, examples and Euler
conventions."""

from __future__ import annotations

import math

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal

from processing.attitude import rotations as rot

from .rotations_support import Q_RANDOM, assert_same_rotation

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
