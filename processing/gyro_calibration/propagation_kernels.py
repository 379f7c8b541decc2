"""Components-first kernels of the gyro-grid integration (processing.gyro_calibration.propagation): quaternion
products, rotation matrices, the blocked prefix scan and the step quaternions and their Jacobians of 003 §2.3.

Internals work components-first: quaternions (4, n), vectors (3, n), matrices (3, 3, n), so that every arithmetic
pass runs over one contiguous array (about 3x faster than (n, 4) rows at 1e6 samples).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

SCAN_BLOCK = 16
"""Block length of the recursive blocked prefix scan (measured fastest among 8..64 at 1e4..1e6 samples)."""

FloatArray = NDArray[np.float64]


class GyroPropagationError(ValueError):
    """Bad input to the gyro-grid integration: shapes, non-increasing times, outputs outside the grid."""


def _qmul_cf(p: FloatArray, q: FloatArray) -> FloatArray:
    """Hamilton product of components-first quaternions p (4, ...), q (4, ...) (broadcasting)."""
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    out = np.empty(np.broadcast_shapes(p.shape, q.shape))
    out[0] = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
    out[1] = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
    out[2] = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
    out[3] = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0
    return out


def _dcm_cf(q: FloatArray) -> FloatArray:
    """R(q/|q|) (3, 3, ...) of components-first quaternions q (4, ...) of any non-zero norm.

    The same products, sums and differences in the same order as the textbook form (bit for bit), written
    into the output and two scratch arrays instead of a temporary per term (about 2x faster at 864,000)."""
    w, x, y, z = q
    tail = q.shape[1:]
    t1, t2 = np.empty(tail), np.empty(tail)
    s = np.multiply(w, w)
    for c in (x, y, z):  # ((w² + x²) + y²) + z²
        np.multiply(c, c, out=t1)
        s += t1
    np.divide(2.0, s, out=s)
    xs, ys, zs = x * s, y * s, z * s
    xx, yy, zz = x * xs, y * ys, np.multiply(z, zs, out=s)
    out = np.empty((3, 3, *tail))
    for i, (a, b) in enumerate(((yy, zz), (xx, zz), (xx, yy))):  # diagonal: 1 - (a + b)
        np.add(a, b, out=out[i, i])
        np.subtract(1.0, out[i, i], out=out[i, i])
    # off-diagonal pairs: (i, j) = u - v, (j, i) = u + v with u, v: xy, wz; xz, wy; yz, wx
    for (a, b, c, d), (i, j) in (((x, ys, w, zs), (0, 1)), ((x, zs, w, ys), (2, 0)), ((y, zs, w, xs), (1, 2))):
        np.multiply(a, b, out=t1)
        np.multiply(c, d, out=t2)
        np.subtract(t1, t2, out=out[i, j])
        np.add(t1, t2, out=out[j, i])
    return out


def _matmul_cf(a: FloatArray, b: FloatArray) -> FloatArray:
    """a @ b for stacks a (3, 3, ...), b (3, m, ...) stored components-first. Returns (3, m, ...).

    One einsum pass (the products summed over j in order, as a[i, 0] b[0, k] + a[i, 1] b[1, k] + ...
    would be; about half the time of those 5 m numpy passes with their temporaries at 864,000 samples)."""
    return np.einsum("ij...,jk...->ik...", a, b)


def _eye_minus_cross_cf(v: FloatArray, scale: FloatArray) -> FloatArray:
    """scale (I - [v x]) as (3, 3, ...) from v (3, ...)."""
    out = np.empty((3, 3, *v.shape[1:]))
    out[0, 0] = out[1, 1] = out[2, 2] = scale
    out[0, 1], out[0, 2] = scale * v[2], -scale * v[1]
    out[1, 0], out[1, 2] = -scale * v[2], scale * v[0]
    out[2, 0], out[2, 1] = scale * v[1], -scale * v[0]
    return out


def _pad_blocks(k: FloatArray, n_blocks: int) -> FloatArray:
    """(4, n) -> (4, SCAN_BLOCK, n_blocks), identity-padded, position within the block first."""
    x = np.empty((4, SCAN_BLOCK, n_blocks))
    _fill_blocks(x, 0, k)
    return x


def _fill_blocks(x: FloatArray, start: int, k: FloatArray) -> None:
    """Write k (4, m) into the blocked x (4, SCAN_BLOCK, n_blocks) at sequence positions start .. start + m - 1
    (start a multiple of SCAN_BLOCK) in one copy; a last, partial block is padded with the identity."""
    full, rest = divmod(k.shape[1], SCAN_BLOCK)
    b0 = start // SCAN_BLOCK
    xt = x.transpose(0, 2, 1)  # (4, n_blocks, SCAN_BLOCK) view, sequence order
    xt[:, b0 : b0 + full] = k[:, : full * SCAN_BLOCK].reshape(4, full, SCAN_BLOCK)
    if rest:
        xt[:, b0 + full, :rest] = k[:, full * SCAN_BLOCK :]
        xt[0, b0 + full, rest:], xt[1:, b0 + full, rest:] = 1.0, 0.0


def _cumprod_cf(k: FloatArray, method: str = "blocked", out: FloatArray | None = None) -> FloatArray:
    """Inclusive prefix products of (4, n) quaternions, recursive over blocks of SCAN_BLOCK.

    Inside the blocks: "blocked" runs along the SCAN_BLOCK positions, vectorised across all blocks at
    once (about 2 n products in total); "doubling" is the Hillis-Steele log-depth scan (about
    (log2(SCAN_BLOCK) + 1) n products). Either way the block totals are scanned recursively and multiplied
    back in, so the Python-level iteration count is O(SCAN_BLOCK log(n) / log(SCAN_BLOCK)), independent of
    the sample count up to that logarithm. Measured at n = 864,000: 0.05 s blocked, 0.12 s doubling.
    out: a (4, n) array (rows contiguous) to write the products into, instead of a new one; returned.
    """
    n = k.shape[1]
    if n <= SCAN_BLOCK:
        x = k.copy()
        for i in range(1, n):
            x[:, i] = _qmul_cf(x[:, i - 1], x[:, i])
        if out is None:
            return x
        out[...] = x
        return out
    return _cumprod_blocks(_pad_blocks(k, -(-n // SCAN_BLOCK)), n, method, out)


def _cumprod_blocks(x: FloatArray, n: int, method: str, out: FloatArray | None) -> FloatArray:
    """:func:`_cumprod_cf` of the n > SCAN_BLOCK quaternions in the blocked x (4, L, B) (:func:`_pad_blocks`;
    slices along L are contiguous runs of B), overwritten."""
    if method == "blocked":
        for i in range(1, SCAN_BLOCK):
            x[:, i] = _qmul_cf(x[:, i - 1], x[:, i])
    elif method == "doubling":
        s = 1
        while s < SCAN_BLOCK:
            x[:, s:] = _qmul_cf(x[:, :-s], x[:, s:])
            s *= 2
    else:
        raise GyroPropagationError(f"method must be 'blocked' or 'doubling', got {method!r}")
    totals = _cumprod_cf(np.ascontiguousarray(x[:, -1]), method)[:, :-1]
    for i in range(SCAN_BLOCK):  # one block position at a time: the temporaries stay in cache (25 % faster)
        x[:, i, 1:] = _qmul_cf(totals, x[:, i, 1:])
    seq = x.transpose(0, 2, 1)  # (4, n_blocks, SCAN_BLOCK): sequence order
    if out is None:
        return seq.reshape(4, -1)[:, :n]
    full, rest = divmod(n, SCAN_BLOCK)
    blocks = out[:, : full * SCAN_BLOCK].view()
    blocks.shape = (4, full, SCAN_BLOCK)  # a view or an error, never a silent copy
    blocks[...] = seq[:, :full]
    if rest:
        out[:, full * SCAN_BLOCK :] = seq[:, full, :rest]
    return out


def _kappa_cf(tau: FloatArray, ws: FloatArray, we: FloatArray, scheme: int) -> FloatArray:
    """Step quaternions (4, n) of 003 §2.3 from tau = dt/4 (n,) and end rates (3, n)."""
    out = np.empty((4, tau.size))
    if scheme == 1:
        a, b = tau * ws, tau * we
        inv = 1.0 / (1.0 + b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
        out[0] = (1.0 - (a[0] * b[0] + a[1] * b[1] + a[2] * b[2])) * inv
        out[1] = (a[0] + b[0] + a[1] * b[2] - a[2] * b[1]) * inv
        out[2] = (a[1] + b[1] + a[2] * b[0] - a[0] * b[2]) * inv
        out[3] = (a[2] + b[2] + a[0] * b[1] - a[1] * b[0]) * inv
    else:
        v = (0.5 * tau) * (ws + we)
        vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
        inv = 1.0 / (1.0 + vv)
        out[0] = (1.0 - vv) * inv
        out[1:] = (2.0 * inv) * v
    return out


def _jacobians_cf(tau: FloatArray, ws: FloatArray, we: FloatArray, scheme: int) -> tuple[FloatArray, FloatArray]:
    """A, B (3, 3, n) of :func:`step_rate_jacobians`, components-first."""
    if scheme == 1:
        vs, ve = tau * ws, tau * we
        ns = 1.0 + vs[0] * vs[0] + vs[1] * vs[1] + vs[2] * vs[2]
        ne = 1.0 + ve[0] * ve[0] + ve[1] * ve[1] + ve[2] * ve[2]
        u_end = np.concatenate([np.ones((1, tau.size)), ve])
        r_end_t = _dcm_cf(u_end).transpose(1, 0, 2)
        a = _matmul_cf(r_end_t, _eye_minus_cross_cf(vs, 2.0 * tau / ns))
        b = _eye_minus_cross_cf(ve, 2.0 * tau / ne)
        return a, b
    g = _cayley_jacobian_cf(tau, ws, we, 2.0)
    return g, g


def _jacobian_sum_cf(tau: FloatArray, ws: FloatArray, we: FloatArray, scheme: int) -> FloatArray:
    """A + B (3, 3, n) of :func:`_jacobians_cf` (the forcing of a rate parameter constant across the step);
    scheme 2 makes it in one pass (A = B: the factor 4 instead of 2, exact in binary, so bit for bit A + B)."""
    if scheme == 1:
        a, b = _jacobians_cf(tau, ws, we, scheme)
        return a + b
    return _cayley_jacobian_cf(tau, ws, we, 4.0)


def _cayley_jacobian_cf(tau: FloatArray, ws: FloatArray, we: FloatArray, factor: float) -> FloatArray:
    """factor tau / (1 + |v|²)² [(1 - |v|²) I - 2 [v x] + 2 v v^T], v = tau (ws + we) / 2 (scheme 2's A for
    factor 2)."""
    v = (0.5 * tau) * (ws + we)
    vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    c = factor * tau / (1.0 + vv) ** 2
    c2v = (2.0 * c) * v
    g = c2v[:, None] * v[None, :]  # (2 c v_i) v_j, as c2 * v[:, None] * v[None, :] forms it
    diag = c * (1.0 - vv)
    for i in range(3):
        g[i, i] += diag
    g[0, 1] += c2v[2]
    g[0, 2] -= c2v[1]
    g[1, 0] -= c2v[2]
    g[1, 2] += c2v[0]
    g[2, 0] += c2v[1]
    g[2, 1] -= c2v[0]
    return g


# ---------------------------------------------------------------------------------------------------
# Public row-layout (n, 4) / (n, 3) wrappers.
