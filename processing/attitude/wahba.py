"""Wahba's problem: the rotation that best maps reference vectors onto observed ones, vectorised over epochs.

Given at each epoch n unit vectors b_i observed in frame B (body, sensor) and the same directions r_i
known in a reference frame R (orbital, inertial) with weights a_i >= 0, find dcm_BR minimising

    J(A) = sum_i a_i |b_i - A r_i|^2                                    (002, eq. 8; Wahba 1965)

(the paper's M_X1X2 with U1 = b in the body frame, U2 = r in the orbital frame). With
B = sum a_i b_i r_i^T (the attitude profile matrix), J = 2 (lambda0 - tr(A B^T)), lambda0 = sum a_i.

Solvers (all return :class:`WahbaResult` with q_BR scalar first, Hamilton, canonical, v_B = q o v_R o q^-1):

- :func:`q_method` -- Davenport's q-method: the eigenvector of the 4x4 matrix K for its largest
  eigenvalue (002, eq. 9: the paper's matrix is -K in the vector-first convention, so its *smallest*
  eigenvalue's eigenvector is the same quaternion). numpy's batched symmetric eigensolver.
- :func:`quest` -- QUEST (Shuster & Oh 1981): lambda_max by Newton-Raphson on the characteristic
  quartic of K, the quaternion from one column of adj(lambda_max I - K). Column 0 is the classical
  (adj((lambda+sigma)I - S) z, det((lambda+sigma)I - S)) (Gibbs-vector form), which vanishes for 180 deg
  rotations; instead of Shuster's trial-and-error sequential rotations, each epoch rotates the
  reference frame by 180 deg about the axis k whose diagonal cofactor c q_k^2 is the largest
  (Markley & Mortari 2000, J. Astronaut. Sci. 48, "Quaternion attitude estimation using vector
  observations"), so the column used is never small. Pure elementwise numpy in cache-sized chunks.
- :func:`svd_method` -- Markley's SVD method (1988): B = U diag(s) V^T, A = U diag(1, 1, det U det V) V^T.
- :func:`esoq2` -- Mortari's ESOQ2 (1997): with lambda_max from the quartic, the rotation axis is the
  null vector of the symmetric 3x3 M = (lambda - sigma)((lambda + sigma) I - S) - z z^T and the
  quaternion is ((lambda - sigma) e, z.e) (vector first); M vanishes at zero rotation, so the
  reference frame is always turned by 180 deg about the axis k of the smallest B_kk first, which
  keeps lambda - sigma >= 2 lambda / 3 for data consistent with a rotation.

Conventions inside (Shuster's vector-first quaternion qbar = (qv, q4) with A = R(q4, -qv)):
S = B + B^T, sigma = tr B, z = sum a_i b_i x r_i, K = [[S - sigma I, z], [z^T, sigma]]. Our Hamilton
scalar-first q_BR = (q4, -qv).

Covariance: the QUEST measurement model (Shuster & Oh 1981): if b_i = A r_i + noise with isotropic
tangential noise of std sigma_i (rad) and the weights are a_i = 1 / sigma_i^2, the rotation-vector
error delta (A_true = exp([delta x]) A_est... small) has covariance P = [sum a_i (I - b_i b_i^T)]^-1 in
frame B, rad^2. With other weights (e.g. normalised to sum 1) P is in units of 1/weight: multiply by
the variance the weights were normalised with.

Per-epoch status (``WahbaResult.status``): OK (0); UNOBSERVABLE (1): fewer than two non-collinear
weighted vectors, the rotation about the single direction is undetermined (q is one of the
solutions, covariance NaN); NOT_CONVERGED (2): Newton did not reach the tolerance (QUEST, ESOQ2);
INVALID (3): no usable vector (all weights zero, NaN or zero-length vectors); q is NaN.
Rows with NaN or zero-length vectors are treated as weight 0. The solvers' per-epoch kernels (on the
nine components of B) are in processing.attitude.wahba_kernels.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.attitude.wahba_kernels import (
    Kernel,
    esoq2_kernel,
    k_from_profile_matrix,
    q_method_kernel,
    quest_kernel,
    svd_kernel,
)

__all__ = [
    "INVALID",
    "METHODS",
    "NOT_CONVERGED",
    "OK",
    "UNOBSERVABLE",
    "WahbaInputError",
    "WahbaResult",
    "attitude_profile_matrix",
    "davenport_k",
    "esoq2",
    "q_method",
    "quest",
    "solve",
    "svd_method",
]

OK, UNOBSERVABLE, NOT_CONVERGED, INVALID = 0, 1, 2, 3
STATUS_NAMES = {OK: "ok", UNOBSERVABLE: "unobservable", NOT_CONVERGED: "not_converged", INVALID: "invalid"}
CHUNK = 8192
"""Epochs per elementwise pass (arrays of this length stay in cache)."""
OBSERVABILITY_TOL = 1e-10
"""An epoch is UNOBSERVABLE when det(sum a (I - b b^T)) < tol * lambda0^3 (two vectors closer than
about 1e-5 rad to collinear, or one vector)."""

FloatArray = NDArray[np.float64]


class WahbaInputError(ValueError):
    """Vectors or weights of the wrong shape, or negative weights."""


@dataclass(frozen=True)
class WahbaResult:
    """Solution of Wahba's problem at each epoch (leading shape ``...`` of the inputs).

    q: (..., 4) q_BR, scalar first, canonical (q0 >= 0); NaN where status is INVALID.
    loss: (...) J = sum a_i |b_i - A r_i|^2 of 002 eq. 8 (twice the 1/2-weighted loss of Markley).
    covariance_rad2: (..., 3, 3) rotation-vector error covariance in frame B (see the module
        docstring: rad^2 when a_i = 1/sigma_i^2); NaN where not OK/NOT_CONVERGED.
    lambda_max: (...) largest eigenvalue of K (loss = 2 (lambda0 - lambda_max)).
    status: (...) int8 codes OK, UNOBSERVABLE, NOT_CONVERGED, INVALID.
    iterations: Newton iterations used (max over epochs; 0 for q-method and SVD).
    method: solver name.
    """

    q: FloatArray
    loss: FloatArray
    covariance_rad2: FloatArray
    lambda_max: FloatArray
    status: NDArray[np.int8]
    iterations: int
    method: str

    @property
    def ok(self) -> NDArray[np.bool_]:
        """True where the attitude is fully determined (status OK)."""
        return self.status == OK


def _shapes(b: ArrayLike, r: ArrayLike, weights: ArrayLike | None) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Check shapes; returns float arrays b, r (..., n, 3) and weights broadcast to (..., n)."""
    b_arr = np.asarray(b, dtype=np.float64)
    r_arr = np.asarray(r, dtype=np.float64)
    if b_arr.ndim < 2 or b_arr.shape[-1] != 3 or r_arr.shape != b_arr.shape:
        raise WahbaInputError(
            f"observed and reference vectors must both have shape (..., n, 3), got {b_arr.shape} and {r_arr.shape}"
        )
    if weights is None:
        w = np.ones(b_arr.shape[:-1])
    else:
        w = np.asarray(weights, dtype=np.float64)
        try:
            w = np.broadcast_to(w, b_arr.shape[:-1])
        except ValueError:
            raise WahbaInputError(
                f"weights must broadcast to {b_arr.shape[:-1]} (epochs, vectors), got {w.shape}"
            ) from None
    if np.any(w < 0):
        raise WahbaInputError(f"weights must be >= 0, got min {np.nanmin(w)}")
    return b_arr, r_arr, w


