"""Kernels of the Wahba solvers (processing.attitude.wahba): each takes the nine components of the
attitude profile matrix B (elementwise arrays over a chunk of epochs) and lambda0 = sum a_i, and returns
(q unnormalised, lambda_max, converged, iterations). QUEST and ESOQ2 are elementwise numpy (Newton on the
characteristic quartic of K, Shuster & Oh 1981; Mortari 1997), the q-method and the SVD method batched
LAPACK. Conventions and references: see processing.attitude.wahba.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from processing.attitude import rotations

__all__ = [
    "SMALL_Q0",
    "Kernel",
    "KernelOut",
    "esoq2_kernel",
    "k_from_profile_matrix",
    "q_method_kernel",
    "quest_kernel",
    "svd_kernel",
]

SMALL_Q0 = 0.1
"""QUEST uses the classical column (Gibbs-vector form) when |q0| >= this, else the rotated frame."""

FloatArray = NDArray[np.float64]
KernelOut = tuple[FloatArray, FloatArray, NDArray[np.bool_], int]
Kernel = Callable[[list[FloatArray], FloatArray, float, int], KernelOut]
"""A solver on the nine components of B: returns (q unnormalised, lambda_max, converged, iterations)."""


def k_from_profile_matrix(B: FloatArray) -> FloatArray:
    """Davenport's K (..., 4, 4) for the Hamilton scalar-first q_BR from B (..., 3, 3)."""
    S = B + np.swapaxes(B, -1, -2)
    sigma = np.trace(B, axis1=-2, axis2=-1)
    z = np.stack([B[..., 1, 2] - B[..., 2, 1], B[..., 2, 0] - B[..., 0, 2], B[..., 0, 1] - B[..., 1, 0]], axis=-1)
    K = np.empty(B.shape[:-2] + (4, 4))
    K[..., 0, 0] = sigma
    K[..., 0, 1:] = -z
    K[..., 1:, 0] = -z
    K[..., 1:, 1:] = S - sigma[..., None, None] * np.eye(3)
    return K


def _lambda_max(b: list[FloatArray], lam0: FloatArray, tol: float, max_iter: int
                ) -> tuple[FloatArray, NDArray[np.bool_], int, tuple[FloatArray, ...]]:
    """Newton-Raphson for the largest root of the characteristic quartic of K (Shuster & Oh 1981).

    f(l) = l^4 - (a + b) l^2 - c l + (a b + c sigma - d), a = sigma^2 - kappa, b = sigma^2 + z.z,
    c = det S + z^T S z, d = z^T S^2 z, kappa = tr adj S; started at lambda0 = sum a_i.
    """
    b00, b01, b02, b10, b11, b12, b20, b21, b22 = b
    sigma = b00 + b11 + b22
    s00, s11, s22 = 2 * b00, 2 * b11, 2 * b22
    s01, s02, s12 = b01 + b10, b02 + b20, b12 + b21
    z0, z1, z2 = b12 - b21, b20 - b02, b01 - b10
    kappa = s11 * s22 - s12 * s12 + s00 * s22 - s02 * s02 + s00 * s11 - s01 * s01
    det_s = s00 * (s11 * s22 - s12 * s12) - s01 * (s01 * s22 - s12 * s02) + s02 * (s01 * s12 - s11 * s02)
    sz0 = s00 * z0 + s01 * z1 + s02 * z2
    sz1 = s01 * z0 + s11 * z1 + s12 * z2
    sz2 = s02 * z0 + s12 * z1 + s22 * z2
    zz = z0 * z0 + z1 * z1 + z2 * z2
    zsz = z0 * sz0 + z1 * sz1 + z2 * sz2
    zs2z = sz0 * sz0 + sz1 * sz1 + sz2 * sz2
    sig2 = sigma * sigma
    ca = sig2 - kappa
    cb = sig2 + zz
    cc = det_s + zsz
    apb = ca + cb
    const = ca * cb + cc * sigma - zs2z
    lam = lam0.copy()
    done = np.zeros(lam.shape, dtype=bool)
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is reported
        lam2 = lam * lam
        f = (lam2 - apb) * lam2 - cc * lam + const
        fp = (4.0 * lam2 - 2.0 * apb) * lam - cc
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.where(fp != 0.0, f / fp, 0.0)
        lam = lam - step
        done = np.abs(step) <= tol * np.maximum(lam0, np.finfo(float).tiny)
        if done.all():
            break
    lam2 = lam * lam
    fp = (4.0 * lam2 - 2.0 * apb) * lam - cc  # f'(lambda_max) = prod over the other eigenvalues of (lambda - l_k)
    return lam, done, it, (sigma, s00, s11, s22, s01, s02, s12, z0, z1, z2, fp)


