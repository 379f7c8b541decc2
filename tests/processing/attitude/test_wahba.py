"""Wahba solvers (002 eqs. 8-9): agreement with scipy, exact constructed cases, loss, covariance, statuses."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from processing.attitude import rotations, wahba

METHODS = sorted(wahba.METHODS)


def _random_case(n_epochs: int, n_vec: int, noise: float, seed: int):
    rng = np.random.default_rng(seed)
    rot = Rotation.random(n_epochs, random_state=seed)
    r = rng.normal(size=(n_epochs, n_vec, 3))
    r /= np.linalg.norm(r, axis=-1, keepdims=True)
    b = np.einsum("nij,nkj->nki", rot.as_matrix(), r) + noise * rng.normal(size=r.shape)
    b /= np.linalg.norm(b, axis=-1, keepdims=True)
    w = rng.uniform(0.2, 3.0, size=(n_epochs, n_vec))
    return b, r, w, rot


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("n_vec", [2, 3, 5])
def test_agrees_with_scipy_align_vectors(method: str, n_vec: int) -> None:
    b, r, w, _ = _random_case(150, n_vec, 0.02, seed=n_vec)
    res = wahba.solve(method, b, r, w)
    ref = np.array([Rotation.align_vectors(b[i], r[i], weights=w[i])[0].as_quat(scalar_first=True)
                    for i in range(b.shape[0])])
    assert np.all(res.ok)
    assert np.max(rotations.angle_between(res.q, ref)) < 1e-9
    assert np.all(res.q[:, 0] >= 0)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("angle_deg", [0.0, 90.0, 180.0, 179.9999])
@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, -2, 0.5)])
def test_exact_constructed_rotations(method: str, angle_deg: float, axis: tuple[float, ...]) -> None:
    """Noise-free vectors rotated by 0, 90, 180 deg: every solver returns the rotation to rounding."""
    q_true = rotations.quat_canonical(rotations.quat_from_axis_angle(axis, np.deg2rad(angle_deg)))
    r = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.3, -0.4, 0.8]])
    b = rotations.quat_rotate(q_true, r)
    res = wahba.solve(method, b, r, [1.0, 2.0, 0.5])
    assert res.status == wahba.OK
    assert rotations.angle_between(res.q, q_true) < 1e-12
    assert res.loss == pytest.approx(0.0, abs=1e-12)
    assert res.lambda_max == pytest.approx(3.5, abs=1e-12)


def test_180_degrees_about_each_axis_two_vectors() -> None:
    """The Gibbs-vector form of QUEST fails at 180 deg; the rotated-frame column choice does not."""
    r = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    for axis in np.eye(3):
        q_true = np.concatenate([[0.0], axis])
        b = rotations.quat_rotate(q_true, r)
        for method in METHODS:
            res = wahba.solve(method, b, r)
            assert rotations.angle_between(res.q, q_true) < 1e-12, (method, axis)


def test_loss_is_eq8_and_davenport_k() -> None:
    b, r, w, _ = _random_case(50, 3, 0.05, seed=7)
    res = wahba.quest(b, r, w)
    dcm = rotations.quat_to_dcm(res.q)
    direct = np.einsum("nk,nki->n", w, (b - np.einsum("nij,nkj->nki", dcm, r)) ** 2)
    np.testing.assert_allclose(res.loss, direct, rtol=1e-9, atol=1e-12)
    # q^T K q = tr(A B^T) for any unit q; the paper's eq. 9 matrix (vector first) is -K reordered.
    K = wahba.davenport_k(b, r, w)
    B = wahba.attitude_profile_matrix(b, r, w)
    q = rotations.quat_normalize(np.random.default_rng(1).normal(size=(50, 4)))
    np.testing.assert_allclose(np.einsum("ni,nij,nj->n", q, K, q),
                               np.einsum("nij,nij->n", rotations.quat_to_dcm(q), B), atol=1e-12)
    u1, u2, a = b[0], r[0], w[0]
    paper = sum(a[i] * np.block([[np.eye(3) * (u1[i] @ u2[i]) - np.outer(u2[i], u1[i]) - np.outer(u1[i], u2[i]),
                                  -np.cross(u1[i], u2[i])[:, None]],
                                 [-np.cross(u1[i], u2[i])[None, :], -np.atleast_2d(u1[i] @ u2[i])]])
                for i in range(3))
    vals, vecs = np.linalg.eigh(paper)
    qbar = vecs[:, 0]  # eigenvector of the smallest eigenvalue (002), Shuster order (qv, q4)
    q_paper = np.concatenate([[qbar[3]], -qbar[:3]])
    assert rotations.angle_between(q_paper, res.q[0]) < 1e-9
    assert vals[0] == pytest.approx(-res.lambda_max[0], rel=1e-9)


def test_covariance_two_perpendicular_vectors() -> None:
    """P = [sum a (I - b b^T)]^-1 = sigma^2 diag(1, 1, 1/2) for b = x, y with a = 1/sigma^2."""
    sigma = 1e-3
    r = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    for method in METHODS:
        res = wahba.solve(method, r, r, np.full(2, sigma**-2))
        np.testing.assert_allclose(res.covariance_rad2, sigma**2 * np.diag([1.0, 1.0, 0.5]), rtol=1e-12)


def test_covariance_matches_monte_carlo() -> None:
    """Errors of QUEST with isotropic noise of sigma on b and weights 1/sigma^2 have covariance P."""
    rng = np.random.default_rng(3)
    n = 20000
    sig = np.array([0.01, 0.003, 0.02])
    r = np.array([[1.0, 0.2, 0.0], [0.0, 1.0, 0.5], [0.4, -0.3, 1.0]])
    r = r / np.linalg.norm(r, axis=1, keepdims=True)
    q_true = rotations.quat_from_axis_angle([0.3, 0.5, -1.0], 2.0)
    b0 = rotations.quat_rotate(q_true, r)
    b = b0[None] + rng.normal(size=(n, 3, 3)) * sig[None, :, None]
    res = wahba.quest(b, np.broadcast_to(r, b.shape), sig**-2)
    err = rotations.quat_to_rotvec(rotations.quat_multiply(res.q, rotations.quat_conjugate(q_true)))
    emp = np.cov(err.T)
    p = res.covariance_rad2.mean(axis=0)
    np.testing.assert_allclose(np.diag(emp), np.diag(p), rtol=0.08)


def test_statuses_and_missing_vectors() -> None:
    b = np.array([
        [[1.0, 0, 0], [0, 1.0, 0]],  # ok
        [[1.0, 0, 0], [2.0, 0, 0]],  # collinear: rotation about x undetermined
        [[np.nan, 0, 0], [0, 1.0, 0]],  # one vector left
        [[0.0, 0, 0], [0, 0, 0]],  # nothing usable
    ])
    r = np.array([[[1.0, 0, 0], [0, 1.0, 0]]] * 4)
    r[1, 1] = [3.0, 0, 0]
    for method in METHODS:
        res = wahba.solve(method, b, r)
        assert res.status.tolist() == [wahba.OK, wahba.UNOBSERVABLE, wahba.UNOBSERVABLE, wahba.INVALID], method
        assert np.all(np.isnan(res.q[3])) and np.all(np.isfinite(res.q[:3]))
        assert np.all(np.isnan(res.covariance_rad2[1:]))
        # the unobservable solutions still map the one direction exactly
        assert np.allclose(rotations.quat_rotate(res.q[1], [1.0, 0, 0]), [1.0, 0, 0])
    res = wahba.quest(b[:1], r[:1], [[0.0, 1.0]])
    assert res.status[0] == wahba.UNOBSERVABLE  # a zero weight removes a vector


def test_shapes_single_epoch_and_leading_dims() -> None:
    b, r, w, _ = _random_case(12, 3, 0.01, seed=5)
    one = wahba.quest(b[0], r[0], w[0])
    assert one.q.shape == (4,) and one.covariance_rad2.shape == (3, 3) and one.status.shape == ()
    grid = wahba.esoq2(b.reshape(3, 4, 3, 3), r.reshape(3, 4, 3, 3), w.reshape(3, 4, 3))
    flat = wahba.esoq2(b, r, w)
    assert grid.q.shape == (3, 4, 4)
    np.testing.assert_allclose(grid.q.reshape(12, 4), flat.q, atol=1e-15)
    assert one.q == pytest.approx(flat.q[0], abs=1e-15)
    # one weight vector for all epochs
    np.testing.assert_allclose(wahba.quest(b, r, [1.0, 2.0, 3.0]).q,
                               wahba.quest(b, r, np.tile([1.0, 2.0, 3.0], (12, 1))).q, atol=1e-15)


def test_input_errors() -> None:
    with pytest.raises(wahba.WahbaInputError, match=r"shape \(\.\.\., n, 3\)"):
        wahba.quest(np.zeros((5, 3)), np.zeros((5, 2)))
    with pytest.raises(wahba.WahbaInputError, match="weights must be >= 0"):
        wahba.q_method(np.eye(3), np.eye(3), [1.0, -1.0, 1.0])
    with pytest.raises(wahba.WahbaInputError, match="broadcast"):
        wahba.svd_method(np.eye(3), np.eye(3), [1.0, 1.0])
    with pytest.raises(wahba.WahbaInputError, match="unknown Wahba method"):
        wahba.solve("triad", np.eye(3), np.eye(3))
