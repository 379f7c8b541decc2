"""Tests of processing.frames.orbital: the 003 §1.6 orbital frame and the paper-004 LVLH frame."""

import numpy as np
import pytest

from processing.attitude import rotations
from processing.frames.orbital import (
    OrbitalFrameInputError,
    dcm_IO_003,
    dcm_IO_lvlh_004,
    q_IO_003,
    q_IO_lvlh_004,
)
from processing.orbits.two_body import circular_orbit_state

X, Y, Z = np.eye(3)


def test_003_axes_hand_computed_r_along_x_v_along_y():
    # r along x, v along y: radial (axis 3) = x, normal r x v (axis 2) = z, axis 1 = z x x = y
    dcm = dcm_IO_003([7000e3, 0.0, 0.0], [0.0, 7500.0, 0.0])
    np.testing.assert_array_equal(dcm[:, 0], Y)
    np.testing.assert_array_equal(dcm[:, 1], Z)
    np.testing.assert_array_equal(dcm[:, 2], X)


def test_004_axes_hand_computed_r_along_x_v_along_y():
    # X0 along velocity (y), Z0 to the Earth's centre (-x), Y0 = Z0 x X0 = -z (minus orbit normal)
    dcm = dcm_IO_lvlh_004([7000e3, 0.0, 0.0], [0.0, 7500.0, 0.0])
    np.testing.assert_array_equal(dcm[:, 0], Y)
    np.testing.assert_array_equal(dcm[:, 1], -Z)
    np.testing.assert_array_equal(dcm[:, 2], -X)


def test_003_axes_hand_computed_polar_orbit():
    # r along z (over the north pole), v along -x: axis 3 = z, axis 2 = z x (-x) = -y, axis 1 = -y x z = -x
    dcm = dcm_IO_003([0.0, 0.0, 7e6], [-7.5e3, 0.0, 0.0])
    np.testing.assert_array_equal(dcm, np.stack([-X, -Y, Z], axis=-1))


def test_non_circular_x0_is_transversal_not_velocity():
    # flight-path angle 10 deg: v = 7.5 km/s (sin 10, cos 10, 0) with r along x
    gamma = np.deg2rad(10.0)
    r = np.array([7e6, 0.0, 0.0])
    v = 7.5e3 * np.array([np.sin(gamma), np.cos(gamma), 0.0])
    lvlh = dcm_IO_lvlh_004(r, v)
    np.testing.assert_allclose(lvlh[:, 0], Y, atol=1e-16)  # perpendicular to r, not along v
    assert np.dot(lvlh[:, 0], v / np.linalg.norm(v)) == pytest.approx(np.cos(gamma), rel=1e-15)
    np.testing.assert_allclose(dcm_IO_003(r, v)[:, 0], Y, atol=1e-16)


def _random_states(n=200, seed=1):
    rng = np.random.default_rng(seed)
    r = rng.normal(size=(n, 3)) * 7e6
    v = rng.normal(size=(n, 3)) * 7e3
    return r, v


@pytest.mark.parametrize("func", [dcm_IO_003, dcm_IO_lvlh_004])
def test_orthonormal_and_right_handed(func):
    r, v = _random_states()
    dcm = func(r, v)
    assert dcm.shape == (200, 3, 3)
    np.testing.assert_allclose(np.einsum("nji,njk->nik", dcm, dcm), np.broadcast_to(np.eye(3), dcm.shape), atol=1e-15)
    np.testing.assert_allclose(np.linalg.det(dcm), 1.0, atol=1e-15)
    np.testing.assert_allclose(np.cross(dcm[..., 0], dcm[..., 1]), dcm[..., 2], atol=1e-15)


def test_axes_relations_between_the_two_definitions():
    r, v = _random_states()
    a, b = dcm_IO_003(r, v), dcm_IO_lvlh_004(r, v)
    np.testing.assert_array_equal(b[..., 0], a[..., 0])
    np.testing.assert_array_equal(b[..., 1], -a[..., 1])
    np.testing.assert_array_equal(b[..., 2], -a[..., 2])
    # radial and normal directions
    np.testing.assert_allclose(a[..., 2], r / np.linalg.norm(r, axis=-1, keepdims=True), atol=1e-16)
    h = np.cross(r, v)
    np.testing.assert_allclose(a[..., 1], h / np.linalg.norm(h, axis=-1, keepdims=True), atol=1e-16)
    # axis 1 on the side of the velocity
    assert np.all(np.sum(a[..., 0] * v, axis=-1) > 0)


def test_quaternions_match_matrices_and_are_canonical():
    r, v = _random_states()
    for qf, mf in ((q_IO_003, dcm_IO_003), (q_IO_lvlh_004, dcm_IO_lvlh_004)):
        q = qf(r, v)
        assert q.shape == (200, 4)
        assert np.all(q[..., 0] >= 0)
        np.testing.assert_allclose(rotations.quat_to_dcm(q), mf(r, v), atol=1e-15)
        # v_I = dcm_IO v_O: the O-frame coordinates of the radius are (0, 0, |r|) for 003
    q = q_IO_003(r, v)
    r_O = rotations.quat_rotate(rotations.quat_conjugate(q), r)
    np.testing.assert_allclose(r_O[..., :2], 0.0, atol=1e-8)
    np.testing.assert_allclose(r_O[..., 2], np.linalg.norm(r, axis=-1), rtol=1e-15)


def test_lvlh_rate_is_minus_w0_about_y0_on_circular_orbit():
    # 004: w_OI = (0, -w0, 0); equivalently the 003 frame rotates at +n about its axis 2.
    t = np.array([0.0, 0.5])
    a = 7000e3
    r, v = circular_orbit_state(t, a, 1.7, 0.3, 0.2)
    n = np.linalg.norm(v[0]) / a
    q = q_IO_lvlh_004(r, v)
    dq = rotations.quat_multiply(rotations.quat_conjugate(q[0]), q[1])
    w_O = rotations.quat_to_rotvec(dq) / 0.5
    np.testing.assert_allclose(w_O, [0.0, -n, 0.0], atol=1e-15)
    q3 = q_IO_003(r, v)
    w3 = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(q3[0]), q3[1])) / 0.5
    np.testing.assert_allclose(w3, [0.0, n, 0.0], atol=1e-15)


def test_scalar_and_array_agree_and_broadcasting():
    r, v = _random_states(5)
    batch = dcm_IO_003(r, v)
    np.testing.assert_array_equal(dcm_IO_003(r[2], v[2]), batch[2])
    # one velocity for all positions broadcasts
    assert dcm_IO_003(r, v[0]).shape == (5, 3, 3)


def test_degenerate_states_give_nan_rows():
    r = np.array([[7e6, 0, 0], [7e6, 0, 0], [0, 0, 0]], dtype=float)
    v = np.array([[0, 7e3, 0], [7e3, 0, 0], [0, 7e3, 0]], dtype=float)
    dcm = dcm_IO_003(r, v)
    assert np.all(np.isfinite(dcm[0]))
    assert np.all(np.isnan(dcm[1][:, :2]))
    assert np.all(np.isnan(dcm[2]))


def test_bad_shapes():
    with pytest.raises(OrbitalFrameInputError, match=r"shape \(\.\.\., 3\)"):
        dcm_IO_003(np.zeros((4, 2)), np.zeros((4, 3)))
    with pytest.raises(OrbitalFrameInputError, match="do not broadcast"):
        dcm_IO_lvlh_004(np.ones((4, 3)), np.ones((5, 3)))
