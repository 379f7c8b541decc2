"""Nonlinear discrete Luenberger observer of the gyro drift (000, eqs. 3-8), motion classes, drift trend.

Paper 000 (Somov & Butyrin 2016) estimates the gyro drift b^g at the star-tracker period T_o with a
discrete observer. Linear model (000, eqs. 3-4), per axis, p = 4 sigma ~ attitude angle:

    p_{k+1} = p_k + i_k + b_k T_o,  b_{k+1} = b_k,  y_k = p_k          (state x = {p, b})

observer x^_{k+1} = A_d x^_k + B_d u_k + G_d (y_k - C_d x^_k), G_d = {g1 I, g2 I} (eq. 6), error
dynamics eps_{k+1} = (A_d - G_d C_d) eps_k (eq. 5) with the characteristic polynomial per channel
z^2 + a1 z + a0, a1 = -(2 - g1), a0 = 1 - (g1 - T_o g2). The gains place both roots at
z* = exp(nu T_o (-xi +- j sqrt(1 - xi^2))), nu = 3 / (xi T_r), xi = 0.95 (Vieta: a0* = exp(-2 xi nu T_o),
a1* = -2 exp(-xi nu T_o) cos(nu T_o sqrt(1 - xi^2))), so that the estimates enter a +-5 % tube of the
initial error within about T_r (:func:`observer_gains`).

Nonlinear form (000, eq. 8). The attitude estimate is a quaternion, propagated over [t_k, t_k+1] by the
integral of eq. (7) on the calibrated gyro spline (processing.signal.gyro_integration.interval_rotations), and
corrected by the rotation Q(e, g phi) of the fraction g of the innovation rotation; the drift by
4 g2 sigma of the innovation. Implementation notes (all equivalent to 000 in the linear limit):

- innovation: delta_k = 4 sigma(Lambda^_k^-1 o Lambda_m,k), the measured attitude relative to the
  predicted one in the star-tracker axes (~ p^a_k - p^_k of eq. 6). 000 writes Q_k = Lambda~_m,k o
  Lambda^_k (the conjugate); the sign used here is the one for which (8) reduces to (6).
- current form: eq. (6) is the predictor form x^_{k+1|k} = A x^_{k|k-1} + B u + G (y - C x^). The same
  observer in current (filter) form corrects at t_k, x^_{k|k} = x^_{k|k-1} + K (y - C x^), and then
  predicts with A; G = A K gives K = {alpha I, (beta / T_o) I} with alpha = g1 - T_o g2, beta = T_o g2,
  and identical predictions. The current form lets the corrected attitude start each interval.
- sign of the drift: here b is the drift *in the measured rate* (w_meas = w + b, subtracted by the
  correction of eq. 2), so b^_{k|k} = b^_{k|k-1} - (beta / T_o) M delta_k, with M mapping a rate in the
  star-tracker axes back to the gyro frame (M = (1 + m^) dcm_GS^; 000 adds g2 Delta p to the drift of
  its model (3), where the drift enters with the opposite sign).
- acquisition: at start-up the gains are max(alpha_n, alpha), max(beta_n, beta) with
  alpha_n = 2 (2n - 1) / (n (n + 1)), beta_n = 6 / (n (n + 1)) the growing-memory least-squares gains of
  the n-th measurement (the alpha-beta filter equal to a straight-line fit of all data so far, i.e. the
  transient Kalman gains without process noise). 000 chose its stationary gains close to the
  steady-state Kalman filter and notes that the transient Kalman gains need the Riccati equation;
  these gains give the transient of the line fit, and the stationary observer of 000 after about
  4 T_r / (3 xi) samples. With acquisition=False the observer is stationary from the start.
- motion classes: the correction runs only in class MT_alpha, where |w| <= 1 deg/s (a parameter) on
  both sides of the sample. During faster slews (000: 1-5 deg/s, up to 120 s) the correction is off and
  the drift is predicted by a least-squares polynomial trend (000: 2nd order) of the drift estimates
  of the last window of corrected operation (:func:`fit_drift_trend`). When the correction resumes the
  attitude estimate is re-initialised from the star tracker (the attitude error accumulated over the
  slew would otherwise be read as drift); the drift keeps its predicted value. The innovation at that
  sample, the attitude error of the prediction through the slew, is recorded (:func:`slew_error_bound`
  bounds it). The reset attitude carries the full star-tracker noise, so for the next 1/alpha samples
  the attitude gain is 1/n and the drift gain 0 (the least-squares mean of the innovations with the
  drift held: re-acquisition), after which the stationary gains resume; without it every reset would
  disturb the drift estimate by ~ beta/T_o x the star-tracker noise. An interval that leaves the gyro
  data (a gap) is handled the same way.

The drift increment during propagation: the spline was corrected with a reference drift b_ref, the
estimate differs by db = b^ - b_ref, so the rate of the frame is off by -L db (L = dcm_SG / (1 + m^)),
and the interval rotation U_k is corrected to U_k o exp(J_k (-L db)) with J_k = T (I - [theta_k x] / 2)
the first-order Jacobian of the rotation over the interval with respect to a constant rate (theta_k the
interval's rotation vector; the neglected terms are of relative order |theta|^2 / 6, 1e-3 at 5 deg/s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import solve_discrete_lyapunov

from processing.attitude import rotations

__all__ = [
    "MODE_CORRECTED",
    "MODE_INIT",
    "MODE_PREDICTED",
    "MODE_RESUMED",
    "DriftObserverError",
    "DriftObserverResult",
    "DriftTrend",
    "acquisition_gains",
    "fit_drift_trend",
    "observer_gains",
    "ramp_lag_s",
    "run_drift_observer",
    "slew_error_bound",
    "stationary_noise",
]

FloatArray = NDArray[np.float64]

MODE_INIT, MODE_CORRECTED, MODE_PREDICTED, MODE_RESUMED = 0, 1, 2, 3
MODE_NAMES = {MODE_INIT: "init", MODE_CORRECTED: "corrected", MODE_PREDICTED: "predicted", MODE_RESUMED: "resumed"}


class DriftObserverError(ValueError):
    """Bad observer input: shapes, non-increasing times, parameters outside their domain."""


def observer_gains(t_o_s: float, t_r_s: float, xi: float = 0.95) -> tuple[float, float]:
    """Gains (g1 [-], g2 [1/s]) of 000 eq. (6) placing both roots at exp(nu T_o (-xi +- j sqrt(1 - xi^2))).

    nu = 3 / (xi T_r); a0* = exp(-2 xi nu T_o), a1* = -2 exp(-xi nu T_o) cos(nu T_o sqrt(1 - xi^2));
    from a1 = -(2 - g1), a0 = 1 - (g1 - T_o g2): g1 = 2 + a1*, g2 = (a0* - 1 + g1) / T_o. 000, eqs. 5-6.
    """
    if not (t_o_s > 0 and t_r_s > 0 and 0 < xi < 1):
        raise DriftObserverError(f"need T_o > 0, T_r > 0, 0 < xi < 1; got {t_o_s}, {t_r_s}, {xi}")
    nu = 3.0 / (xi * t_r_s)
    a0 = math.exp(-2.0 * xi * nu * t_o_s)
    a1 = -2.0 * math.exp(-xi * nu * t_o_s) * math.cos(nu * t_o_s * math.sqrt(1.0 - xi * xi))
    g1 = 2.0 + a1
    return g1, (a0 - 1.0 + g1) / t_o_s


def acquisition_gains(n: int) -> tuple[float, float]:
    """Growing-memory (straight-line least-squares) current-form gains (alpha_n, beta_n) of measurement n >= 2."""
    return 2.0 * (2 * n - 1) / (n * (n + 1)), 6.0 / (n * (n + 1))


def ramp_lag_s(t_o_s: float, t_r_s: float, xi: float = 0.95) -> float:
    """Lag [s] of the stationary observer's drift estimate behind a drift that changes at a constant rate.

    With the current-form gains (alpha, beta) the classical alpha-beta steady-state error to a constant
    second difference of the tracked angle gives a drift error of b' T_o (alpha - beta / 2) / beta for a
    drift rate b': the estimate equals the drift T_o (alpha - beta / 2) / beta seconds earlier
    (~0.6 T_r for xi = 0.95). Slews and re-acquisitions, during which the drift is not corrected,
    lengthen the effective lag.
    """
    g1, g2 = observer_gains(t_o_s, t_r_s, xi)
    alpha, beta = g1 - t_o_s * g2, t_o_s * g2
    return t_o_s * (alpha - 0.5 * beta) / beta


def stationary_noise(t_o_s: float, t_r_s: float, noise_rad: float, xi: float = 0.95) -> tuple[float, float]:
    """Steady-state std of the attitude [rad] and drift [rad/s] errors of one channel for white
    measurement noise of std noise_rad (discrete Lyapunov equation of eq. 5 with the noise input)."""
    g1, g2 = observer_gains(t_o_s, t_r_s, xi)
    alpha, beta = g1 - t_o_s * g2, t_o_s * g2
    # current form, per axis: e = attitude error before the correction, c = T_o x drift error;
    # e' = (1 - alpha - beta) e + c - (alpha + beta) v, c' = c - beta e - beta v (v measurement noise)
    a = np.array([[1.0 - alpha - beta, 1.0], [-beta, 1.0]])
    g = np.array([[-(alpha + beta)], [-beta]]) * noise_rad
    p = solve_discrete_lyapunov(a, g @ g.T)
    return float(math.sqrt(p[0, 0])), float(math.sqrt(p[1, 1]) / t_o_s)


@dataclass(frozen=True)
class DriftTrend:
    """Least-squares polynomial drift trend b(t) = sum_p c_p ((t - t_ref) / scale)^p (000: 2nd order).

    coefficients (degree + 1, 3) [rad/s]; t_ref_s, scale_s [s]; span_s: times the fit used [first, last].
    """

    coefficients: FloatArray
    t_ref_s: float
    scale_s: float
    span_s: tuple[float, float]

    @property
    def degree(self) -> int:
        return self.coefficients.shape[0] - 1

    def shifted(self, lead_s: float) -> DriftTrend:
        """The trend advanced by lead_s: b'(t) = b(t + lead_s) (compensates an estimator lag of lead_s)."""
        return DriftTrend(coefficients=self.coefficients, t_ref_s=self.t_ref_s - lead_s, scale_s=self.scale_s,
                          span_s=self.span_s)

    def __call__(self, t_s: ArrayLike) -> FloatArray:
        x = (np.asarray(t_s, dtype=np.float64) - self.t_ref_s) / self.scale_s
        out = np.zeros(np.shape(x) + (3,))
        for c in self.coefficients[::-1]:
            out = out * x[..., None] + c
        return out


