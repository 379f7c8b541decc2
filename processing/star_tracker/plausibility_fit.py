"""The fits behind :func:`processing.star_tracker.plausibility.check_star_tracker_gyro`.

Holds the eight readings of a star-tracker upload (:class:`Convention`, ``CONVENTIONS``,
:func:`apply_convention`), the gyro attitude at arbitrary times (003 §2.3 scheme 2), the pairs of
consecutive star-tracker samples and their residual rotations, step 1 of the check (every convention on a
grid of time offsets, ranked by the generalised residual variance) and step 2 (Gauss-Newton on the offset,
the gyro offset and the calibration error with the sandwich covariance). The model and the steps are
described in :mod:`processing.star_tracker.plausibility`.

Times s from the first gyro sample; angles rad; rates rad/s; quaternions scalar first, Hamilton, q_AB maps B
to A.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.gyro_calibration.propagation import quat_cumprod, step_quaternions

__all__ = [
    "CONVENTIONS",
    "Convention",
    "apply_convention",
]

FloatArray = NDArray[np.float64]

CONVENTION_RATIO_MIN = 4.0
"""Another reading is reported when the one given leaves a generalised residual variance this many times
larger (a log-likelihood ratio of P/2 log 4 = 0.7 P for P intervals: never reached by noise)."""
CALIBRATION_PRIOR = 0.01
"""Prior sigma of each entry of the gyro calibration error K (1 %: scale factors, misalignment ~34')."""
BLOCK_INTERVALS = 100
"""Decimation of the final fit keeps contiguous blocks of this many intervals (lag-1 terms stay)."""
GAP_FACTOR = 1.5
"""Consecutive star-tracker samples further apart than this times the median step are not paired; gyro
steps longer than 2.5 median steps are gaps that no interval may span."""
GN_ITERATIONS = 8


@dataclass(frozen=True)
class Convention:
    """One way of reading the star-tracker upload: ``scalar_last``: the stored q0..q3 hold (x, y, z, w);
    ``inverse``: they are q_SI (sensor <- inertial) rather than q_IS; ``transposed_mounting``: the
    configured q_BS is q_SB."""

    scalar_last: bool
    inverse: bool
    transposed_mounting: bool

    @property
    def name(self) -> str:
        parts = [n for n, on in (("scalar_last", self.scalar_last), ("inverse_direction", self.inverse),
                                 ("transposed_mounting", self.transposed_mounting)) if on]
        return "+".join(parts) or "as_given"


CONVENTIONS: tuple[Convention, ...] = tuple(
    Convention(a, b, c) for c in (False, True) for b in (False, True) for a in (False, True)
)
"""The eight readings tested, ``as_given`` first."""


def apply_convention(q_IS: ArrayLike, q_BS: ArrayLike, convention: Convention) -> tuple[FloatArray, FloatArray]:
    """(q_IS (M, 4), q_BS (4,)) as they would be under ``convention`` (the repair the warning proposes)."""
    q = np.asarray(q_IS, dtype=np.float64)
    if convention.scalar_last:
        q = q[..., [3, 0, 1, 2]]
    if convention.inverse:
        q = rotations.quat_conjugate(q)
    m = np.asarray(q_BS, dtype=np.float64)
    if convention.transposed_mounting:
        m = rotations.quat_conjugate(m)
    return rotations.quat_normalize(q), rotations.quat_normalize(m)


# ---------------------------------------------------------------------------------------------------
# The gyro attitude at arbitrary times.


@dataclass(frozen=True)
class GyroAttitude:
    """Gyro grid (s from the first sample), rates (N, 3), node attitudes U (N, 4) of 003 §2.3 scheme 2, the
    cumulative count of gap steps (N,) and the noise per gyro axis."""

    t: FloatArray
    w: FloatArray
    u: FloatArray
    gaps_before: NDArray[np.int64]
    arw: FloatArray

    @classmethod
    def build(cls, t: FloatArray, w: FloatArray) -> GyroAttitude:
        dt = np.diff(t)
        kappa = step_quaternions(dt, w[:-1], w[1:], 2)
        u = np.concatenate([[[1.0, 0.0, 0.0, 0.0]], quat_cumprod(kappa)])
        step = float(np.median(dt))
        gaps = np.concatenate([[0], np.cumsum(dt > 2.5 * step)])
        d2 = np.diff(w, n=2, axis=0)
        arw = np.sqrt(np.mean(d2 * d2, axis=0) / 6.0 * step)  # white noise: var(d2) = 6 sigma², N = sigma sqrt(h)
        return cls(t, w, u, gaps, arw)

    def node(self, t: FloatArray) -> NDArray[np.int64]:
        return np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, self.t.size - 2)

    def attitude(self, t: FloatArray) -> FloatArray:
        """U(t) (M, 4): the node attitude before t and a partial scheme-2 step with the rate interpolated."""
        k = self.node(t)
        h = t - self.t[k]
        frac = (h / (self.t[k + 1] - self.t[k]))[:, None]
        w_t = self.w[k] + frac * (self.w[k + 1] - self.w[k])
        return rotations.quat_multiply(self.u[k], step_quaternions(h, self.w[k], w_t, 2))


