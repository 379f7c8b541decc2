"""Gyro-grid kinematics and pseudo-derivatives (003 §2.2-2.3): scan, schemes, eq. 7."""

from __future__ import annotations

import numpy as np
import pytest

from processing.attitude import rotations as rot
from processing.gyro_calibration import propagation as gp


def sequential_product(kappa: np.ndarray) -> np.ndarray:
    out = np.empty_like(kappa)
    acc = np.array([1.0, 0.0, 0.0, 0.0])
    for i, k in enumerate(kappa):  # reference loop, test only
        acc = rot.quat_multiply(acc, k)
        out[i] = acc
    return out


@pytest.mark.parametrize("method", ["blocked", "doubling"])
@pytest.mark.parametrize("n", [1, 2, 5, gp.SCAN_BLOCK, gp.SCAN_BLOCK + 1, 257, 5000])
def test_cumprod_matches_sequential_product(n: int, method: str) -> None:
    rng = np.random.default_rng(n)
    kappa = rot.quat_normalize(rng.normal(size=(n, 4))) * rng.uniform(0.9, 1.1, (n, 1))  # non-unit too
    got = gp.quat_cumprod(kappa, method=method)
    want = sequential_product(kappa)
    assert got.shape == (n, 4)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * np.abs(want).max())


def test_cumprod_empty_and_bad_shape() -> None:
    assert gp.quat_cumprod(np.zeros((0, 4))).shape == (0, 4)
    with pytest.raises(gp.GyroPropagationError, match=r"kappa must have shape \(n, 4\), got \(3, 3\)"):
        gp.quat_cumprod(np.zeros((3, 3)))
    with pytest.raises(gp.GyroPropagationError, match="method must be 'blocked' or 'doubling', got 'x'"):
        gp.quat_cumprod(np.tile([1.0, 0, 0, 0], (100, 1)), method="x")


def test_step_quaternions_are_the_paper_formulas() -> None:
    rng = np.random.default_rng(1)
    dt = rng.uniform(0.05, 0.2, 50)
    w0, w1 = rng.normal(0, 0.3, (50, 3)), rng.normal(0, 0.3, (50, 3))
    tau = dt[:, None] / 4
    ones = np.ones((50, 1))
    # 003 §2.3 scheme 1: kappa = (1, tau w_k) o (1, -tau w_{k+1})^-1
    left = np.concatenate([ones, tau * w0], axis=1)
    right = np.concatenate([ones, -tau * w1], axis=1)
    inv_right = rot.quat_conjugate(right) / np.sum(right**2, axis=1, keepdims=True)
    np.testing.assert_allclose(gp.step_quaternions(dt, w0, w1, 1), rot.quat_multiply(left, inv_right), atol=1e-15)
    # 003's expanded form: (1 - tau² w_k.w_{k+1}, tau (w_k + w_{k+1}) + tau² w_k x w_{k+1}) / (1 + tau² |w_{k+1}|²)
    den = 1 + np.sum((tau * w1) ** 2, axis=1, keepdims=True)
    expanded = np.concatenate(
        [1 - np.sum(tau * w0 * tau * w1, axis=1, keepdims=True), tau * (w0 + w1) + np.cross(tau * w0, tau * w1)],
        axis=1,
    ) / den
    np.testing.assert_allclose(gp.step_quaternions(dt, w0, w1, 1), expanded, atol=1e-15)
    # scheme 2 with the midpoint rate: ((1 - tau²|w|²), 2 tau w) / (1 + tau²|w|²), unit norm
    wm = 0.5 * (w0 + w1)
    vv = np.sum((tau * wm) ** 2, axis=1, keepdims=True)
    k2 = gp.step_quaternions(dt, w0, w1, 2)
    np.testing.assert_allclose(k2, np.concatenate([1 - vv, 2 * tau * wm], axis=1) / (1 + vv), atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(k2, axis=1), 1.0, atol=1e-15)