def fit_drift_trend(t_s: ArrayLike, drift: ArrayLike, degree: int, *, min_span_per_degree_s: float = 100.0
                    ) -> DriftTrend:
    """LSQ polynomial trend of drift estimates (000: prediction through slews from a 2nd-order trend).

    t_s (n,) [s], drift (n, 3) [rad/s], n >= 1. The degree is reduced to what the data support: at most
    n - 1 and at most span / min_span_per_degree_s (a short window extrapolated by a high degree would
    amplify the estimates' noise). Centred and scaled time for conditioning.
    """
    t = np.asarray(t_s, dtype=np.float64)
    b = np.asarray(drift, dtype=np.float64)
    if t.ndim != 1 or t.size == 0 or b.shape != (t.size, 3):
        raise DriftObserverError(f"expected t_s (n >= 1,) and drift (n, 3), got {t.shape} and {b.shape}")
    span = float(t[-1] - t[0])
    d = int(max(0, min(degree, t.size - 1, math.floor(span / min_span_per_degree_s))))
    t_ref = 0.5 * float(t[0] + t[-1])
    scale = max(0.5 * span, 1.0)
    x = (t - t_ref) / scale
    v = x[:, None] ** np.arange(d + 1)
    coef, *_ = np.linalg.lstsq(v, b, rcond=None)
    return DriftTrend(coefficients=np.asarray(coef, dtype=np.float64), t_ref_s=t_ref, scale_s=scale,
                      span_s=(float(t[0]), float(t[-1])))