# ---------------------------------------------------------------------------------------------------
# Intervals and residuals.


@dataclass(frozen=True)
class _Intervals:
    """Pairs of consecutive star-tracker samples: start/end times (P,) s, lengths, the sample index of the
    start (P,) and whether each pair shares its end sample with the next pair (lag-1 neighbours)."""

    t_a: FloatArray
    t_b: FloatArray
    first: NDArray[np.int64]
    next_shared: NDArray[np.bool_]

    @property
    def dt(self) -> FloatArray:
        return self.t_b - self.t_a

    def take(self, idx: NDArray[np.int64]) -> _Intervals:
        shared = np.zeros(idx.size, dtype=bool)
        shared[:-1] = (self.first[idx[1:]] == self.first[idx[:-1]] + 1)
        return _Intervals(self.t_a[idx], self.t_b[idx], self.first[idx], shared)


def pair_intervals(t_st: FloatArray, gyro: GyroAttitude, margin_s: float) -> _Intervals:
    dt = np.diff(t_st)
    step = float(np.median(dt)) if dt.size else 0.0
    ok = (dt > 0) & (dt <= GAP_FACTOR * step)
    a, b = t_st[:-1], t_st[1:]
    ok &= (a - margin_s >= gyro.t[0]) & (b + margin_s <= gyro.t[-1])
    ka = gyro.node(np.clip(a - margin_s, gyro.t[0], gyro.t[-1]))
    kb = gyro.node(np.clip(b + margin_s, gyro.t[0], gyro.t[-1]))
    ok &= gyro.gaps_before[kb + 1] == gyro.gaps_before[ka]
    idx = np.flatnonzero(ok)
    shared = np.zeros(idx.size, dtype=bool)
    shared[:-1] = idx[1:] == idx[:-1] + 1
    return _Intervals(a[idx], b[idx], idx, shared)


def _relative(q: FloatArray, first: NDArray[np.int64]) -> FloatArray:
    """dQ_n = q_n^-1 o q_{n+1} (P, 4) for the pairs starting at ``first``."""
    return rotations.quat_multiply(rotations.quat_conjugate(q[first]), q[first + 1])


@dataclass(frozen=True)
class _Candidate:
    """A convention's measured relative rotations dQ (P, 4) on the intervals and its q_SG (4,)."""

    convention: Convention
    dq: FloatArray
    q_SG: FloatArray


GridFit = tuple[_Candidate, float, float, FloatArray, FloatArray]
"""A convention's grid fit: (candidate, score, its tau, c (3,), residuals (P, 3))."""


def _end_attitudes(gyro: GyroAttitude, iv: _Intervals, tau: float) -> tuple[FloatArray, FloatArray]:
    """U(t_a + tau) and U(t_b + tau) (P, 4): an end shared with the next interval's start (the contiguous blocks
    of the final fit) is that start's attitude, computed once (the same rows)."""
    u_a = gyro.attitude(iv.t_a + tau)
    shared = iv.next_shared[:-1]
    u_b = np.empty_like(u_a)
    u_b[:-1][shared] = u_a[1:][shared]
    own = ~iv.next_shared
    own[-1] = True
    u_b[own] = gyro.attitude(iv.t_b[own] + tau)
    return u_a, u_b


def _gyro_relative(gyro: GyroAttitude, iv: _Intervals, tau: float, q_SG: FloatArray) -> FloatArray:
    """dU_n,S(tau) (P, 4): the gyro's relative rotation over each interval shifted by tau, sensor axes."""
    u_a, u_b = _end_attitudes(gyro, iv, tau)
    du = rotations.quat_multiply(rotations.quat_conjugate(u_a), u_b)
    return rotations.quat_multiply(rotations.quat_multiply(q_SG, du), rotations.quat_conjugate(q_SG))


def _misfit(du: FloatArray, cand: _Candidate) -> FloatArray:
    """e (P, 3) = rotvec(dU_S^-1 o dQ) for the gyro's relative rotations du (P, 4)."""
    return rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(du), cand.dq))


