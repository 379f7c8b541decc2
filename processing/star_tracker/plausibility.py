"""Plausibility of star-tracker quaternions against gyro rates, and the time-tag offset between them.

Beyond 003 (its data model: star-tracker q_IS every few seconds, gyro rates in between, 003 §1.4 compares
the two rates). A star-tracker upload can be read under a wrong convention and still pass every check of
its own (unit norm, increasing times): scalar-last values under q0..q3 headers, q_SI given instead of q_IS,
a mounting q_BS entered as q_SB. The gyro tells: the relative rotation between consecutive star-tracker
samples must be the one the gyro integrates over the same interval.

Model. For consecutive star-tracker samples n, n+1 (no gap) the measured relative rotation is
dQ_n = q_n^-1 o q_{n+1} (sensor axes at t_n). The gyro's is dU_n(tau) = U(t_n + tau)^-1 o U(t_{n+1} + tau),
U the attitude propagated on the gyro grid by 003 §2.3 scheme 2 (exact partial steps between nodes),
turned into the sensor axes by q_SG = q_BS^-1 o q_BG. tau is the time-tag offset: a star-tracker sample
tagged t was taken at t + tau on the gyro's clock (as in processing.definitive: q_IS(t_tag) =
q_IB(t_tag + tau) o q_BS). The residual rotation e_n = rotvec(dU_n,S(tau)^-1 o dQ_n) is, for the right
convention,

    e_n = c dt_n + K theta_n + noise_n,    noise_n = nu_{n+1} - nu_n + g_n,

c = -b_S the gyro offset (w_meas = w + b) in sensor axes (003's Delta), K a small calibration error of the
gyro (scale factors and misalignment; theta_n the gyro's rotation vector over the interval), nu the
star-tracker noise (white, per sensor axis) and g_n the integrated gyro noise (white, N² dt_n per axis for
an angle random walk N). The noise is MA(1): lag-0 variance 2 sigma² + N² dt, lag-1 covariance -sigma².

Steps of :func:`check_star_tracker_gyro`:

1. Conventions. Each of the eight combinations of {order as given, scalar last} x {q_IS, q_SI} x
   {q_BS, q_SB} is fitted with (c, tau) (tau on a grid over +-max_time_offset_s) on at most
   ``CANDIDATE_INTERVALS`` intervals, and scored by the generalised variance of its residuals,
   det(sum e e^T / P) (the Gaussian likelihood with a free 3x3 noise covariance, log L = -P/2 log det + const:
   made for the anisotropic star-tracker noise whatever axes a reading turns it into, and unchanged when a
   reading merely rotates the noise, so that no reading wins on noise alone, e.g. without motion). When the
   reading as given scores at least ``CONVENTION_RATIO_MIN`` times worse than the best one, the best one is
   reported (``quaternion_convention``), with the readings the data cannot tell from it (within that factor:
   e.g. the transposed mounting when q_BS is close to its own transpose).
   ``convention_determined``: every reading that is not the same rotation scores that much worse.
   Rates that hardly change (a constant rate about a fixed axis, an inertial hold) cannot tell some
   conventions apart: a wrong one then differs by a constant rate that a gyro offset absorbs.
2. Time offset. On the best convention, Gauss-Newton on (c, K, tau), K with a Gaussian prior of
   ``CALIBRATION_PRIOR`` per entry (so that calibration errors of a few 0.1 %, e.g. 000's agile
   satellite, do not look like implausible data while a wrong mounting cannot hide in K), on at most
   ``max_intervals`` intervals (contiguous blocks). Per-axis weights from the residuals; the covariance is
   the sandwich with the lag-0 and lag-1 residual products (exact for MA(1) noise), so sigma_tau comes from
   the residuals, not from an assumed noise. tau is determined when sigma_tau <= time_offset_sigma_max_s;
   its information comes from the rate changes only (a constant rate turns a time offset into a constant
   attitude offset).
3. Consistency. Per sensor axis the residual mean square against the noise it should be:
   2 sigma_st² + N² dt, sigma_st² = -(lag-1 autocovariance of the residuals) (the star-tracker noise seen
   by the data themselves) and N from the gyro's second differences. A smooth systematic disagreement has a
   positive lag-1 autocovariance, so it cannot pass as noise. ``consistency_ratio`` above
   ``CONSISTENCY_MAX`` means the data disagree beyond noise under the best convention: ``implausible_input``.

Warnings (processing.tasks.ResultWarning, in ``PlausibilityResult.warnings``): ``quaternion_convention``
naming the convention that fits and how to re-upload; ``implausible_input`` with the numbers; ``time_offset``
when |tau| > 3 sigma and above ``TIME_OFFSET_MIN_S``. A job that reports the offset adds
``PlausibilityResult.not_observable_warning()`` when the data do not determine it. Clean data raise none
(tests/processing/star_tracker/test_plausibility.py measures it).

Cost: O(N) in the gyro samples (one prefix product of the step quaternions) plus 8 x 41 grid evaluations on
at most 2,000 intervals and a few Gauss-Newton steps on at most ``max_intervals``: ~0.05 s for 20 min of 003
data, ~1.3 s for 24 h of a 10 Hz gyro and a 1 Hz tracker.

Times int64 TAI ns; angles rad; rates rad/s; quaternions scalar first, Hamilton, q_AB maps B to A.
Gyro increments (da over an interval) can be passed as rates da/interval_s at the interval midpoints.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.gyro_calibration.propagation import quat_cumprod, step_quaternions
from processing.tasks import ResultWarning
from processing.units import ARCSEC_PER_RAD, NS_PER_S

__all__ = [
    "CONVENTIONS",
    "Convention",
    "ConventionFit",
    "PlausibilityError",
    "PlausibilityResult",
    "apply_convention",
    "check_star_tracker_gyro",
]

FloatArray = NDArray[np.float64]


def _finite(x: float) -> float | None:
    """JSON has no infinity: None for a non-finite number."""
    return float(x) if np.isfinite(x) else None


CONVENTION_RATIO_MIN = 4.0
"""Another reading is reported when the one given leaves a generalised residual variance this many times
larger (a log-likelihood ratio of P/2 log 4 = 0.7 P for P intervals: never reached by noise)."""
CONSISTENCY_MAX = 4.0
"""Residual mean square per axis above this many times the expected noise (rms 2x) is implausible."""
CALIBRATION_PRIOR = 0.01
"""Prior sigma of each entry of the gyro calibration error K (1 %: scale factors, misalignment ~34')."""
TIME_OFFSET_MIN_S = 1e-3
"""A time offset below this is not worth a warning, however significant."""
CANDIDATE_INTERVALS = 2000
"""Intervals used to compare the conventions (evenly spread); the final fit uses up to max_intervals."""
BLOCK_INTERVALS = 100
"""Decimation of the final fit keeps contiguous blocks of this many intervals (lag-1 terms stay)."""
GAP_FACTOR = 1.5
"""Consecutive star-tracker samples further apart than this times the median step are not paired; gyro
steps longer than 2.5 median steps are gaps that no interval may span."""
TAU_GRID_STEP_S = 0.05
"""Step of the grid search of the time offset (then refined by Gauss-Newton)."""
GN_ITERATIONS = 8


class PlausibilityError(ValueError):
    """Bad input to the plausibility check: shapes, too few samples, no overlap of the two time grids."""


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


@dataclass(frozen=True)
class ConventionFit:
    """A tested convention: its generalised residual variance relative to the best one's (``fit_ratio`` = 1
    for the best), its residual rms per sensor axis (rad per interval), the time offset and gyro offset (gyro
    frame) it would imply."""

    convention: Convention
    fit_ratio: float
    residual_rms_rad: FloatArray
    time_offset_s: float
    gyro_bias_G_rad_s: FloatArray


@dataclass(frozen=True)
class PlausibilityResult:
    """Result of :func:`check_star_tracker_gyro`.

    warnings: ResultWarning list (empty for clean data); convention: name of the best-fitting convention
    (``as_given`` unless another fits clearly better); convention_determined: whether the rates tell the
    conventions apart; candidates: every tested convention, best first; time_offset_s / _sigma_s (None
    when not determined: time_offset_observable False); gyro_bias_G_rad_s (3,) the offset b of w_meas =
    w + b in the gyro frame (an estimate from the increments, for orientation; gyro_bias_fit is the
    estimator); rate_disagreement_rms_rad_s (3,) residual rms per interval / mean interval, sensor axes;
    expected_noise_rms_rad_s (3,) the same for the noise model; consistency_ratio (3,) residual mean square
    over the expected one; star_tracker_noise_rad (3,) sigma_st per sensor axis from the lag-1
    autocovariance; gyro_arw_rad_sqrt_s (3,) per gyro axis; calibration (3, 3) the fitted K;
    n_intervals used by the final fit; mean_interval_s.
    """

    warnings: list[ResultWarning]
    convention: str
    convention_determined: bool
    candidates: tuple[ConventionFit, ...]
    time_offset_s: float | None
    time_offset_sigma_s: float | None
    time_offset_observable: bool
    gyro_bias_G_rad_s: FloatArray
    rate_disagreement_rms_rad_s: FloatArray
    expected_noise_rms_rad_s: FloatArray
    consistency_ratio: FloatArray
    star_tracker_noise_rad: FloatArray
    gyro_arw_rad_sqrt_s: FloatArray
    calibration: FloatArray
    n_intervals: int
    mean_interval_s: float
    time_offset_estimate_s: float = 0.0
    """The estimate and its sigma (inf when the rates carry no information) even when not determined."""
    time_offset_sigma_estimate_s: float = np.inf
    time_offset_sigma_max_s: float = 0.1

    def not_observable_warning(self) -> ResultWarning | None:
        """The ``not_observable`` warning a job that reports time_offset_s adds when it is null (else None).

        Not in ``warnings``: a job that does not report the offset has nothing undetermined to declare."""
        if self.time_offset_observable:
            return None
        return ResultWarning(
            "not_observable",
            f"the rates change too little to determine the star-tracker time offset against the gyro (sigma "
            f"{self.time_offset_sigma_estimate_s:.3g} s > {self.time_offset_sigma_max_s:g} s): time_offset_s is null",
            {"parameters": ["time_offset_s"], "time_offset_sigma_s": _finite(self.time_offset_sigma_estimate_s),
             "sigma_max_s": self.time_offset_sigma_max_s},
        )

    def summary(self) -> dict[str, Any]:
        """JSON-able summary, units in the keys (rates in arcsec/s, the offset in s)."""
        a = ARCSEC_PER_RAD

        def floats(x: FloatArray) -> list[float]:
            return [float(v) for v in np.asarray(x, dtype=np.float64).reshape(-1)]

        return {
            "convention": self.convention,
            "convention_determined": self.convention_determined,
            "time_offset_s": self.time_offset_s,
            "time_offset_sigma_s": self.time_offset_sigma_s,
            "time_offset_observable": self.time_offset_observable,
            "gyro_bias_G_rad_s": floats(self.gyro_bias_G_rad_s),
            "rate_disagreement_rms_arcsec_s": floats(self.rate_disagreement_rms_rad_s * a),
            "expected_noise_rms_arcsec_s": floats(self.expected_noise_rms_rad_s * a),
            "consistency_ratio": floats(self.consistency_ratio),
            "star_tracker_noise_arcsec": floats(self.star_tracker_noise_rad * a),
            "n_intervals": self.n_intervals,
            "mean_interval_s": self.mean_interval_s,
            "candidates": [{"convention": c.convention.name, "fit_ratio": c.fit_ratio,
                            "residual_rms_arcsec": floats(c.residual_rms_rad * a),
                            "time_offset_s": c.time_offset_s} for c in self.candidates],
        }


# ---------------------------------------------------------------------------------------------------
# The gyro attitude at arbitrary times.


@dataclass(frozen=True)
class _Gyro:
    """Gyro grid (s from the first sample), rates (N, 3), node attitudes U (N, 4) of 003 §2.3 scheme 2, the
    cumulative count of gap steps (N,) and the noise per gyro axis."""

    t: FloatArray
    w: FloatArray
    u: FloatArray
    gaps_before: NDArray[np.int64]
    arw: FloatArray

    @classmethod
    def build(cls, t: FloatArray, w: FloatArray) -> _Gyro:
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


def _intervals(t_st: FloatArray, gyro: _Gyro, margin_s: float) -> _Intervals:
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


def _gyro_relative(gyro: _Gyro, iv: _Intervals, tau: float, q_SG: FloatArray) -> FloatArray:
    """dU_n,S(tau) (P, 4): the gyro's relative rotation over each interval shifted by tau, sensor axes."""
    du = rotations.quat_multiply(rotations.quat_conjugate(gyro.attitude(iv.t_a + tau)), gyro.attitude(iv.t_b + tau))
    return rotations.quat_multiply(rotations.quat_multiply(q_SG, du), rotations.quat_conjugate(q_SG))


def _residual(gyro: _Gyro, iv: _Intervals, cand: _Candidate, tau: float) -> tuple[FloatArray, FloatArray]:
    """(e (P, 3) = rotvec(dU_S^-1 o dQ), theta (P, 3) = rotvec(dU_S)) at the offset tau."""
    du = _gyro_relative(gyro, iv, tau, cand.q_SG)
    e = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(du), cand.dq))
    return e, rotations.quat_to_rotvec(du)


