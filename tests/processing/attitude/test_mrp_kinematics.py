"""Tests of the MRP kinematics of paper 000 and their Dormand-Prince integration
(processing.attitude.mrp_kinematics)."""

import numpy as np
import pytest

from processing.attitude import rotations
from processing.attitude.mrp_kinematics import (
    SCAN_BLOCK,
    MrpKinematicsError,
    dp45_mrp_step,
    mrp_rate,
    quat_cumprod,
    quat_product,
    rate_from_mrp,
)

ARCSEC_RAD = np.pi / 648000.0
DEG_RAD = np.pi / 180.0


def _coning(t, half_cone_rad, cone_rate_rad_s):
    """Coning motion q(t) = (cos a, 0, sin a cos Wt, sin a sin Wt) and its exact body rate 2 vec(q^-1 o q')."""
    t = np.asarray(t, dtype=float)
    c, s = np.cos(half_cone_rad), np.sin(half_cone_rad)
    z = np.zeros_like(t)
    q = np.stack([np.full_like(t, c), z, s * np.cos(cone_rate_rad_s * t), s * np.sin(cone_rate_rad_s * t)], -1)
    q_dot = np.stack([z, z, -s * cone_rate_rad_s * np.sin(cone_rate_rad_s * t),
                      s * cone_rate_rad_s * np.cos(cone_rate_rad_s * t)], -1)
    w = 2.0 * rotations.quat_multiply(rotations.quat_conjugate(q), q_dot)
    return q, w[..., 1:]


def test_forward_and_inverse_kinematics_are_inverse():
    rng = np.random.default_rng(0)
    sigma = rng.uniform(-0.55, 0.55, (200, 3))
    w = rng.normal(size=(200, 3))
    np.testing.assert_allclose(rate_from_mrp(sigma, mrp_rate(sigma, w)), w, rtol=0, atol=1e-14)
    # single vectors work like arrays
    np.testing.assert_allclose(mrp_rate(sigma[0], w[0]), mrp_rate(sigma, w)[0], rtol=1e-15)
    # at sigma = 0: sigma' = w / 4 (theta ~ 4 sigma)
    np.testing.assert_allclose(mrp_rate([0.0, 0.0, 0.0], [1.0, 2.0, 3.0]), [0.25, 0.5, 0.75])


def test_mrp_kinematics_match_the_quaternion_kinematics():
    """d/dt mrp_to_quat(sigma) = 1/2 q o (0, w) for sigma' = F^sigma(sigma, w) (DESIGN.md convention)."""
    rng = np.random.default_rng(1)
    sigma = rng.uniform(-0.5, 0.5, (50, 3))
    w = rng.normal(size=(50, 3))
    sd = mrp_rate(sigma, w)
    eps = 1e-6
    q_dot_num = (rotations.mrp_to_quat(sigma + eps * sd) - rotations.mrp_to_quat(sigma - eps * sd)) / (2 * eps)
    q = rotations.mrp_to_quat(sigma)
    q_dot = 0.5 * rotations.quat_multiply(q, np.concatenate([np.zeros((50, 1)), w], axis=-1))
    np.testing.assert_allclose(q_dot_num, q_dot, atol=1e-9)


def test_dp45_step_is_fifth_order_and_its_estimate_bounds_the_error():
    q0, _ = _coning(0.0, 5 * DEG_RAD, 2.0)
    errors, estimates = [], []
    for h in (0.4, 0.2, 0.1):
        sigma, est = dp45_mrp_step(lambda c, h=h: _coning(np.array([c * h]), 5 * DEG_RAD, 2.0)[1], h)
        q1, _ = _coning(h, 5 * DEG_RAD, 2.0)
        exact = rotations.quat_multiply(rotations.quat_conjugate(q0), q1)
        errors.append(rotations.angle_between(rotations.mrp_to_quat(sigma[0]), exact))
        estimates.append(4 * est[0])
    errors, estimates = np.array(errors), np.array(estimates)
    orders = np.log2(errors[:-1] / errors[1:])
    assert np.all(orders > 5.5), orders  # local error O(h^6)
    assert np.all(errors < estimates)  # the embedded 4th-order estimate is conservative