def _residual(gyro: GyroAttitude, iv: _Intervals, cand: _Candidate, tau: float) -> tuple[FloatArray, FloatArray]:
    """(e (P, 3) = rotvec(dU_S^-1 o dQ), theta (P, 3) = rotvec(dU_S)) at the offset tau."""
    du = _gyro_relative(gyro, iv, tau, cand.q_SG)
    return _misfit(du, cand), rotations.quat_to_rotvec(du)


def _profile(e: FloatArray, dt: FloatArray, weights: FloatArray) -> tuple[float, FloatArray, FloatArray]:
    """Weighted residual sum of squares after the offset fit e ~ c dt (per axis), c (3,), residuals (P, 3)."""
    c = (dt @ e) / (dt @ dt)
    r = e - dt[:, None] * c
    return float(np.sum(r * r * weights)), c, r


# ---------------------------------------------------------------------------------------------------
# Step 1: the conventions.


def candidate_rotations(q: FloatArray, q_BS: FloatArray, q_BG: FloatArray, iv: _Intervals) -> list[_Candidate]:
    out = []
    for conv in CONVENTIONS:
        qc, q_BS_c = apply_convention(q, q_BS, conv)
        out.append(_Candidate(conv, _relative(qc, iv.first), rotations.quat_multiply(rotations.quat_conjugate(q_BS_c),
                                                                                       q_BG)))
    return out


def _grid_residuals(gyro: GyroAttitude, iv: _Intervals, cands: list[_Candidate], taus: FloatArray) -> list[FloatArray]:
    """Per candidate the residual rotations e (G, P, 3) on the tau grid; the gyro's relative rotations are
    computed once, and turned into sensor axes once per distinct mounting."""
    t_a = (iv.t_a[None, :] + taus[:, None]).ravel()
    t_b = (iv.t_b[None, :] + taus[:, None]).ravel()
    du = rotations.quat_multiply(rotations.quat_conjugate(gyro.attitude(t_a)), gyro.attitude(t_b))
    du = du.reshape(taus.size, -1, 4)
    in_sensor: dict[bytes, FloatArray] = {}
    out = []
    for cand in cands:
        key = cand.q_SG.tobytes()
        if key not in in_sensor:
            in_sensor[key] = rotations.quat_multiply(rotations.quat_multiply(cand.q_SG, du),
                                                     rotations.quat_conjugate(cand.q_SG))
        out.append(rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(in_sensor[key]),
                                                                    cand.dq[None])))
    return out


def _grid_fits(e_all: list[FloatArray], cands: list[_Candidate], iv: _Intervals,
               taus: FloatArray) -> list[GridFit]:
    """Per candidate (candidate, score, its tau, c (3,), residuals (P, 3)), the score the least over the tau
    grid of the generalised variance det(R^T R / P) of the residuals after the offset fit."""
    dt = iv.dt
    out = []
    for cand, e in zip(cands, e_all, strict=True):
        c = np.einsum("n,gni->gi", dt, e) / (dt @ dt)
        r = e - dt[None, :, None] * c[:, None, :]
        score = np.maximum(np.linalg.det(np.einsum("gni,gnj->gij", r, r) / dt.size), 0.0)
        j = int(np.argmin(score))
        out.append((cand, float(score[j]), float(taus[j]), c[j], r[j]))
    return out


def rank_conventions(gyro: GyroAttitude, iv: _Intervals, cands: list[_Candidate],
          taus: FloatArray) -> tuple[list[GridFit], bool]:
    """Every candidate's grid fit, best first (generalised residual variance), and whether the best is
    determined (every different one is CONVENTION_RATIO_MIN worse)."""
    e_all = _grid_residuals(gyro, iv, cands, taus)
    fits = sorted(_grid_fits(e_all, cands, iv, taus), key=lambda f: f[1])
    best = fits[0]
    scale = max(best[1], 1e-300)
    # a candidate that is the same rotation as the best (e.g. a mounting equal to its own transpose, or no
    # motion at all) leaves the same residuals to rounding
    different = [f for f in fits[1:] if f[1] - best[1] > 1e-9 * scale]
    determined = bool(different) and all(f[1] / scale >= CONVENTION_RATIO_MIN for f in different)
    return fits, determined


# ---------------------------------------------------------------------------------------------------
# Step 2: the final fit of (c, K, tau) with the sandwich covariance.


@dataclass(frozen=True)
class _Final:
    tau: float
    tau_sigma: float
    c: FloatArray
    k: FloatArray
    r: FloatArray


