"""Kinematics in modified Rodrigues parameters (000), its Dormand-Prince integration, quaternion chaining.

Paper 000 (Somov & Butyrin 2016) writes the attitude as the MRP vector sigma = e tan(theta/4)
(sigma = lambda / (1 + lambda_0) of the quaternion Lambda = (lambda_0, lambda)) and uses the forward
and inverse kinematic equations (000, the unnumbered pair before "Постановка задачи"):

    sigma' = F^sigma(sigma, w) = 1/4 (1 - sigma^2) w + 1/2 sigma x w + 1/2 sigma <sigma, w>,
    w = F^w(sigma, sigma') = 4 [(1 - sigma^2) sigma' - 2 sigma x sigma' + 2 sigma <sigma', sigma>] / (1 + sigma^2)^2,

with w the angular rate of the frame in its own axes, so that (in our convention, DESIGN.md) the
quaternion q_IX(sigma) obeys q' = 1/2 q o w. Eq. (7) integrates sigma' = F^sigma(sigma, w(tau)) over
each star-tracker period "by ODE45" (Dormand-Prince 5(4), Shampine 1986 = 000 ref. 18).

Here one Dormand-Prince 5(4) step is taken per step of a caller-given grid, *from sigma = 0*: the
rotation over a step does not depend on the attitude at its start (q(t + h) = q(t) o q_step, the
kinematics are invariant under a constant left factor), so every step of a long record is integrated at
once, vectorised, and the attitude follows by chaining the step quaternions (:func:`quat_cumprod`).
Starting from zero keeps |sigma| ~ theta/4 tiny (no shadow-set switching) and is mathematically the
same solution of (7) as starting from the absolute MRP. The embedded 4th-order solution gives the
local error estimate of each step, returned with the result.

Shapes: vectors (..., 3), quaternions (..., 4) scalar first; rates rad/s; times s.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DP45_NODES",
    "MrpKinematicsError",
    "dp45_mrp_step",
    "mrp_rate",
    "quat_cumprod",
    "quat_product",
    "rate_from_mrp",
]

FloatArray = NDArray[np.float64]

DP45_NODES = (0.0, 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0, 1.0, 1.0)
"""Stage nodes c_i of the Dormand-Prince 5(4) pair (the last stage is FSAL, at the step's end)."""
_DP_A = (
    (),
    (1.0 / 5.0,),
    (3.0 / 40.0, 9.0 / 40.0),
    (44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0),
    (19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0),
    (9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0, -5103.0 / 18656.0),
    (35.0 / 384.0, 0.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0),
)
_DP_B5 = _DP_A[6] + (0.0,)
_DP_B4 = (5179.0 / 57600.0, 0.0, 7571.0 / 16695.0, 393.0 / 640.0, -92097.0 / 339200.0, 187.0 / 2100.0, 1.0 / 40.0)
_DP_E = tuple(b5 - b4 for b5, b4 in zip(_DP_B5, _DP_B4, strict=True))

SCAN_BLOCK = 64
"""Block length of the two-level prefix product in :func:`quat_cumprod`."""


class MrpKinematicsError(ValueError):
    """Bad input to the MRP kinematics: shapes that do not match (..., 3) / (..., 4)."""


def _vec(x: ArrayLike, name: str) -> FloatArray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim < 1 or a.shape[-1] != 3:
        raise MrpKinematicsError(f"{name} must have shape (..., 3), got {a.shape}")
    return a


def mrp_rate(sigma: ArrayLike, w: ArrayLike) -> FloatArray:
    """F^sigma(sigma, w): MRP rate (..., 3) [1/s] of the frame turning at w (..., 3) [rad/s] in its axes.

    000, forward MRP kinematics: 1/4 (1 - |sigma|^2) w + 1/2 sigma x w + 1/2 sigma <sigma, w>.
    """
    s, w = _vec(sigma, "sigma"), _vec(w, "w")
    s2 = np.sum(s * s, axis=-1, keepdims=True)
    sw = np.sum(s * w, axis=-1, keepdims=True)
    return 0.25 * (1.0 - s2) * w + 0.5 * np.cross(s, w) + 0.5 * sw * s


def rate_from_mrp(sigma: ArrayLike, sigma_dot: ArrayLike) -> FloatArray:
    """F^w(sigma, sigma'): angular rate (..., 3) [rad/s] in the frame's own axes, inverse of :func:`mrp_rate`.

    000, inverse MRP kinematics: 4 [(1 - |sigma|^2) sigma' - 2 sigma x sigma' + 2 sigma <sigma', sigma>]
    / (1 + |sigma|^2)^2 (003 §1.3 gives the same formula for its z).
    """
    s, d = _vec(sigma, "sigma"), _vec(sigma_dot, "sigma_dot")
    s2 = np.sum(s * s, axis=-1, keepdims=True)
    sd = np.sum(s * d, axis=-1, keepdims=True)
    return 4.0 * ((1.0 - s2) * d - 2.0 * np.cross(s, d) + 2.0 * sd * s) / (1.0 + s2) ** 2


def _f(sx: FloatArray, sy: FloatArray, sz: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """F^sigma on component arrays (faster than the (..., 3) form in the inner loop)."""
    wx, wy, wz = w[..., 0], w[..., 1], w[..., 2]
    a = 0.25 * (1.0 - (sx * sx + sy * sy + sz * sz))
    b = 0.5 * (sx * wx + sy * wy + sz * wz)
    return (
        a * wx + 0.5 * (sy * wz - sz * wy) + b * sx,
        a * wy + 0.5 * (sz * wx - sx * wz) + b * sy,
        a * wz + 0.5 * (sx * wy - sy * wx) + b * sz,
    )


def dp45_mrp_step(
    rate_at: Callable[[float], FloatArray], h_s: ArrayLike, sigma0: ArrayLike | None = None
) -> tuple[FloatArray, FloatArray]:
    """One Dormand-Prince 5(4) step of eq. (7), sigma' = F^sigma(sigma, w(tau)), for many steps at once.

    rate_at(c) -> (N, 3) rad/s: the rate of each step at its local time tau = c h, for the nodes c of
    :data:`DP45_NODES` (called six times, c = 1 once). h_s: (N,) or scalar step lengths [s].
    sigma0: (N, 3) initial MRPs, default 0 (the step's own rotation, see the module docstring).
    Returns sigma (N, 3) at tau = h (5th order) and the local error estimate (N,) = |sigma5 - sigma4|,
    i.e. about a quarter of the angle error [rad] of each step. 000, eq. (7) with ODE45.
    """
    h = np.asarray(h_s, dtype=np.float64)
    w0 = np.asarray(rate_at(0.0), dtype=np.float64)
    n = w0.shape[0]
    h = np.broadcast_to(h, (n,))
    if sigma0 is None:
        s0 = (np.zeros(n), np.zeros(n), np.zeros(n))
    else:
        s_arr = _vec(sigma0, "sigma0")
        s0 = (s_arr[:, 0], s_arr[:, 1], s_arr[:, 2])
    ks: list[tuple[FloatArray, FloatArray, FloatArray]] = []
    w_cache = {0.0: w0}
    stage: tuple[FloatArray, ...] = s0
    for i, c in enumerate(DP45_NODES):
        if i > 0:
            stage = tuple(
                s0[j] + h * sum(a * k[j] for a, k in zip(_DP_A[i], ks, strict=False) if a != 0.0) for j in range(3)
            )
        w = w_cache.get(c)
        if w is None:
            w = w_cache[c] = np.asarray(rate_at(c), dtype=np.float64)
        ks.append(_f(stage[0], stage[1], stage[2], w))
    sigma5 = stage  # the 7th stage is evaluated at the 5th-order solution (FSAL: a_7j = b_j)
    sigma = np.stack(sigma5, axis=-1)
    err = np.sqrt(sum((h * sum(e * k[j] for e, k in zip(_DP_E, ks, strict=True) if e != 0.0)) ** 2 for j in range(3)))
    return sigma, np.asarray(err)


def quat_product(p: FloatArray, q: FloatArray) -> FloatArray:
    """Hamilton product p o q of (..., 4) arrays of equal shape, without input checks (inner loops;
    processing.attitude.rotations.quat_multiply is the checked, broadcasting version)."""
    p0, p1, p2, p3 = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    q0, q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty(np.broadcast_shapes(p.shape, q.shape))
    out[..., 0] = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
    out[..., 1] = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
    out[..., 2] = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
    out[..., 3] = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0
    return out


def quat_cumprod(q: ArrayLike) -> FloatArray:
    """Prefix products C_k = q_0 o q_1 o ... o q_k of (N, 4) quaternions (Hamilton), renormalised.

    Chains step rotations: with q_k the rotation over step k (q(t_{k+1}) = q(t_k) o q_k), C_k is the
    rotation from t_0 to t_{k+1}. Two-level scan: products inside blocks of :data:`SCAN_BLOCK`
    (vectorised over blocks), then the block totals recursively, then one broadcast product; no
    Python loop over samples. Rounding grows like the number of levels, not like N.
    """
    a = np.asarray(q, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 4:
        raise MrpKinematicsError(f"q must have shape (N, 4), got {a.shape}")
    n = a.shape[0]
    if n <= SCAN_BLOCK:
        out = a.copy()
        for i in range(1, n):
            out[i] = quat_product(out[i - 1], out[i])
        return out / np.linalg.norm(out, axis=-1, keepdims=True)
    nb = -(-n // SCAN_BLOCK)
    blocks = np.zeros((nb * SCAN_BLOCK, 4))
    blocks[:, 0] = 1.0
    blocks[:n] = a
    blocks = blocks.reshape(nb, SCAN_BLOCK, 4)
    for i in range(1, SCAN_BLOCK):
        blocks[:, i] = quat_product(blocks[:, i - 1], blocks[:, i])
    totals = quat_cumprod(blocks[:, -1])
    blocks[1:] = quat_product(totals[:-1, None, :], blocks[1:])
    out = blocks.reshape(-1, 4)[:n]
    return out / np.linalg.norm(out, axis=-1, keepdims=True)