def _profile(e: FloatArray, dt: FloatArray, weights: FloatArray) -> tuple[float, FloatArray, FloatArray]:
    """Weighted residual sum of squares after the offset fit e ~ c dt (per axis), c (3,), residuals (P, 3)."""
    c = (dt @ e) / (dt @ dt)
    r = e - dt[:, None] * c
    return float(np.sum(r * r * weights)), c, r


# ---------------------------------------------------------------------------------------------------
# Step 1: the conventions.


def _candidates(q: FloatArray, q_BS: FloatArray, q_BG: FloatArray, iv: _Intervals) -> list[_Candidate]:
    out = []
    for conv in CONVENTIONS:
        qc, q_BS_c = apply_convention(q, q_BS, conv)
        out.append(_Candidate(conv, _relative(qc, iv.first), rotations.quat_multiply(rotations.quat_conjugate(q_BS_c),
                                                                                       q_BG)))
    return out


def _grid_residuals(gyro: _Gyro, iv: _Intervals, cands: list[_Candidate], taus: FloatArray) -> list[FloatArray]:
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
               taus: FloatArray) -> list[tuple[_Candidate, float, float, FloatArray, FloatArray]]:
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


def _rank(gyro: _Gyro, iv: _Intervals, cands: list[_Candidate],
          taus: FloatArray) -> tuple[list[tuple[_Candidate, float, float, FloatArray, FloatArray]], bool]:
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