def final_fit(gyro: GyroAttitude, iv: _Intervals, cand: _Candidate, tau0: float, delta_s: float,
               max_time_offset_s: float, arw_S: FloatArray) -> _Final:
    """Gauss-Newton on x = (c (3), vec K (9), s): e(tau) ~ c dt + K theta - (de/dtau) s, tau <- tau + s, with
    the Gaussian prior on K, per-axis weights from the residuals; then the sandwich covariance."""
    p = iv.dt.size
    prior = np.zeros(13)
    prior[3:12] = 1.0 / CALIBRATION_PRIOR**2
    jac = np.zeros((p, 3, 13))
    jac[:, :, 0:3] = iv.dt[:, None, None] * np.eye(3)

    def solve(tau: float, weights: FloatArray | None) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray,
                                                                FloatArray]:
        e, theta = _residual(gyro, iv, cand, tau)
        e_p = _misfit(_gyro_relative(gyro, iv, tau + delta_s, cand.q_SG), cand)  # no theta needed at tau +- delta
        e_m = _misfit(_gyro_relative(gyro, iv, tau - delta_s, cand.q_SG), cand)
        for i in range(3):
            jac[:, i, 3 + 3 * i: 6 + 3 * i] = theta
        jac[:, :, 12] = -(e_p - e_m) / (2.0 * delta_s)
        if weights is None:
            _, _, r0 = _profile(e, iv.dt, np.ones(3))
            weights = 1.0 / np.maximum(np.mean(r0**2, axis=0), 1e-30)
        jw = jac * weights[None, :, None]
        a_mat = np.einsum("nip,niq->pq", jw, jac) + np.diag(prior)
        sol = np.linalg.solve(a_mat, np.einsum("nip,ni->p", jw, e))
        r = e - np.einsum("nip,p->ni", jac, sol)
        return sol, r, a_mat, jw, weights

    tau, weights = tau0, None
    for it in range(GN_ITERATIONS + 1):
        sol, r, a_mat, jw, w_used = solve(tau, weights)
        step = float(sol[12])
        # converged when the step is a hundredth of the offset's scale 1 / sqrt(a_tau,tau); that last, tiny step
        # is applied to first order (so is the last one when the iterations run out)
        if it == GN_ITERATIONS or abs(step) * np.sqrt(max(a_mat[12, 12], 1e-300)) < 0.01:
            break
        tau = float(np.clip(tau + np.clip(step, -0.5, 0.5), -max_time_offset_s, max_time_offset_s))
        weights = 1.0 / np.maximum(np.mean(r**2, axis=0), 1e-30)
    g = np.einsum("nip,ni->np", jw, r)  # scores (P, 13)
    lag0 = g.T @ g
    shared = iv.next_shared[:-1]
    cross = g[:-1][shared].T @ g[1:][shared]
    # de/dtau holds the gyro noise at both ends of each interval (variance N²/delta per axis): its share of
    # the curvature is not information about tau (errors in variables), so it is taken out of the bread.
    a_sig = a_mat.copy()
    a_sig[12, 12] -= p * float(np.sum(w_used * arw_S**2)) / delta_s
    var_tau = np.inf
    if a_sig[12, 12] > 0 and np.all(np.linalg.eigvalsh(a_sig) > 0):
        a_inv = np.linalg.inv(a_sig)
        var_tau = float((a_inv @ (lag0 + cross + cross.T) @ a_inv)[12, 12])
        if not var_tau > 0:  # the truncated lag-1 sum need not be positive definite: fall back to lag 0
            var_tau = float((a_inv @ lag0 @ a_inv)[12, 12])
    return _Final(tau=tau + step, tau_sigma=float(np.sqrt(max(var_tau, 0.0))), c=sol[:3],
                  k=sol[3:12].reshape(3, 3), r=r)


def spread_indices(n: int, limit: int) -> NDArray[np.int64]:
    """At most ``limit`` of n indices, evenly spread."""
    if n <= limit:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, limit).round().astype(np.int64))


def block_indices(n: int, limit: int) -> NDArray[np.int64]:
    """At most about ``limit`` of n indices in contiguous blocks of BLOCK_INTERVALS, evenly spread."""
    if n <= limit:
        return np.arange(n)
    n_blocks = max(1, limit // BLOCK_INTERVALS)
    starts = np.linspace(0, n - BLOCK_INTERVALS, n_blocks).round().astype(np.int64)
    return np.unique((starts[:, None] + np.arange(BLOCK_INTERVALS)[None, :]).reshape(-1))

