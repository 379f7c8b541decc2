"""Kinematics q' = 1/2 q o w integrated directly on the gyro grid, with pseudo-derivatives (003 §2.2-2.3).

Paper 003 (Avanesov et al., Keldysh preprint 74, 2010) §2.3 integrates eq. (5) ``dp/dt = 1/2 p o w'``
(eq. 3') on the gyro grid t'_k by ``p(t'_{k+1}) = p(t'_k) o kappa_k`` with, tau_k = (t'_{k+1} - t'_k)/4:

- scheme 1 (trapezoid): kappa_k = (1, tau_k w_k) o (1, -tau_k w_{k+1})^-1; not norm-preserving,
  |p_{k+1}| = |p_k| sqrt((1 + tau² |w_k|²) / (1 + tau² |w_{k+1}|²)) (the product telescopes);
- scheme 2 (midpoint rate w_{k+1/2} = (w_k + w_{k+1})/2): kappa_k = (1 - tau²|w|², 2 tau w) / (1 + tau²|w|²),
  |kappa_k| = 1.

Vectorisation. The attitude at every node is the prefix product U_k = kappa_0 o ... o kappa_{k-1}, computed
by :func:`quat_cumprod`, an associative scan over blocks of ``SCAN_BLOCK`` (scanned position by position
across all blocks at once, or by Hillis-Steele doubling) applied recursively to the block totals
(components-first arrays): about 2 N quaternion products, log(N)/log(SCAN_BLOCK) levels of recursion and
no Python loop over samples.

Pseudo-derivatives (003 §2.2, eq. 7). For a parameter x the pseudo-derivative psi = dPsi/dx is the vector
with dp/dx = 1/2 p o psi. Eq. (7), dpsi/dt + w' x psi = dw'/dx, is linear with the solution
psi(t) = R(U_t)^T [psi(t0) + int R(U_s) dw'/dx ds]: the initial value carried by the motion and a
cumulative sum of rotated forcing terms. Discretised by the same scheme as the attitude (the exact
linearisation of the kappa_k recursion, rather than 003's separate Cramer's-rule step; the two agree to
O(h³) per step, see tests), a rate perturbation dw_k at the nodes gives

    psi_k = R(U_k)^T [psi_0 + sum_{j<k} R(U_{j+1}) (A_j dw_j + B_j dw_{j+1})],

where g_j = A_j dw_j + B_j dw_{j+1} = 2 vec(kappa_j^-1 o dkappa_j) (:func:`step_rate_jacobians`). The
scalar part of kappa^-1 o dkappa (a change of |p| in scheme 1) is dropped, as 003 drops it. Rotations by
non-unit quaternions mean rotations by the normalised ones.

Times t_s are float64 seconds from any epoch; rates rad/s in the frame being propagated (body, or the
star-tracker frame in 003 §2.4); quaternions scalar first, Hamilton, (..., 4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.gyro_calibration.propagation_kernels import (
    SCAN_BLOCK,
    GyroPropagationError,
    _cumprod_blocks,
    _cumprod_cf,
    _dcm_cf,
    _fill_blocks,
    _jacobian_sum_cf,
    _jacobians_cf,
    _kappa_cf,
    _matmul_cf,
    _qmul_cf,
)

__all__ = [
    "SCAN_BLOCK",
    "GyroPropagationError",
    "Propagation",
    "mrp_pseudo_derivatives",
    "propagate",
    "quat_cumprod",
    "step_quaternions",
    "step_rate_jacobians",
]

CHUNK = 16384
"""Grid steps per chunk of the step quaternions and of the pseudo-derivatives' forcing sums (cache-sized
temporaries; the forcing sums measured 69-70 ms at 8192 and 16384 against 112 at 2048 and 183 ms for
whole-grid arrays at 864,000 nodes, the step quaternions 9 ms at 16384 against 18 ms)."""

FloatArray = NDArray[np.float64]


def _check_scheme(scheme: int) -> int:
    if scheme not in (1, 2):
        raise GyroPropagationError(f"scheme must be 1 (trapezoid) or 2 (midpoint), got {scheme!r}")
    return int(scheme)


def quat_cumprod(kappa: ArrayLike, method: str = "blocked") -> FloatArray:
    """Inclusive prefix products c_i = kappa_0 o kappa_1 o ... o kappa_i of (n, 4) quaternions.

    Vectorised associative scan: the sequence is cut into blocks of ``SCAN_BLOCK``, scanned inside the
    blocks (method "blocked": position by position across all blocks at once, ~2 n products; "doubling":
    Hillis-Steele, ~5 n products), the block totals are scanned recursively and multiplied back in
    (depth log(n)/log(SCAN_BLOCK)). Works for non-unit quaternions (003 §2.3 scheme 1). Rounding grows
    like (SCAN_BLOCK + log n) eps, not n eps. Returns (n, 4).
    """
    k = np.asarray(kappa, dtype=np.float64)
    if k.ndim != 2 or k.shape[1] != 4:
        raise GyroPropagationError(f"kappa must have shape (n, 4), got {k.shape}")
    if k.shape[0] == 0:
        return k.copy()
    return np.ascontiguousarray(_cumprod_cf(np.ascontiguousarray(k.T), method).T)


def _rows3(x: ArrayLike, name: str) -> FloatArray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise GyroPropagationError(f"{name} must have shape (n, 3), got {a.shape}")
    return np.ascontiguousarray(a.T)


def step_quaternions(dt_s: ArrayLike, w_start: ArrayLike, w_end: ArrayLike, scheme: int) -> FloatArray:
    """Step quaternions kappa (n, 4) of 003 §2.3 over intervals of length dt_s (n,).

    w_start, w_end (n, 3) rad/s: rates at the two ends of each interval. Scheme 1 (trapezoid):
    kappa = (1, tau w_start) o (1, -tau w_end)^-1 = (1, tau w_start) o (1, tau w_end) / (1 + tau² |w_end|²),
    tau = dt/4. Scheme 2: the Cayley step of the midpoint rate w_m = (w_start + w_end)/2,
    (1 - tau²|w_m|², 2 tau w_m)/(1 + tau²|w_m|²), unit norm.
    """
    scheme = _check_scheme(scheme)
    tau = 0.25 * np.asarray(dt_s, dtype=np.float64).reshape(-1)
    return np.ascontiguousarray(_kappa_cf(tau, _rows3(w_start, "w_start"), _rows3(w_end, "w_end"), scheme).T)


def step_rate_jacobians(
    dt_s: ArrayLike, w_start: ArrayLike, w_end: ArrayLike, scheme: int
) -> tuple[FloatArray, FloatArray]:
    """Matrices A, B (n, 3, 3) with 2 vec(kappa^-1 o dkappa) = A dw_start + B dw_end (003 §2.3 schemes).

    Scheme 1, with v = tau w (tau = dt/4) and u = (1, v):
      A = 2 tau R(u_end)^T (I - [v_start x]) / (1 + |v_start|²),  B = 2 tau (I - [v_end x]) / (1 + |v_end|²);
    scheme 2, with v = tau (w_start + w_end)/2:
      A = B = 2 tau / (1 + |v|²)² [(1 - |v|²) I - 2 [v x] + 2 v v^T]
    (the derivative of the Cayley map; cf. 003 §1.3's w(z, z') formula). A + B = dt I + O(dt² |w|).
    """
    scheme = _check_scheme(scheme)
    tau = 0.25 * np.asarray(dt_s, dtype=np.float64).reshape(-1)
    a, b = _jacobians_cf(tau, _rows3(w_start, "w_start"), _rows3(w_end, "w_end"), scheme)
    return np.ascontiguousarray(a.transpose(2, 0, 1)), np.ascontiguousarray(b.transpose(2, 0, 1))


def mrp_pseudo_derivatives(z: ArrayLike) -> FloatArray:
    """Initial pseudo-derivatives dPsi/dz (3, 3), column k = d psi / d z_k, of p(t0) = p(z) (003 §2.2).

    003 §2.2: d psi_1/d z_1 = s (z_1 p_1 + p_0), d psi_2/d z_1 = s (z_1 p_2 - p_3), ... i.e.
    dPsi/dz = s (p_vec z^T + p_0 I - [p_vec x]) with s = 4/(1 + |z|²) and p = p(z) the quaternion of the
    (modified) Rodrigues parameters z: p_0 = (1 - |z|²)/(1 + |z|²), p_vec = 2 z/(1 + |z|²).
    """
    z = np.asarray(z, dtype=np.float64)
    if z.shape != (3,):
        raise GyroPropagationError(f"z must have shape (3,), got {z.shape}")
    zz = float(z @ z)
    p0 = (1.0 - zz) / (1.0 + zz)
    pv = 2.0 * z / (1.0 + zz)
    s = 4.0 / (1.0 + zz)
    cross = np.array([[0.0, -pv[2], pv[1]], [pv[2], 0.0, -pv[0]], [-pv[1], pv[0], 0.0]])
    return s * (np.outer(pv, z) + p0 * np.eye(3) - cross)


# ---------------------------------------------------------------------------------------------------
# Propagation with pseudo-derivatives at output times.


@dataclass(frozen=True)
class Propagation:
    """Result of :func:`propagate`; M output times, m rate parameters.

    u_out (M, 4): U(t_n) with p(t_n) = p(t0) o U(t_n) (unit for scheme 2; |U| drifts slightly in
    scheme 1, as 003 §2.3 states); rot_out (M, 3, 3): R(U(t_n)/|U|); psi_out (M, 3, m): pseudo-derivatives
    at t_n of the m rate parameters with psi(t0) = 0 (the forcing part of eq. 7); the pseudo-derivative
    of an initial-condition parameter with psi(t0) = c is rot_out^T c.
    """

    u_out: FloatArray
    rot_out: FloatArray
    psi_out: FloatArray


def propagate(
    t_s: ArrayLike,
    w: ArrayLike,
    t_out: ArrayLike,
    *,
    scheme: int = 2,
    rate_jacobian: ArrayLike | None = None,
    derivatives: bool = True,
) -> Propagation:
    """Integrate q' = 1/2 q o w from U(t_s[0]) = 1 on the grid and evaluate at t_out, with eq. (7).

    t_s (N,) strictly increasing s; w (N, 3) rad/s at the nodes (w' of 003 eq. 5: measured rates plus
    offsets, in the propagated frame); t_out (M,) s within [t_s[0], t_s[-1]]; scheme 1 or 2 (003 §2.3).
    rate_jacobian: dw_k/dx (N, 3, m) of m parameters, default the identity (m = 3: the offsets Delta of
    003 eq. 5, forcing e_k in eq. 7). Between nodes the rate is linear in time and an output is reached
    by a partial step of the same scheme from the preceding node (the grid itself is untouched).
    derivatives=False skips eq. (7) (psi_out is then (M, 3, 0)). Returns :class:`Propagation`.
    Cost O(N log N / log SCAN_BLOCK), no Python loop over samples.
    (003 §2.2, eqs. 5, 7; §2.3)
    """
    scheme = _check_scheme(scheme)
    grid = _grid(t_s, w, t_out, rate_jacobian)
    u_nodes = _node_attitudes(grid, scheme)
    out = _output_steps(grid, u_nodes, scheme)
    psi = _pseudo_derivatives(grid, u_nodes, out, scheme) if derivatives else None
    return Propagation(
        u_out=np.ascontiguousarray(out.u_out.T),
        rot_out=np.ascontiguousarray(out.rot.transpose(2, 0, 1)),
        psi_out=np.zeros((out.k.size, 3, 0)) if psi is None else np.ascontiguousarray(psi.transpose(2, 0, 1)),
    )


@dataclass(frozen=True)
class _Grid:
    """Checked inputs, components first: node times t (N,), steps dt (N - 1,), rates wc (3, N), output
    times t_out (M,), the rate Jacobian (3, m, N) or None (identity, m = 3)."""

    t: FloatArray
    dt: FloatArray
    wc: FloatArray
    t_out: FloatArray
    jac: FloatArray | None
    m: int


def _grid(t_s: ArrayLike, w: ArrayLike, t_out: ArrayLike, rate_jacobian: ArrayLike | None) -> _Grid:
    t = np.asarray(t_s, dtype=np.float64)
    if t.ndim != 1 or t.size < 2:
        raise GyroPropagationError(f"t_s must have shape (N,) with N >= 2, got {t.shape}")
    n = t.size
    wa = np.asarray(w, dtype=np.float64)
    if wa.shape != (n, 3):
        raise GyroPropagationError(f"w must have shape ({n}, 3) matching t_s, got {wa.shape}")
    dt = np.diff(t)
    if not np.all(dt > 0):
        raise GyroPropagationError("t_s must be strictly increasing")
    to = np.asarray(t_out, dtype=np.float64)
    if to.ndim != 1:
        raise GyroPropagationError(f"t_out must have shape (M,), got {to.shape}")
    if to.size and not (to.min() >= t[0] and to.max() <= t[-1]):
        raise GyroPropagationError(
            f"t_out must lie within the gyro grid [{t[0]}, {t[-1]}] s, got [{to.min()}, {to.max()}]"
        )
    jac = None
    m = 3
    if rate_jacobian is not None:
        jac_rows = np.asarray(rate_jacobian, dtype=np.float64)
        if jac_rows.ndim != 3 or jac_rows.shape[:2] != (n, 3):
            raise GyroPropagationError(f"rate_jacobian must have shape ({n}, 3, m), got {jac_rows.shape}")
        m = jac_rows.shape[2]
        jac = np.ascontiguousarray(jac_rows.transpose(1, 2, 0))  # (3, m, N)
    return _Grid(t=t, dt=dt, wc=np.ascontiguousarray(wa.T), t_out=to, jac=jac, m=m)


def _node_attitudes(grid: _Grid, scheme: int) -> FloatArray:
    """U_k (4, N) at the nodes: prefix products of the step quaternions of 003 §2.3 (these made CHUNK steps at a
    time, elementwise and so bit for bit the same, with cache-sized temporaries: 2x faster at 864,000)."""
    n_steps = grid.dt.size
    u_nodes = np.empty((4, grid.t.size))
    u_nodes[:, 0] = (1.0, 0.0, 0.0, 0.0)
    if n_steps <= SCAN_BLOCK:
        _cumprod_cf(_kappa_cf(0.25 * grid.dt, grid.wc[:, :-1], grid.wc[:, 1:], scheme), out=u_nodes[:, 1:])
        return u_nodes
    # the step quaternions go straight into the scan's blocked layout, the products straight into u_nodes
    x = np.empty((4, SCAN_BLOCK, -(-n_steps // SCAN_BLOCK)))
    step = max(CHUNK // SCAN_BLOCK, 1) * SCAN_BLOCK
    for a in range(0, n_steps, step):
        b = min(a + step, n_steps)
        _fill_blocks(x, a, _kappa_cf(0.25 * grid.dt[a:b], grid.wc[:, a:b], grid.wc[:, a + 1 : b + 1], scheme))
    _cumprod_blocks(x, n_steps, "blocked", u_nodes[:, 1:])
    return u_nodes


@dataclass(frozen=True)
class _Outputs:
    """Partial steps to the output times: preceding node k (M,), partial step dtp and its fraction f of
    the interval, rates at both ends (3, M), U at the outputs (4, M) and R(U) (3, 3, M)."""

    k: NDArray[np.intp]
    dtp: FloatArray
    f: FloatArray
    w_k: FloatArray
    w_o: FloatArray
    u_out: FloatArray
    rot: FloatArray


def _output_steps(grid: _Grid, u_nodes: FloatArray, scheme: int) -> _Outputs:
    """Partial steps of the same scheme from the preceding node k to each output time."""
    t, wc, to = grid.t, grid.wc, grid.t_out
    k = np.clip(np.searchsorted(t, to, side="right") - 1, 0, t.size - 2)
    dtp = to - t[k]
    f = dtp / grid.dt[k]
    w_k = wc[:, k]
    w_o = (1.0 - f) * w_k + f * wc[:, k + 1]
    u_out = _qmul_cf(u_nodes[:, k], _kappa_cf(0.25 * dtp, w_k, w_o, scheme))
    return _Outputs(k=k, dtp=dtp, f=f, w_k=w_k, w_o=w_o, u_out=u_out, rot=_dcm_cf(u_out))


def _pseudo_derivatives(grid: _Grid, u_nodes: FloatArray, out: _Outputs, scheme: int) -> FloatArray:
    """psi (3, m, M) at the outputs (eq. 7): forcing sums S_k = sum_{j<k} R(U_{j+1}) (A_j D_j + B_j D_{j+1})
    carried to the preceding node, plus the partial step."""
    jac, k, f = grid.jac, out.k, out.f
    if jac is None:
        gp = _jacobian_sum_cf(0.25 * out.dtp, out.w_k, out.w_o, scheme)
    else:
        ap, bp = _jacobians_cf(0.25 * out.dtp, out.w_k, out.w_o, scheme)
        gp = _matmul_cf(ap, jac[:, :, k]) + _matmul_cf(bp, (1.0 - f) * jac[:, :, k] + f * jac[:, :, k + 1])
    return _matmul_cf(out.rot.transpose(1, 0, 2), _forcing_at(grid, u_nodes, k, scheme)) + gp


def _step_forcing(grid: _Grid, a: int, b: int, scheme: int) -> FloatArray:
    """A_j D_j + B_j D_{j+1} (3, m, b - a) of the steps j = a .. b-1 (rad per unit of each parameter)."""
    tau, ws, we = 0.25 * grid.dt[a:b], grid.wc[:, a:b], grid.wc[:, a + 1 : b + 1]
    if grid.jac is None:
        return _jacobian_sum_cf(tau, ws, we, scheme)
    sa, sb = _jacobians_cf(tau, ws, we, scheme)
    return _matmul_cf(sa, grid.jac[:, :, a:b]) + _matmul_cf(sb, grid.jac[:, :, a + 1 : b + 1])


def _forcing_at(grid: _Grid, u_nodes: FloatArray, k: NDArray[np.intp], scheme: int) -> FloatArray:
    """The forcing sums S_k (3, m, M) at the nodes k, S_0 = 0, S_{i+1} = S_i + R(U_{i+1}) g_i.

    Made CHUNK steps at a time, each chunk's running sum started from the previous chunk's last one:
    the same additions in the same order as one cumulative sum over the whole grid (bit for bit), but the
    temporaries (rotations, step Jacobians, their products) stay in cache instead of being (3, 3, N) arrays
    written to and read back from memory (about 2.5x faster at 864,000 nodes). Unsorted k (output times
    in any order) are handled in sorted order."""
    res = np.empty((3, grid.m, k.size))
    if k.size > 1 and np.any(k[1:] < k[:-1]):
        order = np.argsort(k, kind="stable")
        res[:, :, order] = _forcing_at(grid, u_nodes, k[order], scheme)
        return res
    n_steps = grid.dt.size
    run = np.zeros((3, grid.m, min(CHUNK, n_steps) + 1))  # [..., 0]: the sum carried in
    lo = 0
    for a in range(0, n_steps, CHUNK):
        b = min(a + CHUNK, n_steps)
        part = run[:, :, : b - a + 1]
        np.einsum("ij...,jk...->ik...", _dcm_cf(u_nodes[:, a + 1 : b + 1]), _step_forcing(grid, a, b, scheme),
                  out=part[:, :, 1:])  # _matmul_cf written into the chunk
        np.cumsum(part, axis=-1, out=part)  # part[..., i - a] = S_i for a <= i <= b
        hi = int(np.searchsorted(k, b, side="right"))
        res[:, :, lo:hi] = part[:, :, k[lo:hi] - a]
        lo = hi
        run[:, :, 0] = part[:, :, b - a]
    return res