def test_coning_drift_over_720_s_at_the_paper_step():
    """000 (ref. 7): coning at |w| = 0.5 deg/s, step 0.015625 s, 720 s: computational drift < 0.00025".
    Step rotations from sigma = 0 integrated all at once, then chained (the module's scheme)."""
    half_cone = 5 * DEG_RAD
    cone_rate = 0.5 * DEG_RAD / (2 * np.sin(half_cone))
    h = 1.0 / 64.0
    t = np.arange(0.0, 720.0, h)
    sigma, est = dp45_mrp_step(lambda c: _coning(t + c * h, half_cone, cone_rate)[1], h)
    _, w = _coning(t, half_cone, cone_rate)
    np.testing.assert_allclose(np.linalg.norm(w, axis=-1), 0.5 * DEG_RAD, rtol=1e-12)
    chain = quat_cumprod(rotations.mrp_to_quat(sigma))
    q_start, _ = _coning(0.0, half_cone, cone_rate)
    q_end, _ = _coning(720.0, half_cone, cone_rate)
    drift = rotations.angle_between(rotations.quat_multiply(q_start, chain[-1]), q_end)
    assert drift < 1e-6 * ARCSEC_RAD, drift / ARCSEC_RAD  # 250x below the paper's figure
    assert 4 * est.sum() < 1e-6 * ARCSEC_RAD


def test_dp45_from_a_nonzero_start_and_shapes():
    rng = np.random.default_rng(2)
    s0 = rng.uniform(-0.3, 0.3, (5, 3))
    w = rng.normal(size=(5, 3)) * 0.1
    sigma, err = dp45_mrp_step(lambda c: w, 0.01, sigma0=s0)
    # constant rate: q(h) = q(s0) o exp(w h)
    expected = rotations.quat_multiply(rotations.mrp_to_quat(s0), rotations.rotvec_to_quat(w * 0.01))
    np.testing.assert_allclose(rotations.angle_between(rotations.mrp_to_quat(sigma), expected), 0.0, atol=1e-15)
    assert err.shape == (5,)
    with pytest.raises(MrpKinematicsError, match=r"sigma0 must have shape \(\.\.\., 3\)"):
        dp45_mrp_step(lambda c: w, 0.01, sigma0=np.zeros((5, 2)))
    with pytest.raises(MrpKinematicsError, match="sigma must have shape"):
        mrp_rate(np.zeros(4), np.zeros(3))


@pytest.mark.parametrize("n", [1, 7, SCAN_BLOCK, SCAN_BLOCK + 1, 20 * SCAN_BLOCK + 3])
def test_quat_cumprod_equals_the_sequential_product(n):
    rng = np.random.default_rng(n)
    q = rotations.quat_normalize(np.array([1.0, 0.0, 0.0, 0.0]) + 0.3 * rng.normal(size=(n, 4)))
    out = quat_cumprod(q)
    acc = q[0]
    ref = [acc]
    for k in range(1, n):  # test only: the reference sequential product
        acc = rotations.quat_multiply(acc, q[k])
        ref.append(acc)
    np.testing.assert_allclose(out, np.array(ref) / np.linalg.norm(ref, axis=-1, keepdims=True), atol=1e-13)
    with pytest.raises(MrpKinematicsError, match=r"\(N, 4\)"):
        quat_cumprod(q[:, :3])


def test_quat_product_matches_rotations():
    rng = np.random.default_rng(3)
    p, q = rng.normal(size=(2, 10, 4))
    np.testing.assert_allclose(quat_product(p, q), rotations.quat_multiply(p, q), rtol=1e-15, atol=1e-15)