def analytic_motion(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """q(t) = exp(phi(t) n / 2) o exp(psi(t) m / 2), fixed axes n, m; w = phi' R(B)^T n + psi' m."""
    n = np.array([0.3, -0.5, 0.81])
    n /= np.linalg.norm(n)
    m = np.array([1.0, 0.2, -0.1])
    m /= np.linalg.norm(m)
    phi, dphi = 0.4 * np.sin(0.7 * t) + 0.05 * t, 0.28 * np.cos(0.7 * t) + 0.05
    psi, dpsi = 0.3 * t + 0.2 * np.cos(1.3 * t), 0.3 - 0.26 * np.sin(1.3 * t)
    a = rot.rotvec_to_quat(phi[:, None] * n)
    b = rot.rotvec_to_quat(psi[:, None] * m)
    w = dphi[:, None] * rot.quat_rotate(rot.quat_conjugate(b), np.broadcast_to(n, b[:, 1:].shape)) + dpsi[:, None] * m
    return rot.quat_multiply(a, b), w


@pytest.mark.parametrize("scheme", [1, 2])
def test_schemes_are_second_order_against_an_analytic_motion(scheme: int) -> None:
    errors = []
    for h in (0.02, 0.01):
        t = np.arange(0.0, 60.0 + h / 2, h)
        q_true, w = analytic_motion(t)
        p = gp.propagate(t, w, t, scheme=scheme, derivatives=False)
        q = rot.quat_multiply(q_true[0], p.u_out)
        errors.append(float(np.max(rot.angle_between(q_true, rot.quat_normalize(q)))))
    assert errors[0] < 2e-4  # rad, at |w| ~ 0.4 rad/s and h = 0.02 s
    assert 3.6 < errors[0] / errors[1] < 4.4  # O(h²) global error


def test_schemes_agree_to_truncation_error_and_norms() -> None:
    diffs = []
    for h in (0.1, 0.05):
        t = np.arange(0.0, 1200.0 + h / 2, h)
        _, w = analytic_motion(t)
        w = 0.01 * w  # ~4e-3 rad/s, |w'| ~ 3e-3 rad/s²
        p1 = gp.propagate(t, w, t, scheme=1, derivatives=False)
        p2 = gp.propagate(t, w, t, scheme=2, derivatives=False)
        diffs.append(float(np.max(rot.angle_between(rot.quat_normalize(p1.u_out), p2.u_out))))
    # the schemes differ by their O(h²) truncation errors: ~ h² |w| |w'| T / 12 ~ 1e-6 rad at h = 0.1 s
    assert diffs[0] < 5e-6
    assert 3.6 < diffs[0] / diffs[1] < 4.4
    # scheme 2 keeps |q| = 1 over 12,000 steps (003 §2.3)
    np.testing.assert_allclose(np.linalg.norm(p2.u_out, axis=1), 1.0, atol=1e-13)
    # scheme 1 norm: |p_K| = sqrt((1 + tau²|w_0|²) / (1 + tau²|w_K|²)) (003 §2.3, the product telescopes)
    tau2 = (0.05 / 4) ** 2
    want = np.sqrt((1 + tau2 * np.sum(w[0] ** 2)) / (1 + tau2 * np.sum(w**2, axis=1)))
    np.testing.assert_allclose(np.linalg.norm(p1.u_out, axis=1), want, rtol=1e-12)


def test_outputs_between_nodes_are_partial_steps() -> None:
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.08, 0.12, 200))
    w = rng.normal(0, 0.01, (200, 3))
    at_nodes = gp.propagate(t, w, t, scheme=2)
    # outputs exactly at nodes, including the last, reproduce the node products
    np.testing.assert_allclose(at_nodes.u_out, np.vstack([[1, 0, 0, 0], gp.quat_cumprod(
        gp.step_quaternions(np.diff(t), w[:-1], w[1:], 2))]), atol=1e-14)
    # an output inside a step equals a step of the same scheme with the interpolated rate
    k, f = 57, 0.3
    t_mid = t[k] + f * (t[k + 1] - t[k])
    one = gp.propagate(t, w, [t_mid], scheme=2)
    w_mid = (1 - f) * w[k] + f * w[k + 1]
    kap = gp.step_quaternions([t_mid - t[k]], w[k][None], w_mid[None], 2)
    np.testing.assert_allclose(one.u_out[0], rot.quat_multiply(at_nodes.u_out[k], kap[0]), atol=1e-15)


def central_psi(t: np.ndarray, w: np.ndarray, t_out: np.ndarray, scheme: int, dw: np.ndarray) -> np.ndarray:
    """psi = 2 vec(U^-1 dU) by central differences along the rate perturbation dw (N, 3)."""
    eps = 1e-6
    up = gp.propagate(t, w + eps * dw, t_out, scheme=scheme, derivatives=False).u_out
    um = gp.propagate(t, w - eps * dw, t_out, scheme=scheme, derivatives=False).u_out
    u = gp.propagate(t, w, t_out, scheme=scheme, derivatives=False).u_out
    inv = rot.quat_conjugate(u) / np.sum(u**2, axis=1, keepdims=True)
    return 2 * rot.quat_multiply(inv, (up - um) / (2 * eps))[:, 1:]