@dataclass(frozen=True)
class DriftObserverResult:
    """Observer output at the star-tracker samples (K of them).

    q_prior (K, 4): predicted q_IS^ before the correction at t_k; q_post (K, 4) after it.
    drift_rad_s (K, 3): drift estimate b^ after the step, gyro frame (w_meas = (1 + m) S^Delta w + b).
    innovation_rad (K, 3): 4 sigma(q_prior^-1 o q_meas), the measured attitude relative to the
    prediction in star-tracker axes (~ rotation vector). mode (K,) int8: MODE_INIT, MODE_CORRECTED,
    MODE_PREDICTED (slew: correction off, drift from the trend), MODE_RESUMED (re-initialised after a
    slew or a gyro gap). gain_attitude, gain_drift_s (K,): alpha_k and beta_k / T_o used (0 when off).
    stationary_from (K,) bool: the gains had reached their stationary values. g1, g2: 000's gains.
    """

    t_s: FloatArray
    q_prior: FloatArray
    q_post: FloatArray
    drift_rad_s: FloatArray
    innovation_rad: FloatArray
    mode: NDArray[np.int8]
    gain_attitude: FloatArray
    gain_drift_s: FloatArray
    stationary: NDArray[np.bool_]
    g1: float
    g2: float

    def slew_end_errors(self) -> tuple[NDArray[np.intp], FloatArray]:
        """Indices of the samples where the correction resumed after a slew, and the innovation there
        (rad, (n, 3)): the attitude error of the drift-predicted estimate at the end of the slew (plus the
        star-tracker noise)."""
        idx = np.flatnonzero(self.mode == MODE_RESUMED)
        return idx, self.innovation_rad[idx]


