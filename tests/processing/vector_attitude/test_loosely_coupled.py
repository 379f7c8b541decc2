"""Loosely coupled scheme (002 eqs. 10-14): Newton for pitch and yaw, closed-form roll."""

from __future__ import annotations

import numpy as np

from processing.attitude import rotations
from processing.vector_attitude import loosely_coupled as lc


def _case(n: int, seed: int):
    rng = np.random.default_rng(seed)
    pitch = rng.uniform(-1.3, 1.3, n)
    yaw = rng.uniform(-np.pi, np.pi, n)
    roll = rng.uniform(-np.pi, np.pi, n)
    dcm_BO = rotations.dcm_from_angles_002(pitch, yaw, roll)
    h_O = rng.normal(size=(n, 3)) * 3e4
    h_B = np.einsum("nij,nj->ni", dcm_BO, h_O)
    return pitch, yaw, roll, dcm_BO, h_O, h_B


def test_exact_inputs_give_the_exact_attitude() -> None:
    pitch, yaw, roll, dcm_BO, h_O, h_B = _case(500, 1)
    res = lc.loosely_coupled(dcm_BO[:, 0, :], h_B, h_O)  # antenna = X1 = row 1 of matrix (3)
    assert res.ok.all() and res.iterations.max() == 0
    q = rotations.quat_from_angles_002(pitch, yaw, roll)
    assert np.max(rotations.angle_between(res.q_BO, q)) < 1e-12
    np.testing.assert_allclose(res.roll_rad, roll, atol=1e-12)


def test_antenna_on_another_body_axis() -> None:
    pitch, yaw, roll, dcm_BO, h_O, h_B = _case(200, 2)
    a_B = np.array([0.2, -0.5, 0.8])
    a_O = np.einsum("nji,j->ni", dcm_BO, a_B / np.linalg.norm(a_B))
    res = lc.loosely_coupled(a_O, h_B, h_O, a_B)
    assert np.max(rotations.angle_between(res.q_BO, rotations.quat_from_angles_002(pitch, yaw, roll))) < 1e-12


def test_newton_keeps_the_magnetometer_and_moves_the_antenna_least() -> None:
    """With an antenna error the result matches the measured field exactly (stage 1 makes rho = 0,
    stage 2 the other two components) and X1 moves from the antenna estimate to the nearest point of
    the cone X1 . h_O = h_x1 (nearest to second order)."""
    pitch, yaw, roll, dcm_BO, h_O, h_B = _case(300, 3)
    rng = np.random.default_rng(9)
    a_est = dcm_BO[:, 0, :] + 0.1 * rng.normal(size=(300, 3))
    a_est /= np.linalg.norm(a_est, axis=1, keepdims=True)
    res = lc.loosely_coupled(a_est, h_B, h_O)
    assert res.ok.all() and res.iterations.max() <= 12
    dcm = rotations.quat_to_dcm(res.q_BO)
    h_pred = np.einsum("nij,nj->ni", dcm, h_O / np.linalg.norm(h_O, axis=1, keepdims=True))
    np.testing.assert_allclose(h_pred, h_B / np.linalg.norm(h_B, axis=1, keepdims=True), atol=1e-9)
    x1 = dcm[:, 0, :]
    moved = np.arccos(np.clip(np.sum(x1 * a_est, axis=1), -1, 1))
    to_truth = np.arccos(np.clip(np.sum(dcm_BO[:, 0, :] * a_est, axis=1), -1, 1))
    # the true X1 is on the cone too, so the nearest point is never farther (Gauss-Newton reaches it to
    # second order in the step) and usually much nearer
    assert np.all(moved <= 1.02 * to_truth + 1e-9)
    assert np.median(moved) < 0.7 * np.median(to_truth)


def test_degenerate_field_along_the_antenna() -> None:
    """A field along X1 leaves the roll undetermined (a11^2 + a12^2 = 0 in eq. 14)."""
    h_O = np.array([[1.0, 0.0, 0.0]])
    res = lc.loosely_coupled(np.array([[1.0, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]]), h_O)
    assert not res.ok[0] and np.isnan(res.q_BO).all()