def _quest_column(b: list[FloatArray], lam: FloatArray, k: NDArray[np.intp]) -> FloatArray:
    """Hamilton q (unnormalised) from column 0 of adj(lambda I - K') in the reference frame turned by
    180 deg about axis k - 1 (k = 0: not turned): (gamma', -X') o (0, -e_k)."""
    sg0 = np.where((k == 1) | (k == 0), 1.0, -1.0)
    sg1 = np.where((k == 2) | (k == 0), 1.0, -1.0)
    sg2 = np.where((k == 3) | (k == 0), 1.0, -1.0)
    b00, b01, b02, b10, b11, b12, b20, b21, b22 = b
    c00, c01, c02 = b00 * sg0, b01 * sg1, b02 * sg2
    c10, c11, c12 = b10 * sg0, b11 * sg1, b12 * sg2
    c20, c21, c22 = b20 * sg0, b21 * sg1, b22 * sg2
    sig = c00 + c11 + c22
    y0, y1, y2 = c12 - c21, c20 - c02, c01 - c10
    lps = lam + sig
    n00, n11, n22 = lps - 2 * c00, lps - 2 * c11, lps - 2 * c22
    n01, n02, n12 = -(c01 + c10), -(c02 + c20), -(c12 + c21)
    # adj(M3') z' (X of QUEST) and det M3' (gamma), M3' = (lambda + sigma') I - S'.
    a00 = n11 * n22 - n12 * n12
    a11 = n00 * n22 - n02 * n02
    a22 = n00 * n11 - n01 * n01
    a01 = n02 * n12 - n01 * n22
    a02 = n01 * n12 - n02 * n11
    a12 = n01 * n02 - n00 * n12
    p0 = n00 * a00 + n01 * a01 + n02 * a02
    p1 = -(a00 * y0 + a01 * y1 + a02 * y2)
    p2 = -(a01 * y0 + a11 * y1 + a12 * y2)
    p3 = -(a02 * y0 + a12 * y1 + a22 * y2)
    e0 = (k == 1).astype(float)
    e1 = (k == 2).astype(float)
    e2 = (k == 3).astype(float)
    rot = k > 0
    # (p0, p) o (0, -e) = (p.e, -p0 e - p x e)
    r0 = p1 * e0 + p2 * e1 + p3 * e2
    r1 = -p0 * e0 - (p2 * e2 - p3 * e1)
    r2 = -p0 * e1 - (p3 * e0 - p1 * e2)
    r3 = -p0 * e2 - (p1 * e1 - p2 * e0)
    return np.stack([np.where(rot, r0, p0), np.where(rot, r1, p1), np.where(rot, r2, p2), np.where(rot, r3, p3)], -1)


def quest_kernel(b: list[FloatArray], lam0: FloatArray, tol: float, max_iter: int) -> KernelOut:
    lam, done, it, (sigma, s00, s11, s22, s01, s02, s12, z0, z1, z2, fp) = _lambda_max(b, lam0, tol, max_iter)
    # Classical QUEST column: q = (gamma, -X) with gamma = det M3 = c q0^2 and X = adj(M3) z = c q0 qv
    # (Shuster's sign), c = f'(lambda_max); so |(gamma, X)| = |c| |q0| measures how small q0 is.
    lps = lam + sigma
    m00, m11, m22 = lps - s00, lps - s11, lps - s22  # M3 = (lambda + sigma) I - S; off-diagonal -s
    a00 = m11 * m22 - s12 * s12
    a11 = m00 * m22 - s02 * s02
    a22 = m00 * m11 - s01 * s01
    a01 = s01 * m22 + s02 * s12
    a02 = s01 * s12 + s02 * m11
    a12 = m00 * s12 + s01 * s02
    gamma = m00 * a00 - s01 * a01 - s02 * a02
    q = np.stack([gamma, -(a00 * z0 + a01 * z1 + a02 * z2), -(a01 * z0 + a11 * z1 + a12 * z2),
                  -(a02 * z0 + a12 * z1 + a22 * z2)], axis=-1)
    small = np.sqrt((q * q).sum(axis=1)) < SMALL_Q0 * np.abs(fp)
    if np.any(small):
        # Near 180 deg: turn the reference frame by 180 deg about the axis k whose diagonal cofactor
        # c q_k^2 of H = lambda I - K is the largest, so the column used is never small.
        bs = [x[small] for x in b]
        lm, bt = lam[small], (lam - sigma)[small]
        n00, n11, n22 = m00[small], m11[small], m22[small]
        t01, t02, t12 = s01[small], s02[small], s12[small]
        y0, y1, y2 = z0[small], z1[small], z2[small]
        d0 = n00 * (n11 * n22 - t12 * t12) - t01 * (t01 * n22 + t12 * t02) - t02 * (t01 * t12 + n11 * t02)
        d1 = bt * (n11 * n22 - t12 * t12) - (n22 * y1 * y1 + 2.0 * t12 * y1 * y2 + n11 * y2 * y2)
        d2 = bt * (n00 * n22 - t02 * t02) - (n22 * y0 * y0 + 2.0 * t02 * y0 * y2 + n00 * y2 * y2)
        d3 = bt * (n00 * n11 - t01 * t01) - (n11 * y0 * y0 + 2.0 * t01 * y0 * y1 + n00 * y1 * y1)
        k = np.argmax(np.stack([d0, d1, d2, d3]), axis=0)
        q[small] = _quest_column(bs, lm, k)
    return q, lam, done, it