@pytest.mark.parametrize("scheme", [1, 2])
def test_pseudo_derivatives_are_the_exact_linearisation(scheme: int) -> None:
    rng = np.random.default_rng(scheme)
    t = np.cumsum(rng.uniform(0.08, 0.12, 400))
    w = rng.normal(0, 0.05, (400, 3)) + [0.0, 0.3, 0.0]
    t_out = np.sort(rng.uniform(t[0], t[-1], 40))
    # offsets Delta (003 eq. 7, forcing e_k)
    p = gp.propagate(t, w, t_out, scheme=scheme)
    for k in range(3):
        dw = np.zeros((400, 3))
        dw[:, k] = 1.0
        np.testing.assert_allclose(p.psi_out[:, :, k], central_psi(t, w, t_out, scheme, dw), atol=2e-7 * 40)
    # a general rate Jacobian: a small rotation of the rate axes, dw = -[w x] dmu
    cross = -np.stack([np.cross(np.eye(3)[k], w) for k in range(3)], axis=-1)  # d(w + mu x w)/dmu_k = e_k x w
    pm = gp.propagate(t, w, t_out, scheme=scheme, rate_jacobian=cross)
    for k in range(3):
        np.testing.assert_allclose(pm.psi_out[:, :, k], central_psi(t, w, t_out, scheme, cross[:, :, k]), atol=1e-5)


@pytest.mark.parametrize("scheme", [1, 2])
def test_pseudo_derivatives_match_the_papers_cramer_scheme(scheme: int) -> None:
    """003 §2.3 solves, per step and by Cramer's rule, scheme 1:
    (I + h/2 [w_{k+1} x]) xi_{k+1} = (I - h/2 [w_k x]) xi_k + h eta, and scheme 2 the same with the
    midpoint rate on both sides. The vectorised exact linearisation of the kappa recursion and 003's
    schemes are O(h²) discretisations of eq. 7 that differ by O(h³ |w|²) per step."""
    h = 0.1
    t = np.arange(0.0, 120.0 + h / 2, h)
    _, w = analytic_motion(t)
    w = 0.05 * w
    p = gp.propagate(t, w, t, scheme=scheme)
    xi = np.zeros((t.size, 3, 3))
    eye = np.eye(3)
    for k in range(t.size - 1):  # reference loop, test only
        w_l, w_r = (w[k], w[k + 1]) if scheme == 1 else ((w[k] + w[k + 1]) / 2,) * 2
        lhs = eye + h / 2 * rot.skew(w_r)
        rhs = (eye - h / 2 * rot.skew(w_l)) @ xi[k] + h * eye
        xi[k + 1] = np.linalg.solve(lhs, rhs)
    scale = np.abs(xi).max()  # ~ T
    assert np.max(np.abs(p.psi_out - xi)) < 1e-6 * scale


def test_mrp_pseudo_derivatives_against_finite_differences() -> None:
    z = np.array([0.11, -0.32, 0.27])
    m = gp.mrp_pseudo_derivatives(z)
    p = rot.mrp_to_quat(z)
    eps = 1e-7
    for k in range(3):
        dz = np.zeros(3)
        dz[k] = eps
        dp = (rot.mrp_to_quat(z + dz) - rot.mrp_to_quat(z - dz)) / (2 * eps)
        psi = 2 * rot.quat_multiply(rot.quat_conjugate(p), dp)  # dp/dz = 1/2 p o psi (003 §2.2)
        assert abs(psi[0]) < 1e-8
        np.testing.assert_allclose(m[:, k], psi[1:], atol=1e-8)
    # at z = 0: s = 4, p = 1, dPsi/dz = 4 I (a small rotation theta has z = theta / 4)
    np.testing.assert_allclose(gp.mrp_pseudo_derivatives(np.zeros(3)), 4 * np.eye(3))


def test_scalar_and_batch_paths_agree() -> None:
    rng = np.random.default_rng(5)
    dt = rng.uniform(0.05, 0.2, 7)
    w0, w1 = rng.normal(0, 0.3, (7, 3)), rng.normal(0, 0.3, (7, 3))
    for scheme in (1, 2):
        a, b = gp.step_rate_jacobians(dt, w0, w1, scheme)
        for i in range(7):
            ai, bi = gp.step_rate_jacobians(dt[i : i + 1], w0[i : i + 1], w1[i : i + 1], scheme)
            np.testing.assert_array_equal(ai[0], a[i])
            np.testing.assert_array_equal(bi[0], b[i])
        # A + B = dt I - dt²/2 [w x] + O(dt³)
        w_max = np.abs(np.concatenate([w0, w1])).max()
        np.testing.assert_allclose(a + b, dt[:, None, None] * np.eye(3), atol=dt.max() ** 2 * w_max)