def _final_fit(gyro: _Gyro, iv: _Intervals, cand: _Candidate, tau0: float, delta_s: float,
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
        e_p, _ = _residual(gyro, iv, cand, tau + delta_s)
        e_m, _ = _residual(gyro, iv, cand, tau - delta_s)
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


# ---------------------------------------------------------------------------------------------------
# The check.


def _inputs(t_st_ns: ArrayLike, q_IS: ArrayLike, q_BS: ArrayLike, t_gyro_ns: ArrayLike, w_G: ArrayLike,
            q_BG: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    ts = np.asarray(t_st_ns)
    tg = np.asarray(t_gyro_ns)
    if ts.dtype.kind not in "iu" or tg.dtype.kind not in "iu":
        raise PlausibilityError(f"times must be integer TAI nanoseconds, got dtypes {ts.dtype} and {tg.dtype}")
    q = np.asarray(q_IS, dtype=np.float64)
    w = np.asarray(w_G, dtype=np.float64)
    if ts.ndim != 1 or q.shape != (ts.size, 4):
        raise PlausibilityError(f"need t_st_ns (M,) and q_IS (M, 4), got {ts.shape} and {q.shape}")
    if tg.ndim != 1 or w.shape != (tg.size, 3) or tg.size < 8:
        raise PlausibilityError(f"need t_gyro_ns (N,) and w_G (N, 3) with N >= 8, got {tg.shape} and {w.shape}")
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(w))):
        raise PlausibilityError("quaternions and rates must be finite")
    if np.any(np.diff(ts) <= 0) or np.any(np.diff(tg) <= 0):
        raise PlausibilityError("star-tracker and gyro times must be strictly increasing")
    m_bs, m_bg = np.asarray(q_BS, dtype=np.float64), np.asarray(q_BG, dtype=np.float64)
    if m_bs.shape != (4,) or m_bg.shape != (4,):
        raise PlausibilityError(f"q_BS and q_BG must have shape (4,), got {m_bs.shape} and {m_bg.shape}")
    epoch = int(tg[0])
    t_s = (ts.astype(np.int64) - epoch).astype(np.float64) / NS_PER_S
    t_g = (tg.astype(np.int64) - epoch).astype(np.float64) / NS_PER_S
    return (t_s, rotations.quat_normalize(q), rotations.quat_normalize(m_bs), t_g, w,
            rotations.quat_normalize(m_bg))