def _qmul(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3, a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1, a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


def _exp(vx: float, vy: float, vz: float) -> tuple[float, float, float, float]:
    """Quaternion of the rotation vector v (rad)."""
    th = math.sqrt(vx * vx + vy * vy + vz * vz)
    if th < 1e-3:
        k = 0.5 - th * th / 48.0
        c = 1.0 - th * th / 8.0 + th**4 / 384.0
    else:
        k = math.sin(0.5 * th) / th
        c = math.cos(0.5 * th)
    return (c, k * vx, k * vy, k * vz)


def _delta(q_hat: tuple[float, ...], q_m: tuple[float, ...]) -> tuple[float, float, float]:
    """4 sigma(q_hat^-1 o q_m) with the shorter of the two MRP sets."""
    a0, a1, a2, a3 = q_hat
    b0, b1, b2, b3 = q_m
    e0 = a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3
    e1 = a0 * b1 - a1 * b0 - a2 * b3 + a3 * b2
    e2 = a0 * b2 + a1 * b3 - a2 * b0 - a3 * b1
    e3 = a0 * b3 - a1 * b2 + a2 * b1 - a3 * b0
    if e0 < 0.0:
        e0, e1, e2, e3 = -e0, -e1, -e2, -e3
    s = 4.0 / (1.0 + e0)
    return (s * e1, s * e2, s * e3)


def _normalize(q: tuple[float, ...]) -> tuple[float, float, float, float]:
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def run_drift_observer(
    t_s: ArrayLike,
    q_meas: ArrayLike,
    interval_q: ArrayLike,
    interval_rotvec: ArrayLike,
    interval_valid: ArrayLike,
    correction_on: ArrayLike,
    *,
    rate_map: ArrayLike,
    drift_ref_rad_s: ArrayLike = (0.0, 0.0, 0.0),
    t_r_s: float = 200.0,
    xi: float = 0.95,
    acquisition: bool = True,
    drift0_rad_s: ArrayLike = (0.0, 0.0, 0.0),
    trend_window_s: float = 600.0,
    trend_degree: int = 2,
) -> DriftObserverResult:
    """Run the nonlinear drift observer (000, eq. 8) over K star-tracker samples.

    t_s (K,) [s] increasing sample times; q_meas (K, 4) measured q_IS (frame A = star tracker);
    interval_q (K - 1, 4), interval_rotvec (K - 1, 3), interval_valid (K - 1,): rotation of A over each
    interval from the calibrated spline corrected with drift_ref_rad_s (gyro_integration.interval_rotations);
    correction_on (K,) bool: class MT_alpha at the sample (correction allowed).
    rate_map (3, 3): L = dcm_SG / (1 + m^), the map from a gyro-frame rate to the A-frame rate.
    t_r_s, xi: 000's T_r and xi; acquisition: growing-memory gains at start-up (see module docstring).
    drift0_rad_s: initial drift estimate (gyro frame). trend_window_s, trend_degree: prediction through
    slews from the trend of the corrected, stationary-gain estimates of the last window.
    Initialised from the first star-tracker quaternion (000). Returns :class:`DriftObserverResult`.
    """
    inp = _observer_inputs(t_s, q_meas, interval_q, interval_rotvec, interval_valid, correction_on, rate_map)
    plan = _observer_plan(inp, drift_ref_rad_s, t_r_s, xi)
    return _observe(inp, plan, acquisition, drift0_rad_s, trend_window_s, trend_degree)


@dataclass(frozen=True)
class _ObserverInputs:
    """Checked observer inputs (shapes in :func:`run_drift_observer`): t (K,), q_meas (K, 4), the
    interval rotations, rotation vectors and validity (K - 1, ...), correction_on (K,), rate_map L."""

    t: FloatArray
    q_meas: FloatArray
    interval_q: FloatArray
    interval_rotvec: FloatArray
    interval_valid: NDArray[np.bool_]
    on: NDArray[np.bool_]
    rate_map: FloatArray


def _observer_inputs(
    t_s: ArrayLike, q_meas: ArrayLike, interval_q: ArrayLike, interval_rotvec: ArrayLike,
    interval_valid: ArrayLike, correction_on: ArrayLike, rate_map: ArrayLike,
) -> _ObserverInputs:
    t = np.asarray(t_s, dtype=np.float64)
    qm = np.asarray(q_meas, dtype=np.float64)
    k_n = t.size
    iq = np.asarray(interval_q, dtype=np.float64)
    irv = np.asarray(interval_rotvec, dtype=np.float64)
    ivalid = np.asarray(interval_valid, dtype=bool)
    on = np.asarray(correction_on, dtype=bool)
    if (t.ndim != 1 or k_n < 2 or qm.shape != (k_n, 4) or iq.shape != (k_n - 1, 4) or irv.shape != (k_n - 1, 3)
            or ivalid.shape != (k_n - 1,) or on.shape != (k_n,)):
        raise DriftObserverError(
            f"shapes: t_s (K,), q_meas (K, 4), interval_* (K - 1, ...), correction_on (K,); got {t.shape}, "
            f"{qm.shape}, {iq.shape}, {irv.shape}, {ivalid.shape}, {on.shape}"
        )
    if not np.all(np.diff(t) > 0):
        raise DriftObserverError("star-tracker times must be strictly increasing")
    lmap = np.asarray(rate_map, dtype=np.float64)
    if lmap.shape != (3, 3):
        raise DriftObserverError(f"rate_map must be (3, 3), got {lmap.shape}")
    return _ObserverInputs(t, qm, iq, irv, ivalid, on, lmap)


@dataclass(frozen=True)
class _ObserverPlan:
    """Gains (000 eqs. 5-6: g1, g2 and the current-form alpha, beta) at T_o, and per-sample Python rows
    for the sequential loop: measured quaternions, interval rotations, the per-interval Jacobian-times-map
    (rotation-vector change per unit drift change, 9 numbers), the inverse rate map M and b_ref."""

    t_o: float
    g1: float
    g2: float
    alpha_s: float
    beta_s: float
    qm: list[tuple[float, ...]]
    iq: list[tuple[float, ...]]
    jl: list[list[float]]
    m_rows: list[tuple[float, ...]]
    b_ref: FloatArray


def _observer_plan(inp: _ObserverInputs, drift_ref_rad_s: ArrayLike, t_r_s: float, xi: float) -> _ObserverPlan:
    m_rows = [tuple(map(float, r)) for r in np.linalg.inv(inp.rate_map)]
    t_o = float(np.median(np.diff(inp.t)))
    g1, g2 = observer_gains(t_o, t_r_s, xi)
    dt = np.diff(inp.t)
    jac = dt[:, None, None] * (np.eye(3) - 0.5 * rotations.skew(inp.interval_rotvec))
    jl = -(jac @ inp.rate_map)
    return _ObserverPlan(
        t_o=t_o, g1=g1, g2=g2, alpha_s=g1 - t_o * g2, beta_s=t_o * g2,
        qm=[tuple(map(float, r)) for r in rotations.quat_normalize(inp.q_meas)],
        iq=[tuple(map(float, r)) for r in inp.interval_q], jl=jl.reshape(-1, 9).tolist(),
        m_rows=m_rows,
        b_ref=np.asarray(drift_ref_rad_s, dtype=np.float64),
    )


def _propagated(q_hat: tuple[float, ...], b: list[float], plan: _ObserverPlan, k: int) -> tuple[float, ...]:
    """q^ over interval k - 1: the interval rotation corrected for b^ - b_ref (module docstring)."""
    row, b_ref = plan.jl[k - 1], plan.b_ref
    db0, db1, db2 = b[0] - b_ref[0], b[1] - b_ref[1], b[2] - b_ref[2]
    corr = _exp(row[0] * db0 + row[1] * db1 + row[2] * db2, row[3] * db0 + row[4] * db1 + row[5] * db2,
                row[6] * db0 + row[7] * db1 + row[8] * db2)
    return _normalize(_qmul(_qmul(q_hat, plan.iq[k - 1]), corr))


def _observe(
    inp: _ObserverInputs, plan: _ObserverPlan, acquisition: bool, drift0_rad_s: ArrayLike, trend_window_s: float,
    trend_degree: int,
) -> DriftObserverResult:
    """000 eq. 8, sample by sample (a sequential algorithm): propagate, innovation, mode, correction."""
    t, on, k_n = inp.t, inp.on, inp.t.size
    q_prior, q_post = np.empty((k_n, 4)), np.empty((k_n, 4))
    drift, innov = np.empty((k_n, 3)), np.zeros((k_n, 3))
    mode = np.empty(k_n, dtype=np.int8)
    gain_a, gain_b = np.zeros(k_n), np.zeros(k_n)
    stationary = np.zeros(k_n, dtype=bool)
    b = [float(x) for x in np.asarray(drift0_rad_s, dtype=np.float64)]
    q_hat = plan.qm[0]
    n_meas, n_reacq = 1, 0
    predicting, need_reset = False, True
    trend: DriftTrend | None = None
    for k in range(k_n):
        if k > 0:
            if not inp.interval_valid[k - 1]:
                need_reset = True
            else:
                q_hat = _propagated(q_hat, b, plan, k)
        q_prior[k] = q_hat
        d = _delta(q_hat, plan.qm[k])
        innov[k] = d
        if k == 0:
            mode[k] = MODE_INIT
            q_hat = plan.qm[k]
            need_reset = False
        elif not on[k]:
            if not predicting:
                predicting = True
                sel = np.flatnonzero(stationary[:k] & (mode[:k] == MODE_CORRECTED) & (t[:k] >= t[k] - trend_window_s))
                trend = fit_drift_trend(t[sel], drift[sel], trend_degree) if sel.size else None
            if trend is not None:
                b = [float(x) for x in trend(t[k])]
            mode[k] = MODE_PREDICTED
        elif predicting or need_reset:
            mode[k] = MODE_RESUMED
            q_hat = plan.qm[k]
            predicting = need_reset = False
            n_reacq = 1
        else:
            alpha, beta, n_meas, n_reacq = _gains(plan, acquisition, n_meas, n_reacq)
            stationary[k] = alpha == plan.alpha_s and beta == plan.beta_s
            q_hat = _normalize(_qmul(q_hat, _exp(alpha * d[0], alpha * d[1], alpha * d[2])))
            f = beta / plan.t_o
            m = plan.m_rows
            b = [b[i] - f * (m[i][0] * d[0] + m[i][1] * d[1] + m[i][2] * d[2]) for i in range(3)]
            mode[k] = MODE_CORRECTED
            gain_a[k], gain_b[k] = alpha, f
        q_post[k] = q_hat
        drift[k] = b
    return DriftObserverResult(
        t_s=t, q_prior=q_prior, q_post=q_post, drift_rad_s=drift, innovation_rad=innov, mode=mode,
        gain_attitude=gain_a, gain_drift_s=gain_b, stationary=stationary, g1=plan.g1, g2=plan.g2,
    )


def _gains(plan: _ObserverPlan, acquisition: bool, n_meas: int, n_reacq: int) -> tuple[float, float, int, int]:
    """(alpha, beta, n_meas, n_reacq) of a correction: re-acquisition after a reset (the mean of the
    innovations, drift held), growing-memory gains at start-up, else the stationary gains of 000."""
    if acquisition and n_reacq and n_reacq + 1 < 1.0 / plan.alpha_s:
        return 1.0 / (n_reacq + 1), 0.0, n_meas, n_reacq + 1
    n_meas += 1
    if acquisition:
        a_n, b_n = acquisition_gains(n_meas)
        return max(a_n, plan.alpha_s), max(b_n, plan.beta_s), n_meas, 0
    return plan.alpha_s, plan.beta_s, n_meas, 0


def slew_error_bound(
    duration_s: ArrayLike,
    rotation_angle_rad: ArrayLike,
    *,
    initial_error_rad: ArrayLike,
    drift_error_rad_s: ArrayLike,
    scale_factor_error: ArrayLike,
    misalignment_error_rad: ArrayLike,
    gyro_noise_rad: ArrayLike = 0.0,
    step_period_s: float = 1.0 / 128.0,
) -> FloatArray:
    """Bound [rad] on the attitude error after propagating through a slew with the predicted drift.

    The small attitude error e (body axes) obeys e' = -w x e + dw, and w x e does not change |e|, so
    d|e|/dt <= |dw| and |e(D)| <= |e(0)| + int_0^D |dw| dt. The rate error of the calibrated gyro is
    dw = dm w + dtheta x w + db + noise (to first order), hence

        |e(D)| <= e0 + D |db| + (|dm| + |dtheta|) Theta + 3 sigma_q sqrt(D / T_q),

    with Theta = int |w| dt the slew's rotation angle, dm, dtheta, db the residual errors of the scale
    factor, misalignment (rotation vector, rad) and predicted drift (rad/s), sigma_q the increment noise
    (rad per increment, a random walk over D / T_q increments, 3 sigma). Arguments broadcast; the
    errors are magnitudes (|db| as a vector norm if given (..., 3) is the caller's choice).
    """
    d = np.asarray(duration_s, dtype=np.float64)
    theta = np.asarray(rotation_angle_rad, dtype=np.float64)
    return (np.asarray(initial_error_rad, dtype=np.float64) + d * np.asarray(drift_error_rad_s, dtype=np.float64)
            + (np.abs(np.asarray(scale_factor_error, dtype=np.float64))
               + np.asarray(misalignment_error_rad, dtype=np.float64)) * theta
            + 3.0 * np.asarray(gyro_noise_rad, dtype=np.float64) * np.sqrt(d / step_period_s))