def _unit_components(v: FloatArray) -> tuple[list[FloatArray], NDArray[np.bool_]]:
    """Unit-vector components of v (3, ...) (components FIRST) and the mask of usable (finite, non-zero)
    vectors; unusable ones are set to zero."""
    x, y, z = v[0], v[1], v[2]
    norm2 = x * x + y * y + z * z
    good = np.isfinite(norm2) & (norm2 > 0)
    if good.all():
        inv = 1.0 / np.sqrt(norm2)
        return [x * inv, y * inv, z * inv], good
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        inv = np.where(good, 1.0 / np.sqrt(norm2), 0.0)
    return [np.where(good, x * inv, 0.0), np.where(good, y * inv, 0.0), np.where(good, z * inv, 0.0)], good


def _prepare(b: ArrayLike, r: ArrayLike, weights: ArrayLike | None) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Unit vectors (..., n, 3) and weights (..., n); unusable vectors get weight 0 (and are zero)."""
    b_arr, r_arr, w = _shapes(b, r, weights)
    bc, gb = _unit_components(np.moveaxis(b_arr, -1, 0))
    rc, gr = _unit_components(np.moveaxis(r_arr, -1, 0))
    good = gb & gr & np.isfinite(w)
    return np.stack(bc, axis=-1), np.stack(rc, axis=-1), np.where(good, w, 0.0)


def attitude_profile_matrix(b: ArrayLike, r: ArrayLike, weights: ArrayLike | None = None) -> FloatArray:
    """B = sum_i a_i b_i r_i^T (..., 3, 3) from unit-normalised b (..., n, 3), r (..., n, 3), a (..., n)."""
    b_u, r_u, w = _prepare(b, r, weights)
    return np.einsum("...n,...ni,...nj->...ij", w, b_u, r_u)


def davenport_k(b: ArrayLike, r: ArrayLike, weights: ArrayLike | None = None) -> FloatArray:
    """Davenport's K (..., 4, 4) for the Hamilton scalar-first q_BR: q^T K q = tr(A B^T).

    K = [[sigma, -z^T], [-z, S - sigma I]] with z = sum a b x r (Shuster's K reordered for q_H = (q4, -qv)).
    002 eq. 9 is -K in the vector-first order; its smallest eigenvalue is -lambda_max.
    """
    B = attitude_profile_matrix(b, r, weights)
    return k_from_profile_matrix(B)


def _sum0(x: FloatArray) -> FloatArray:
    """Sum over the first axis (the vectors of an epoch) by row additions."""
    out = x[0].copy()
    for row in x[1:]:
        out += row
    return out


def _run(name: str, kernel: Kernel, b: ArrayLike, r: ArrayLike, weights: ArrayLike | None, tol: float,
         max_iter: int, covariance: bool) -> WahbaResult:
    """Solve in chunks of epochs: normalise, build B, call the kernel, then loss, covariance and status."""
    b_arr, r_arr, w_arr = _shapes(b, r, weights)
    lead = w_arr.shape[:-1]
    n = w_arr.shape[-1]
    bf, rf, wf = b_arr.reshape(-1, n, 3), r_arr.reshape(-1, n, 3), w_arr.reshape(-1, n)
    total = wf.shape[0]
    q = np.empty((total, 4))
    loss = np.empty(total)
    lam_max = np.empty(total)
    status = np.empty(total, dtype=np.int8)
    cov = np.full((total, 3, 3), np.nan)
    iterations = 0
    tiny = np.finfo(float).tiny
    for s in range(0, total, CHUNK):
        sl = slice(s, min(total, s + CHUNK))
        # Components as contiguous (n, m) arrays: sums over the n vectors are n - 1 row additions.
        bu, gb = _unit_components(np.ascontiguousarray(bf[sl].transpose(2, 1, 0)))
        ru, gr = _unit_components(np.ascontiguousarray(rf[sl].transpose(2, 1, 0)))
        wc = wf[sl].T
        wc = np.where(gb & gr & np.isfinite(wc), wc, 0.0)
        bw = [wc * bu[i] for i in range(3)]
        comps = [_sum0(bw[i] * ru[j]) for i in range(3) for j in range(3)]
        lam0 = _sum0(wc)
        valid = lam0 > 0
        qc, lam, done, it = kernel(comps, lam0, tol, max_iter)
        iterations = max(iterations, it)
        with np.errstate(invalid="ignore", divide="ignore"):
            qc = qc / np.sqrt((qc * qc).sum(axis=1))[:, None]
        lost = valid & ~np.isfinite(qc).all(axis=1)  # adjugate zero: lambda_max not simple (one vector)
        if np.any(lost):
            qc[lost], lam[lost], _, _ = q_method_kernel([c[lost] for c in comps], lam0[lost], tol, max_iter)
        qc = np.where(valid[:, None], qc, np.nan)
        qc = np.where(qc[:, :1] < 0, -qc, qc)
        q[sl] = qc
        # Loss J = 2 (lambda0 - lambda_max) = sum a |b - A r|^2 (002, eq. 8), absolute error ~1e-16 lambda0.
        lam = np.minimum(lam, lam0)
        loss[sl] = np.where(valid, 2.0 * (lam0 - lam), np.nan)
        lam_max[sl] = np.where(valid, lam, np.nan)
        # Information matrix lambda0 I - sum a b b^T; UNOBSERVABLE when nearly singular.
        f00, f11, f22 = _sum0(bw[0] * bu[0]), _sum0(bw[1] * bu[1]), _sum0(bw[2] * bu[2])
        f01, f02, f12 = _sum0(bw[0] * bu[1]), _sum0(bw[0] * bu[2]), _sum0(bw[1] * bu[2])
        i00, i11, i22 = lam0 - f00, lam0 - f11, lam0 - f22
        # Cofactors of [[i00, -f01, -f02], [-f01, i11, -f12], [-f02, -f12, i22]].
        c00 = i11 * i22 - f12 * f12
        c11 = i00 * i22 - f02 * f02
        c22 = i00 * i11 - f01 * f01
        c01 = f01 * i22 + f02 * f12
        c02 = f01 * f12 + f02 * i11
        c12 = i00 * f12 + f01 * f02
        det = i00 * c00 - f01 * c01 - f02 * c02
        observable = det >= OBSERVABILITY_TOL * np.maximum(lam0, tiny) ** 3
        status[sl] = np.where(~valid, INVALID, np.where(~observable, UNOBSERVABLE, np.where(done, OK, NOT_CONVERGED)))
        if covariance:
            good = valid & observable
            with np.errstate(invalid="ignore", divide="ignore"):
                inv_det = np.where(good, 1.0 / np.where(good, det, 1.0), np.nan)
            cc = cov[sl]
            cc[:, 0, 0], cc[:, 1, 1], cc[:, 2, 2] = c00 * inv_det, c11 * inv_det, c22 * inv_det
            cc[:, 0, 1] = cc[:, 1, 0] = c01 * inv_det
            cc[:, 0, 2] = cc[:, 2, 0] = c02 * inv_det
            cc[:, 1, 2] = cc[:, 2, 1] = c12 * inv_det
    zero_q0 = q[:, 0] == 0.0
    if np.any(zero_q0):
        q[zero_q0] = rotations.quat_canonical(q[zero_q0])
    return WahbaResult(q=q.reshape(lead + (4,)), loss=loss.reshape(lead), covariance_rad2=cov.reshape(lead + (3, 3)),
                       lambda_max=lam_max.reshape(lead), status=status.reshape(lead), iterations=iterations,
                       method=name)


def q_method(b: ArrayLike, r: ArrayLike, weights: ArrayLike | None = None, *, covariance: bool = True) -> WahbaResult:
    """Davenport's q-method (002, eq. 9): eigenvector of K for its largest eigenvalue (LAPACK, batched).

    b: (..., n, 3) observed vectors in frame B; r: (..., n, 3) the same directions in frame R (any
    length, normalised here); weights: (..., n) or (n,) a_i >= 0 (default 1). Returns q_BR.
    """
    return _run("q_method", q_method_kernel, b, r, weights, 0.0, 0, covariance)


def svd_method(b: ArrayLike, r: ArrayLike, weights: ArrayLike | None = None, *,
               covariance: bool = True) -> WahbaResult:
    """Markley's SVD method: B = U diag(s) V^T, dcm_BR = U diag(1, 1, det U det V) V^T.

    Arguments as :func:`q_method`. Exact at every rotation angle; LAPACK gesdd per epoch.
    """
    return _run("svd", svd_kernel, b, r, weights, 0.0, 0, covariance)


def quest(b: ArrayLike, r: ArrayLike, weights: ArrayLike | None = None, *, tol: float = 1e-12,
          max_iter: int = 20, covariance: bool = True) -> WahbaResult:
    """QUEST (Shuster & Oh 1981; 002 ref. 12): Newton on the characteristic quartic, q from adj(lambda I - K).

    b: (..., n, 3) observed vectors in frame B; r: (..., n, 3) reference vectors in frame R (normalised
    here); weights (..., n) or (n,) a_i >= 0. tol: Newton stops when every |step| <= tol * lambda0.
    Returns q_BR; robust at every rotation angle (see the module docstring).
    """
    return _run("quest", quest_kernel, b, r, weights, tol, max_iter, covariance)


def esoq2(b: ArrayLike, r: ArrayLike, weights: ArrayLike | None = None, *, tol: float = 1e-12,
          max_iter: int = 20, covariance: bool = True) -> WahbaResult:
    """ESOQ2 (Mortari 1997): lambda_max as in QUEST, rotation axis as the null vector of a 3x3 matrix.

    Arguments as :func:`quest`. The reference frame is always turned by 180 deg about the axis of the
    smallest diagonal element of B (Mortari's rotation to avoid the zero-angle singularity).
    """
    return _run("esoq2", esoq2_kernel, b, r, weights, tol, max_iter, covariance)


METHODS: dict[str, Callable[..., WahbaResult]] = {
    "q_method": q_method,
    "quest": quest,
    "svd": svd_method,
    "esoq2": esoq2,
}


def solve(method: str, b: ArrayLike, r: ArrayLike, weights: ArrayLike | None = None, **options: object
          ) -> WahbaResult:
    """Dispatch by name: one of ``METHODS`` (q_method, quest, svd, esoq2)."""
    try:
        fn = METHODS[method]
    except KeyError:
        raise WahbaInputError(f"unknown Wahba method {method!r}; expected one of {', '.join(METHODS)}") from None
    return fn(b, r, weights, **options)