def _spread(n: int, limit: int) -> NDArray[np.int64]:
    """At most ``limit`` of n indices, evenly spread."""
    if n <= limit:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, limit).round().astype(np.int64))


def _blocks(n: int, limit: int) -> NDArray[np.int64]:
    """At most about ``limit`` of n indices in contiguous blocks of BLOCK_INTERVALS, evenly spread."""
    if n <= limit:
        return np.arange(n)
    n_blocks = max(1, limit // BLOCK_INTERVALS)
    starts = np.linspace(0, n - BLOCK_INTERVALS, n_blocks).round().astype(np.int64)
    return np.unique((starts[:, None] + np.arange(BLOCK_INTERVALS)[None, :]).reshape(-1))


def check_star_tracker_gyro(
    t_st_ns: ArrayLike,
    q_IS: ArrayLike,
    q_BS: ArrayLike,
    t_gyro_ns: ArrayLike,
    w_G: ArrayLike,
    q_BG: ArrayLike = (1.0, 0.0, 0.0, 0.0),
    *,
    sensor: str = "star tracker",
    max_time_offset_s: float = 1.0,
    time_offset_sigma_max_s: float = 0.1,
    max_intervals: int = 20_000,
) -> PlausibilityResult:
    """Do the star-tracker quaternions agree with the gyro rates, under which convention, at which time offset?

    t_st_ns (M,) int64 TAI ns, strictly increasing; q_IS (M, 4) as stored (sensor -> inertial, scalar first);
    q_BS (4,) the configured mounting (sensor -> body); t_gyro_ns (N,) int64 TAI ns; w_G (N, 3) rad/s in the
    gyro frame; q_BG (4,) gyro -> body. sensor: the tracker's name for the messages. max_time_offset_s: the
    time offset is searched within +-this; time_offset_sigma_max_s: above this sigma the offset counts as
    not determined; max_intervals: the final fit uses at most this many star-tracker intervals (contiguous
    blocks; 24 h of 1 Hz data are decimated). See the module docstring for the model and the tests.
    Returns :class:`PlausibilityResult`; raises :class:`PlausibilityError` on bad input or when fewer than
    10 usable intervals lie within the gyro span.
    """
    t_s, q, m_bs, t_g, w, m_bg = _inputs(t_st_ns, q_IS, q_BS, t_gyro_ns, w_G, q_BG)
    if not max_time_offset_s > 0 or not time_offset_sigma_max_s > 0:
        raise PlausibilityError("max_time_offset_s and time_offset_sigma_max_s must be > 0")
    gyro = _Gyro.build(t_g, w)
    step_g = float(np.median(np.diff(t_g)))
    delta_s = 2.0 * step_g
    iv_all = _intervals(t_s, gyro, max_time_offset_s + 2.0 * delta_s)
    if iv_all.t_a.size < 10:
        raise PlausibilityError(
            f"need at least 10 pairs of consecutive star-tracker samples within the gyro span, got {iv_all.t_a.size}")
    n_grid = int(np.ceil(max_time_offset_s / TAU_GRID_STEP_S))
    taus = np.linspace(-max_time_offset_s, max_time_offset_s, 2 * n_grid + 1)

    iv_c = iv_all.take(_spread(iv_all.t_a.size, CANDIDATE_INTERVALS))
    fits, determined = _rank(gyro, iv_c, _candidates(q, m_bs, m_bg, iv_c), taus)
    best = fits[0]
    given_ratio = next(f[1] for f in fits if f[0].convention.name == "as_given") / max(best[1], 1e-300)
    switch = best[0].convention.name != "as_given" and given_ratio >= CONVENTION_RATIO_MIN
    chosen = best[0].convention if switch else CONVENTIONS[0]
    tau0 = best[2] if switch else next(f[2] for f in fits if f[0].convention.name == "as_given")

    iv = iv_all.take(_blocks(iv_all.t_a.size, max_intervals))
    cand = _candidates(q, m_bs, m_bg, iv)[CONVENTIONS.index(chosen)]
    r_SG = rotations.quat_to_dcm(cand.q_SG)
    arw_S = np.sqrt(np.einsum("ij,j,ij->i", r_SG, gyro.arw**2, r_SG))
    fin = _final_fit(gyro, iv, cand, tau0, delta_s, max_time_offset_s, arw_S)

    dt = iv.dt
    ms = np.mean(fin.r**2, axis=0)
    lag1 = fin.r[:-1][iv.next_shared[:-1]] * fin.r[1:][iv.next_shared[:-1]]
    sigma_st2 = np.maximum(-np.mean(lag1, axis=0), 0.0) if lag1.size else np.zeros(3)
    expected = 2.0 * sigma_st2 + arw_S**2 * float(np.mean(dt))
    ratio = ms / np.maximum(expected, 1e-300)
    observable = bool(np.isfinite(fin.tau_sigma) and fin.tau_sigma <= time_offset_sigma_max_s)
    bias_G = -(r_SG.T @ fin.c)
    mean_dt = float(np.mean(dt))

    candidates = tuple(
        ConventionFit(convention=f[0].convention, fit_ratio=float(f[1] / max(best[1], 1e-300)),
                      residual_rms_rad=np.sqrt(np.mean(f[4] ** 2, axis=0)), time_offset_s=f[2],
                      gyro_bias_G_rad_s=-(rotations.quat_to_dcm(f[0].q_SG).T @ f[3]))
        for f in fits
    )
    result = PlausibilityResult(
        warnings=[],
        convention=chosen.name,
        convention_determined=determined,
        candidates=candidates,
        time_offset_s=fin.tau if observable else None,
        time_offset_sigma_s=fin.tau_sigma if observable else None,
        time_offset_observable=observable,
        gyro_bias_G_rad_s=bias_G,
        rate_disagreement_rms_rad_s=np.sqrt(ms) / mean_dt,
        expected_noise_rms_rad_s=np.sqrt(expected) / mean_dt,
        consistency_ratio=ratio,
        star_tracker_noise_rad=np.sqrt(sigma_st2),
        gyro_arw_rad_sqrt_s=gyro.arw,
        calibration=fin.k,
        n_intervals=int(dt.size),
        mean_interval_s=mean_dt,
        time_offset_estimate_s=fin.tau,
        time_offset_sigma_estimate_s=fin.tau_sigma,
        time_offset_sigma_max_s=time_offset_sigma_max_s,
    )
    warnings = _warnings(result, sensor, switch, given_ratio)
    return replace(result, warnings=warnings)


# ---------------------------------------------------------------------------------------------------
# Warnings.


def _repair(conv: Convention, sensor: str) -> str:
    steps = []
    if conv.scalar_last:
        steps.append("the columns hold (x, y, z, w): upload them with the header qx, qy, qz, qw (qw is the "
                     "scalar), not q0..q3")
    if conv.inverse:
        steps.append("the values are q_SI (inertial -> sensor): upload with quaternion_direction=inertial_to_sensor")
    if conv.transposed_mounting:
        steps.append(f"the configured q_BS of {sensor} is q_SB: store its conjugate in star_trackers.{sensor}.q_BS "
                     "(PUT /api/v1/spacecraft/{name}/config)")
    return "; ".join(steps)


def _warnings(res: PlausibilityResult, sensor: str, switch: bool, given_ratio: float) -> list[ResultWarning]:
    out: list[ResultWarning] = []
    a = ARCSEC_PER_RAD
    given = next(c for c in res.candidates if c.convention.name == "as_given")
    if switch:
        conv = res.candidates[0].convention
        quat_fix = conv.scalar_last or conv.inverse
        # readings the rates cannot tell from the best (not those that are the same rotation: a mounting equal
        # to its own transpose)
        near = [c for c in res.candidates[1:] if 1.0 + 1e-9 < c.fit_ratio < CONVENTION_RATIO_MIN]
        alike = [c.convention.name for c in near]
        also = (f" (these rates cannot tell it from {', '.join(alike)}, which fit"
                f" {', '.join(f'{c.fit_ratio:.3g}' for c in near)} times worse)" if near else "")
        out.append(ResultWarning(
            "quaternion_convention",
            f"{sensor}: the star-tracker quaternions agree with the gyro only as {conv.name}{also} (the data as given "
            f"fit {given_ratio:.3g} times worse, residual rms {np.round(given.residual_rms_rad * a, 1).tolist()} "
            f"arcsec per interval against {np.round(res.candidates[0].residual_rms_rad * a, 1).tolist()}): "
            + _repair(conv, sensor)
            + (" (retract the upload first: DELETE /api/v1/spacecraft/{name}/ingests/{id})" if quat_fix else ""),
            {"sensor": sensor, "convention": conv.name, "fit_ratio_as_given": given_ratio,
             "residual_rms_as_given_arcsec": [float(x) for x in given.residual_rms_rad * a],
             "residual_rms_arcsec": [float(x) for x in res.candidates[0].residual_rms_rad * a],
             "alike": alike, "candidates": {c.convention.name: c.fit_ratio for c in res.candidates}},
        ))
    if np.max(res.consistency_ratio) > CONSISTENCY_MAX:
        out.append(ResultWarning(
            "implausible_input",
            f"{sensor}: the star-tracker rates disagree with the gyro rates by "
            f"{np.round(res.rate_disagreement_rms_rad_s * a, 2).tolist()} arcsec/s rms (sensor axes), "
            f"{np.round(np.sqrt(res.consistency_ratio), 1).tolist()} times the noise of both sensors, under "
            f"{'every tested convention' if not switch else 'the best convention ' + res.convention}: check the "
            "mountings (q_BS, q_BG), the gyro units (rad/s) and the time tags",
            {"sensor": sensor, "convention": res.convention,
             "rate_disagreement_rms_arcsec_s": [float(x) for x in res.rate_disagreement_rms_rad_s * a],
             "expected_noise_rms_arcsec_s": [float(x) for x in res.expected_noise_rms_rad_s * a],
             "consistency_ratio": [float(x) for x in res.consistency_ratio], "consistency_max": CONSISTENCY_MAX,
             "candidates": {c.convention.name: c.fit_ratio for c in res.candidates}},
        ))
    if res.time_offset_observable and res.time_offset_s is not None and res.time_offset_sigma_s is not None:
        if abs(res.time_offset_s) > max(3.0 * res.time_offset_sigma_s, TIME_OFFSET_MIN_S):
            out.append(ResultWarning(
                "time_offset",
                f"{sensor}: the star-tracker samples were taken {1e3 * abs(res.time_offset_s):.1f} ± "
                f"{1e3 * res.time_offset_sigma_s:.1f} ms {'after' if res.time_offset_s > 0 else 'before'} their "
                "time tags, on the gyro's clock (time_offset_s "
                f"{res.time_offset_s:+.4f} s; true time = "
                "tag + time_offset_s): correct the time tags, or let the job estimate the offset (gyro_bias_fit: "
                "fit_time_offset; definitive_attitude: estimate_time_offset)",
                {"sensor": sensor, "time_offset_s": res.time_offset_s, "sigma_s": res.time_offset_sigma_s,
                 "threshold_s": max(3.0 * res.time_offset_sigma_s, TIME_OFFSET_MIN_S)},
            ))
    return out