def test_errors_say_what_was_expected() -> None:
    t = np.arange(5.0)
    w = np.zeros((5, 3))
    with pytest.raises(gp.GyroPropagationError, match="strictly increasing"):
        gp.propagate(t[::-1], w, [1.0])
    with pytest.raises(gp.GyroPropagationError, match=r"w must have shape \(5, 3\) matching t_s, got \(4, 3\)"):
        gp.propagate(t, w[:4], [1.0])
    with pytest.raises(gp.GyroPropagationError, match=r"t_out must lie within the gyro grid \[0.0, 4.0\] s"):
        gp.propagate(t, w, [4.5])
    with pytest.raises(gp.GyroPropagationError, match="scheme must be 1 .* or 2"):
        gp.propagate(t, w, [1.0], scheme=3)
    with pytest.raises(gp.GyroPropagationError, match=r"rate_jacobian must have shape \(5, 3, m\)"):
        gp.propagate(t, w, [1.0], rate_jacobian=np.zeros((5, 3)))


def whole_grid_forcing(grid: gp._Grid, u_nodes: np.ndarray, scheme: int) -> np.ndarray:
    """S_k (3, m, N) as one cumulative sum over (3, 3, N) arrays (the unchunked form, test only)."""
    g = gp._step_forcing(grid, 0, grid.dt.size, scheme)
    forcing = np.zeros((3, grid.m, grid.t.size))
    np.cumsum(gp._matmul_cf(gp._dcm_cf(u_nodes[:, 1:]), g), axis=-1, out=forcing[:, :, 1:])
    return forcing


@pytest.mark.parametrize("scheme", [1, 2])
@pytest.mark.parametrize("chunk", [1, 7, 64, 10_000])
@pytest.mark.parametrize("mounting", [False, True])
def test_chunked_forcing_sums_are_bit_identical(scheme: int, chunk: int, mounting: bool,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """The step quaternions and the forcing sums made CHUNK steps at a time equal the whole-grid forms bit for
    bit, outputs on chunk boundaries, on the first and last node and repeated included."""
    rng = np.random.default_rng(11)
    n = 300
    t = np.cumsum(rng.uniform(0.08, 0.12, n))
    w = rng.normal(0, 0.05, (n, 3)) + [0.0, 0.3, 0.0]
    jac = -np.stack([np.cross(np.eye(3)[k], w) for k in range(3)], axis=-1) if mounting else None
    t_out = np.sort(np.concatenate([rng.uniform(t[0], t[-1], 50), t[[0, 7, 7, 14, 64, 128, -1]]]))
    monkeypatch.setattr(gp, "CHUNK", chunk)
    grid = gp._grid(t, w, t_out, jac)
    u_nodes = gp._node_attitudes(grid, scheme)
    whole = gp._cumprod_cf(gp._kappa_cf(0.25 * grid.dt, grid.wc[:, :-1], grid.wc[:, 1:], scheme))
    np.testing.assert_array_equal(u_nodes[:, 1:], whole)
    out = gp._output_steps(grid, u_nodes, scheme)
    expected = whole_grid_forcing(grid, u_nodes, scheme)[:, :, out.k]
    np.testing.assert_array_equal(gp._forcing_at(grid, u_nodes, out.k, scheme), expected)
    shuffled = np.random.default_rng(3).permutation(out.k.size)  # output times in any order
    got = gp._forcing_at(grid, u_nodes, out.k[shuffled], scheme)
    np.testing.assert_array_equal(got, expected[:, :, shuffled])


@pytest.mark.parametrize("n", [1, 5, gp.SCAN_BLOCK, gp.SCAN_BLOCK + 1, 257, 6000, 5000])
def test_cumprod_into_out_is_the_same(n: int) -> None:
    kappa = rot.quat_normalize(np.random.default_rng(n).normal(size=(4, n)).T).T.copy()
    dest = np.full((4, n + 3), np.nan)
    got = gp._cumprod_cf(kappa, out=dest[:, 2:-1])
    np.testing.assert_array_equal(got, gp._cumprod_cf(kappa))
    np.testing.assert_array_equal(dest[:, 2:-1], gp._cumprod_cf(kappa))
    assert np.all(np.isnan(dest[:, :2])) and np.all(np.isnan(dest[:, -1]))


def test_outputs_in_any_order() -> None:
    """propagate at unsorted output times gives each time what the sorted call gives (bit for bit)."""
    rng = np.random.default_rng(12)
    t = np.cumsum(rng.uniform(0.08, 0.12, 500))
    w = rng.normal(0, 0.05, (500, 3))
    t_out = rng.uniform(t[0], t[-1], 60)
    order = np.argsort(t_out)
    p, ps = gp.propagate(t, w, t_out), gp.propagate(t, w, t_out[order])
    np.testing.assert_array_equal(p.psi_out[order], ps.psi_out)
    np.testing.assert_array_equal(p.u_out[order], ps.u_out)