def esoq2_kernel(b: list[FloatArray], lam0: FloatArray, tol: float, max_iter: int) -> KernelOut:
    lam, done, it, _ = _lambda_max(b, lam0, tol, max_iter)
    b00, b01, b02, b10, b11, b12, b20, b21, b22 = b
    k = np.argmin(np.stack([b00, b11, b22]), axis=0)
    sg0 = np.where(k == 0, 1.0, -1.0)
    sg1 = np.where(k == 1, 1.0, -1.0)
    sg2 = np.where(k == 2, 1.0, -1.0)
    c00, c01, c02 = b00 * sg0, b01 * sg1, b02 * sg2
    c10, c11, c12 = b10 * sg0, b11 * sg1, b12 * sg2
    c20, c21, c22 = b20 * sg0, b21 * sg1, b22 * sg2
    sig = c00 + c11 + c22
    z0, z1, z2 = c12 - c21, c20 - c02, c01 - c10
    beta = lam - sig
    lps = lam + sig
    # M = beta ((lambda + sigma) I - S) - z z^T (symmetric 3x3); e = null vector.
    m00 = beta * (lps - 2 * c00) - z0 * z0
    m11 = beta * (lps - 2 * c11) - z1 * z1
    m22 = beta * (lps - 2 * c22) - z2 * z2
    m01 = -beta * (c01 + c10) - z0 * z1
    m02 = -beta * (c02 + c20) - z0 * z2
    m12 = -beta * (c12 + c21) - z1 * z2
    # Rows of adj(M) = c e e^T; take the row with the largest diagonal.
    a00 = m11 * m22 - m12 * m12
    a11 = m00 * m22 - m02 * m02
    a22 = m00 * m11 - m01 * m01
    a01 = m02 * m12 - m01 * m22
    a02 = m01 * m12 - m02 * m11
    a12 = m01 * m02 - m00 * m12
    j = np.argmax(np.stack([np.abs(a00), np.abs(a11), np.abs(a22)]), axis=0)
    e0 = np.where(j == 0, a00, np.where(j == 1, a01, a02))
    e1 = np.where(j == 0, a01, np.where(j == 1, a11, a12))
    e2 = np.where(j == 0, a02, np.where(j == 1, a12, a22))
    # Shuster qbar' = (beta e, z.e); Hamilton q' = (z.e, -beta e); q = q' o (0, -e_k).
    p0 = z0 * e0 + z1 * e1 + z2 * e2
    p1, p2, p3 = -beta * e0, -beta * e1, -beta * e2
    u0 = (k == 0).astype(float)
    u1 = (k == 1).astype(float)
    u2 = (k == 2).astype(float)
    r0 = p1 * u0 + p2 * u1 + p3 * u2
    r1 = -p0 * u0 - (p2 * u2 - p3 * u1)
    r2 = -p0 * u1 - (p3 * u0 - p1 * u2)
    r3 = -p0 * u2 - (p1 * u1 - p2 * u0)
    return np.stack([r0, r1, r2, r3], axis=-1), lam, done, it


def q_method_kernel(b: list[FloatArray], lam0: FloatArray, tol: float, max_iter: int) -> KernelOut:
    B = np.stack(b, axis=-1).reshape(-1, 3, 3)
    vals, vecs = np.linalg.eigh(k_from_profile_matrix(B))
    return vecs[:, :, -1], vals[:, -1], np.ones(B.shape[0], dtype=bool), 0


def svd_kernel(b: list[FloatArray], lam0: FloatArray, tol: float, max_iter: int) -> KernelOut:
    B = np.stack(b, axis=-1).reshape(-1, 3, 3)
    U, sv, Vt = np.linalg.svd(B)
    d = np.linalg.det(U) * np.linalg.det(Vt)
    U[:, :, 2] *= d[:, None]
    lam = sv[:, 0] + sv[:, 1] + d * sv[:, 2]  # Markley 1988: lambda_max = s1 + s2 + d s3
    return rotations.dcm_to_quat(U @ Vt), lam, np.ones(B.shape[0], dtype=bool), 0
