"""Gyroless attitude and rate estimation from magnetometer and sun sensor: the EKF of paper 004 and a
multiplicative EKF.

Both filters estimate q_OB (body B relative to the 004 orbital frame O, see processing.attitude.rigid_body),
the absolute body rate w_BI^B and the two in-plane components (tau_d,x, tau_d,y) of a constant (random
walk) disturbance torque given in O, tau_d^B = dcm_BO (tau_d,x, tau_d,y, 0) (004: "the component of
the disturbance lying in the plane O1X0Y0 dominates for a microsatellite with a gravity boom").
Dynamics: 004 eq. (1)-(3) with a known external torque per step (the magnetorquer dipole times the
measured field), propagated with RK4 (:class:`processing.attitude.rigid_body.RigidBody004`). Measurements:
unit vectors of the field and of the Sun in B against their reference directions in O (004, eq. 4);
the sun sensor may be absent at any step (eclipse, outage), the filter then runs on the magnetometer.

- :class:`GyrolessEKF` -- the filter of 004 (fig. 2): state z = (w_BI^B, q, tau_d,x, tau_d,y) (9), the
  quaternion updated additively and normalised after each update (004, after [4], [10]; the
  covariance is left as the additive update gives it, as in 004);
  Phi = I + F T_s with F the Jacobian of the state equations; H = [0 h1 h2 h3 h4 0] with
  h_k = d(dcm_BO v)/dq_k for v = B^orb, S^orb; R = sigma^2 I per vector. Departures from the printed
  formulas, all to make them exact derivatives: F includes d w_BO / dq (the term w0 c2(q) of w_BO;
  004's Omega omits it) and the third row of d tau_d / d tau (004 prints zeros), and h1..h4 are
  ordered (q0, q1, q2, q3) like the state (004's h4 is the q0 column).
- :class:`GyrolessMEKF` -- beyond the paper (its "further work"): multiplicative EKF with the 3-component
  attitude error q_OB = q_ref o exp(dtheta/2) (dtheta in B), error state (dtheta, dw, dtau) (8), each
  vector measurement used as its two components perpendicular to the predicted direction (the
  measured unit vector has no noise along itself), so NIS has exactly 2 degrees of freedom per vector.

For the paper's 3-component residual of a unit vector the radial component carries no noise, so the
EKF's NIS also has ~2 effective degrees of freedom per vector (`dof` reports 2 per vector for both).

Noise: measurements are unit vectors, so 004's R = 1e-5 I6 is a direction noise of 3.2e-3 rad -- what a
100 nT magnetometer gives on a ~30000 nT field; here R = sigma^2 per step from the sensor noise. 004's
process noise Q is truncated in our copy of the paper ("Q = diag(3e-3, 3e-3, 3e...")); the defaults of
:class:`FilterTuning` were chosen on the 004 scenario so that NIS and NEES sit at their expected values
(tests/processing/test_gyroless_estimation.py).

Per-step algebra is written on plain floats and small numpy arrays (8x8/9x9); one step (predict +
update) costs ~0.1 ms of CPU, see bench/gyroless_ekf.py.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg.lapack import dpotrf as _dpotrf
from scipy.linalg.lapack import dtrtri as _dtrtri

from processing.attitude import rotations
from processing.attitude.rigid_body import RigidBody004, dcm_BO_columns

__all__ = [
    "FilterRun",
    "FilterTuning",
    "GyrolessEKF",
    "GyrolessInputs",
    "GyrolessMEKF",
    "attitude_errors_rad",
    "covariance_sigmas",
    "run_filter",
    "triad_q_OB",
]

FilterKind = Literal["ekf", "mekf"]


@dataclass(frozen=True)
class FilterTuning:
    """Process noise of the filters (continuous-time power spectral densities).

    torque_noise_psd_N2_m2_s: unmodelled torque (white) [N^2 m^2 s], enters w' as J^-1 tau; the default
    (4e-6 N m)^2 s covers 004's unmodelled z disturbance (9.8e-7 N m on Jz = 0.76 kg m^2) and the
    control-torque error of a 100 nT magnetometer.
    disturbance_walk_psd_N2_m2_s: random walk of (tau_d,x, tau_d,y) [N^2 m^2 / s]; the default
    (1e-7 N m)^2/s lets the estimate follow 004's 3e-6-5e-6 N m disturbance at the orbital rate.
    attitude_noise_psd_rad2_s: white noise on the kinematics [rad^2/s] (numerical/model slack).
    """

    torque_noise_psd_N2_m2_s: float = (4e-6) ** 2
    disturbance_walk_psd_N2_m2_s: float = (1e-7) ** 2
    attitude_noise_psd_rad2_s: float = (1e-5) ** 2


@dataclass(frozen=True)
class GyrolessInputs:
    """Per-step inputs of the filters, K steps (times need not be uniform).

    t_s (K,): time [s] since an epoch. b_O, s_O (K, 3): unit reference field and Sun directions in O.
    b_B, s_B (K, 3): measured unit directions in B; NaN rows = no measurement at that step.
    sigma_b_rad, sigma_s_rad (K,): 1-sigma direction noise [rad] per tangent axis.
    torque_B_N_m (K, 3): known torque in B over [t_k, t_k+1) (e.g. mu x B_measured).
    w0_rad_s (K,): orbital rate (w_OI^O = (0, -w0, 0)); n2_rad2_s2 (K,): mu / r^3.
    """

    t_s: NDArray
    b_O: NDArray
    b_B: NDArray
    sigma_b_rad: NDArray
    s_O: NDArray
    s_B: NDArray
    sigma_s_rad: NDArray
    torque_B_N_m: NDArray
    w0_rad_s: NDArray
    n2_rad2_s2: NDArray

    def __post_init__(self) -> None:
        k = np.shape(self.t_s)[0]
        for name in ("b_O", "b_B", "s_O", "s_B", "torque_B_N_m"):
            if np.shape(getattr(self, name)) != (k, 3):
                raise ValueError(f"{name} must have shape ({k}, 3), got {np.shape(getattr(self, name))}")
        for name in ("sigma_b_rad", "sigma_s_rad", "w0_rad_s", "n2_rad2_s2"):
            if np.shape(getattr(self, name)) != (k,):
                raise ValueError(f"{name} must have shape ({k},), got {np.shape(getattr(self, name))}")
        if k and np.any(np.diff(self.t_s) <= 0):
            raise ValueError("t_s must increase strictly")

    @property
    def n_steps(self) -> int:
        return int(np.shape(self.t_s)[0])


def _dcm_v_dq(q: tuple[float, float, float, float], v: tuple[float, float, float]) -> list[list[float]]:
    """d(dcm_BO(q) v)/dq as 3 rows of 4 floats, for dcm_BO(q) v = (q0^2 - u.u) v + 2 (u.v) u - 2 q0 u x v.

    Column 0: 2 q0 v - 2 u x v; columns 1-3: -2 v u^T + 2 (u.v) I + 2 u v^T + 2 q0 [v x]
    (004's h1..h4, reordered to (q0, q1, q2, q3)).
    """
    q0, q1, q2, q3 = q
    vx, vy, vz = v
    uv2 = 2.0 * (q1 * vx + q2 * vy + q3 * vz)
    a0, a1, a2, a3 = 2.0 * q0, 2.0 * q1, 2.0 * q2, 2.0 * q3
    return [
        [a0 * vx - (a2 * vz - a3 * vy), uv2, -vx * a2 + a1 * vy - a0 * vz, -vx * a3 + a1 * vz + a0 * vy],
        [a0 * vy - (a3 * vx - a1 * vz), -vy * a1 + a2 * vx + a0 * vz, uv2, -vy * a3 + a2 * vz - a0 * vx],
        [a0 * vz - (a1 * vy - a2 * vx), -vz * a1 + a3 * vx - a0 * vy, -vz * a2 + a3 * vy + a0 * vx, uv2],
    ]


def _xi(q: tuple[float, float, float, float]) -> list[list[float]]:
    """Xi(q) (4 x 3): q o (0, v) = Xi(q) v; Xi^T Xi = I3, Xi Xi^T = I4 - q q^T for a unit q."""
    q0, q1, q2, q3 = q
    return [[-q1, -q2, -q3], [q0, -q3, q2], [q3, q0, -q1], [-q2, q1, q0]]


def _rotate_BO(cols: tuple, v: ArrayLike) -> tuple[float, float, float]:
    c1, c2, c3 = cols
    x, y, z = float(v[0]), float(v[1]), float(v[2])  # type: ignore[index]
    return (x * c1[0] + y * c2[0] + z * c3[0], x * c1[1] + y * c2[1] + z * c3[1], x * c1[2] + y * c2[2] + z * c3[2])


def _tangent_basis(b: tuple[float, float, float]) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Two unit vectors e1, e2 perpendicular to the unit vector b, with e2 = b x e1."""
    bx, by, bz = b
    if abs(bx) < 0.9:  # e1 = normalise(x_hat x b)
        e1 = (0.0, -bz, by)
    else:  # e1 = normalise(y_hat x b)
        e1 = (bz, 0.0, -bx)
    n = math.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
    e1 = (e1[0] / n, e1[1] / n, e1[2] / n)
    e2 = (by * e1[2] - bz * e1[1], bz * e1[0] - bx * e1[2], bx * e1[1] - by * e1[0])
    return e1, e2


@dataclass
class _UpdateStats:
    nis: float = math.nan
    dof: int = 0
    whitened: list[float] = field(default_factory=list)
    used_sun: bool = False
    used_mag: bool = False
    residual_rad: list[float] = field(default_factory=lambda: [math.nan, math.nan])


class _FilterBase:
    """Shared state and bookkeeping. Subclasses define the covariance layout."""

    n: ClassVar[int]
    kind: ClassVar[str]

    def __init__(
        self,
        J: ArrayLike,
        q_OB: ArrayLike,
        omega_BI_B: ArrayLike,
        P0: NDArray,
        tuning: FilterTuning = FilterTuning(),
        tau_d_O: ArrayLike = (0.0, 0.0),
    ) -> None:
        self.body = RigidBody004.from_inertia(J)
        q = np.asarray(q_OB, dtype=float)
        q = q / np.linalg.norm(q)
        self.q: tuple[float, float, float, float] = (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
        w = np.asarray(omega_BI_B, dtype=float)
        self.w: tuple[float, float, float] = (float(w[0]), float(w[1]), float(w[2]))
        t = np.asarray(tau_d_O, dtype=float)
        self.tau: tuple[float, float] = (float(t[0]), float(t[1]))
        P = np.array(P0, dtype=float)
        if P.shape != (self.n, self.n):
            raise ValueError(f"P0 must be ({self.n}, {self.n}) for the {self.kind} filter, got {P.shape}")
        self.P = P
        self.tuning = tuning
        b = self.body
        self._jinv = (1.0 / b.Jx, 1.0 / b.Jy, 1.0 / b.Jz)
        self._I = np.eye(self.n)
        self._I4 = np.eye(4)
        self._diag = np.arange(self.n) * (self.n + 1)
        self._q_cache: dict[float, NDArray] = {}

    # -- state as a 9-vector (w, q, tau) for storage and smoothing ---------------------------------
    def state(self) -> NDArray:
        return np.array(self.w + self.q + self.tau)

    def set_state(self, x: ArrayLike) -> None:
        x = np.asarray(x, dtype=float)
        q = x[3:7] / np.linalg.norm(x[3:7])
        self.w = (float(x[0]), float(x[1]), float(x[2]))
        self.q = (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
        self.tau = (float(x[7]), float(x[8]))

    def _propagate_state(self, dt: float, w0: float, n2: float, torque_B: ArrayLike) -> None:
        tb = (float(torque_B[0]), float(torque_B[1]), float(torque_B[2]))  # type: ignore[index]
        self.q, self.w = self.body.rk4_step(self.q, self.w, dt, w0, n2, tau_B=tb, tau_O=(self.tau[0], self.tau[1], 0.0))

    def _rate_rows(self, n2: float, cols: tuple) -> tuple[list[list[float]], list[list[float]], list[list[float]]]:
        """Blocks of dw'/d(.) that both filters share, as float rows (scaled by J^-1):
        F_ww = J^-1 ([J w x] - [w x] J), G = J^-1 d tau_g / d c3 = J^-1 3 n^2 ([c3 x] J - [(J c3) x]),
        F_wtau = J^-1 [c1 c2] (d tau_d^B / d(tau_d,x, tau_d,y))."""
        b = self.body
        jx, jy, jz = b.Jx, b.Jy, b.Jz
        ix, iy, iz = self._jinv
        wx, wy, wz = self.w
        c1, c2, c3 = cols
        f_ww = [[0.0, ix * (jy - jz) * wz, ix * (jy - jz) * wy],
                [iy * (jz - jx) * wz, 0.0, iy * (jz - jx) * wx],
                [iz * (jx - jy) * wy, iz * (jx - jy) * wx, 0.0]]
        k = 3.0 * n2
        g = [[0.0, ix * k * (jz - jy) * c3[2], ix * k * (jz - jy) * c3[1]],
             [iy * k * (jx - jz) * c3[2], 0.0, iy * k * (jx - jz) * c3[0]],
             [iz * k * (jy - jx) * c3[1], iz * k * (jy - jx) * c3[0], 0.0]]
        f_wt = [[ix * c1[0], ix * c2[0]], [iy * c1[1], iy * c2[1]], [iz * c1[2], iz * c2[2]]]
        return f_ww, g, f_wt

    def _gain(self, H: NDArray, y: NDArray, var: list[float], stats: _UpdateStats) -> tuple[NDArray, NDArray]:
        """Correction K y and the covariance after the update, P - P H^T S^-1 H P, with NIS and the
        whitened innovations L^-1 y (S = L L^T) filled into stats."""
        PHt = self.P @ H.T
        S = H @ PHt
        m = len(var)
        S.flat[:: m + 1] += var
        L, info = _dpotrf(S, lower=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"innovation covariance not positive definite (LAPACK info {info})")
        L_inv = _dtrtri(L, lower=1)[0]
        w = L_inv @ y
        M = L_inv @ PHt.T  # K = M^T L_inv, P+ = P - M^T M
        stats.nis = float(w @ w)
        stats.whitened = w.tolist()
        return M.T @ w, self.P - M.T @ M

    def update(
        self,
        b_B: ArrayLike | None,
        b_O: ArrayLike,
        sigma_b: float,
        s_B: ArrayLike | None = None,
        s_O: ArrayLike | None = None,
        sigma_s: float = math.nan,
    ) -> _UpdateStats:
        """Fuse unit vectors b (field) and s (Sun); either may be None (skipped). 004 eq. (4).

        Each filter gives the rows of H and the residuals of one vector (``_vector_rows``) and applies
        the correction to its state (``_correct``)."""
        stats = _UpdateStats()
        rows: list[list[float]] = []
        res: list[float] = []
        var: list[float] = []
        cols = dcm_BO_columns(self.q)
        for meas, ref, sig, tag in ((b_B, b_O, sigma_b, "mag"), (s_B, s_O, sigma_s, "sun")):
            if meas is None or ref is None:
                continue
            h, r = self._vector_rows(cols, meas, ref)
            rows.extend(h)
            res.extend(r)
            stats.residual_rad[tag == "sun"] = math.sqrt(sum(x * x for x in r))
            var.extend([sig * sig] * len(r))
            stats.dof += 2
            setattr(stats, "used_sun" if tag == "sun" else "used_mag", True)
        if not rows:
            return stats
        dx, P = self._gain(np.array(rows), np.array(res), var, stats)
        self.P = P
        self._correct(dx.tolist())
        return stats

    def _vector_rows(self, cols: tuple, meas: ArrayLike, ref: ArrayLike) -> tuple[list[list[float]], list[float]]:
        raise NotImplementedError  # pragma: no cover - overridden

    def _correct(self, d: list[float]) -> None:
        raise NotImplementedError  # pragma: no cover - overridden

    def attitude_cov(self) -> NDArray:  # pragma: no cover - overridden
        raise NotImplementedError

    def omega_BO_B(self, w0: float) -> tuple[float, float, float]:
        c2 = dcm_BO_columns(self.q)[1]
        return (self.w[0] + w0 * c2[0], self.w[1] + w0 * c2[1], self.w[2] + w0 * c2[2])


class GyrolessEKF(_FilterBase):
    """The EKF of paper 004 (fig. 2): state (w_BI^B (3), q_OB (4), tau_d,x, tau_d,y) (9).

    ``predict(dt, w0, n2, torque_B)`` propagates the state by RK4 and P with Phi = I + F dt (004);
    ``update(...)`` fuses the field and (optionally) Sun unit vectors, then normalises q.
    """

    n = 9
    kind = "ekf"

    def predict(self, dt: float, w0: float, n2: float, torque_B: ArrayLike) -> NDArray:
        """Propagate over dt [s]; returns the transition matrix Phi (9, 9) used (004: I + F T_s)."""
        F = self.jacobian(w0, n2)
        qa = np.array(self.q)
        self._propagate_state(dt, w0, n2, torque_B)
        Phi = self._I + F * dt
        P = Phi @ self.P @ Phi.T
        # process noise: unmodelled torque on w; attitude white noise dtheta -> dq = 1/2 Xi dtheta with
        # Xi Xi^T = I - q q^T (plus a tiny radial term that keeps P invertible for the smoother); disturbance walk
        P.flat[self._diag] += self._q_diag(dt)
        P[3:7, 3:7] -= (0.25 * self.tuning.attitude_noise_psd_rad2_s * dt) * np.outer(qa, qa)
        self.P = P
        return Phi

    def _q_diag(self, dt: float) -> NDArray:
        q = self._q_cache.get(dt)
        if q is None:
            t = self.tuning
            q = np.array([*(ji * ji * t.torque_noise_psd_N2_m2_s * dt for ji in self._jinv),
                          *([0.25 * t.attitude_noise_psd_rad2_s * dt + 1e-14] * 4),
                          *([t.disturbance_walk_psd_N2_m2_s * dt] * 2)])
            self._q_cache[dt] = q
        return q

    def jacobian(self, w0: float, n2: float) -> NDArray:
        """F = d f / d z (9, 9) at the current estimate (004, the matrix after fig. 2)."""
        q = self.q
        cols = dcm_BO_columns(q)
        f_ww, g, f_wt = self._rate_rows(n2, cols)
        d3 = _dcm_v_dq(q, (0.0, 0.0, 1.0))
        dt_ = _dcm_v_dq(q, (self.tau[0], self.tau[1], 0.0))
        d2 = _dcm_v_dq(q, (0.0, 1.0, 0.0))
        ji = self._jinv
        xi = _xi(q)
        px, py, pz = self.omega_BO_B(w0)
        om = [[0.0, -px, -py, -pz], [px, 0.0, pz, -py], [py, -pz, 0.0, px], [pz, py, -px, 0.0]]
        rows = []
        for i in range(3):
            gi = g[i]
            f_wq = [gi[0] * d3[0][j] + gi[1] * d3[1][j] + gi[2] * d3[2][j] + ji[i] * dt_[i][j] for j in range(4)]
            rows.append([*f_ww[i], *f_wq, *f_wt[i]])
        for i in range(4):
            x = xi[i]
            f_qq = [0.5 * om[i][j] + 0.5 * w0 * (x[0] * d2[0][j] + x[1] * d2[1][j] + x[2] * d2[2][j])
                    for j in range(4)]
            rows.append([0.5 * x[0], 0.5 * x[1], 0.5 * x[2], *f_qq, 0.0, 0.0])
        rows.append([0.0] * 9)
        rows.append([0.0] * 9)
        return np.array(rows)

    def _vector_rows(self, cols: tuple, meas: ArrayLike, ref: ArrayLike) -> tuple[list[list[float]], list[float]]:
        """Three rows of H (d(R(q) ref)/dq) and the residual meas - R(q) ref of one unit vector (004 eq. 4)."""
        r = (float(ref[0]), float(ref[1]), float(ref[2]))  # type: ignore[index]
        pred = _rotate_BO(cols, r)
        z4 = [0.0, 0.0, 0.0]
        rows = [[*z4, *d, 0.0, 0.0] for d in _dcm_v_dq(self.q, r)]
        return rows, [float(meas[i]) - pred[i] for i in range(3)]  # type: ignore[index]

    def _correct(self, d: list[float]) -> None:
        q0, q1, q2, q3 = (a + b for a, b in zip(self.q, d[3:7], strict=True))
        nn = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)  # normalised after the update (004)
        self.q = (q0 / nn, q1 / nn, q2 / nn, q3 / nn)
        self.w = (self.w[0] + d[0], self.w[1] + d[1], self.w[2] + d[2])
        self.tau = (self.tau[0] + d[7], self.tau[1] + d[8])

    def attitude_cov(self) -> NDArray:
        """Covariance (3, 3) [rad^2] of the attitude error dtheta (in B): 4 Xi^T P_qq Xi."""
        xi = np.array(_xi(self.q))
        return 4.0 * xi.T @ self.P[3:7, 3:7] @ xi

    def rate_cov(self) -> NDArray:
        return self.P[0:3, 0:3]

    @staticmethod
    def error_between(xa: NDArray, xb: NDArray) -> NDArray:
        """xa - xb in the filter's coordinates (9): additive, quaternion sign aligned to xb."""
        d = xa - xb
        if float(xa[3:7] @ xb[3:7]) < 0.0:
            d[3:7] = -xa[3:7] - xb[3:7]
        return d

    @staticmethod
    def apply_error(x: NDArray, dx: NDArray) -> NDArray:
        y = x + dx
        y[3:7] /= math.sqrt(float(y[3:7] @ y[3:7]))
        return y


class GyrolessMEKF(_FilterBase):
    """Multiplicative EKF: error state (dtheta (3, in B), dw_BI (3), dtau_d,x, dtau_d,y) (8).

    q_OB = q_ref o exp(dtheta / 2). ``predict`` uses Phi = I + F dt + (F dt)^2 / 2; ``update`` uses two
    tangent components per unit vector (R = sigma^2 I2).
    """

    n = 8
    kind = "mekf"

    def jacobian(self, w0: float, n2: float) -> NDArray:
        """Error-state Jacobian F (8, 8) at the current estimate:
        dtheta' = -[w x] dtheta + dw; dw' = J^-1 (d tau_g/d c3 [c3 x] + [tau_d^B x]) dtheta + F_ww dw + F_wtau dtau."""
        cols = dcm_BO_columns(self.q)
        f_ww, g, f_wt = self._rate_rows(n2, cols)
        c3 = cols[2]
        tx, ty, tz = _rotate_BO(cols, (self.tau[0], self.tau[1], 0.0))
        ji = self._jinv
        # G [c3 x] + J^-1 [tau_d^B x]
        sk = [[0.0, -c3[2], c3[1]], [c3[2], 0.0, -c3[0]], [-c3[1], c3[0], 0.0]]
        st = [[0.0, -tz, ty], [tz, 0.0, -tx], [-ty, tx, 0.0]]
        wx, wy, wz = self.w
        rows = [
            [0.0, wz, -wy, 1.0, 0.0, 0.0, 0.0, 0.0],
            [-wz, 0.0, wx, 0.0, 1.0, 0.0, 0.0, 0.0],
            [wy, -wx, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        ]
        for i in range(3):
            gi = g[i]
            f_wt_i = [gi[0] * sk[0][j] + gi[1] * sk[1][j] + gi[2] * sk[2][j] + ji[i] * st[i][j] for j in range(3)]
            rows.append([*f_wt_i, *f_ww[i], *f_wt[i]])
        rows.append([0.0] * 8)
        rows.append([0.0] * 8)
        return np.array(rows)

    def predict(self, dt: float, w0: float, n2: float, torque_B: ArrayLike) -> NDArray:
        """Propagate over dt [s]; returns Phi (8, 8)."""
        F = self.jacobian(w0, n2) * dt
        self._propagate_state(dt, w0, n2, torque_B)
        Phi = self._I + F + 0.5 * (F @ F)
        P = Phi @ self.P @ Phi.T
        P.flat[self._diag] += self._q_diag(dt)
        self.P = P
        return Phi

    def _q_diag(self, dt: float) -> NDArray:
        """Diagonal of the discrete process noise for a step dt (cached per dt)."""
        q = self._q_cache.get(dt)
        if q is None:
            t = self.tuning
            q = np.array([*([t.attitude_noise_psd_rad2_s * dt] * 3),
                          *(ji * ji * t.torque_noise_psd_N2_m2_s * dt for ji in self._jinv),
                          *([t.disturbance_walk_psd_N2_m2_s * dt] * 2)])
            self._q_cache[dt] = q
        return q

    def _vector_rows(self, cols: tuple, meas: ArrayLike, ref: ArrayLike) -> tuple[list[list[float]], list[float]]:
        """Two rows of H and the residual of one unit vector in the tangent plane of its prediction."""
        pred = _rotate_BO(cols, ref)
        e1, e2 = _tangent_basis(pred)
        mx, my, mz = float(meas[0]), float(meas[1]), float(meas[2])  # type: ignore[index]
        rows = [[-e2[0], -e2[1], -e2[2], 0.0, 0.0, 0.0, 0.0, 0.0], [e1[0], e1[1], e1[2], 0.0, 0.0, 0.0, 0.0, 0.0]]
        return rows, [e1[0] * mx + e1[1] * my + e1[2] * mz, e2[0] * mx + e2[1] * my + e2[2] * mz]

    def _correct(self, d: list[float]) -> None:
        hx, hy, hz = 0.5 * d[0], 0.5 * d[1], 0.5 * d[2]
        ang = math.sqrt(hx * hx + hy * hy + hz * hz)
        k = math.sin(ang) / ang if ang > 1e-12 else 1.0
        e0, e1, e2, e3 = math.cos(ang), k * hx, k * hy, k * hz
        q0, q1, q2, q3 = self.q
        n0 = q0 * e0 - q1 * e1 - q2 * e2 - q3 * e3
        n1 = q0 * e1 + q1 * e0 + q2 * e3 - q3 * e2
        n2 = q0 * e2 + q2 * e0 + q3 * e1 - q1 * e3
        n3 = q0 * e3 + q3 * e0 + q1 * e2 - q2 * e1
        nn = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2 + n3 * n3)
        self.q = (n0 / nn, n1 / nn, n2 / nn, n3 / nn)
        self.w = (self.w[0] + d[3], self.w[1] + d[4], self.w[2] + d[5])
        self.tau = (self.tau[0] + d[6], self.tau[1] + d[7])

    def attitude_cov(self) -> NDArray:
        return self.P[0:3, 0:3]

    def rate_cov(self) -> NDArray:
        return self.P[3:6, 3:6]

    @staticmethod
    def error_between(xa: NDArray, xb: NDArray) -> NDArray:
        """Error (8) taking xb to xa: (rotation vector of q_b^-1 o q_a, w_a - w_b, tau_a - tau_b)."""
        w_a0, w_a1, w_a2, a0, a1, a2, a3, t_a0, t_a1 = xa.tolist()
        w_b0, w_b1, w_b2, b0, b1, b2, b3, t_b0, t_b1 = xb.tolist()
        # q_b^-1 o q_a
        d0 = b0 * a0 + b1 * a1 + b2 * a2 + b3 * a3
        d1 = b0 * a1 - b1 * a0 - (b2 * a3 - b3 * a2)
        d2 = b0 * a2 - b2 * a0 - (b3 * a1 - b1 * a3)
        d3 = b0 * a3 - b3 * a0 - (b1 * a2 - b2 * a1)
        if d0 < 0.0:
            d0, d1, d2, d3 = -d0, -d1, -d2, -d3
        sn = math.sqrt(d1 * d1 + d2 * d2 + d3 * d3)
        s = 2.0 * math.atan2(sn, d0) / sn if sn > 1e-12 else 2.0 / d0  # rotation vector (inverse of exp)
        return np.array([s * d1, s * d2, s * d3, w_a0 - w_b0, w_a1 - w_b1, w_a2 - w_b2, t_a0 - t_b0, t_a1 - t_b1])

    @staticmethod
    def apply_error(x: NDArray, dx: NDArray) -> NDArray:
        """x with the error dx applied: q o exp(dtheta/2) (exact), w + dw, tau + dtau."""
        d = dx.tolist()
        w0_, w1_, w2_, q0, q1, q2, q3, t0, t1 = x.tolist()
        hx, hy, hz = 0.5 * d[0], 0.5 * d[1], 0.5 * d[2]
        ang = math.sqrt(hx * hx + hy * hy + hz * hz)
        c = math.cos(ang)
        k = math.sin(ang) / ang if ang > 1e-12 else 1.0
        e0, e1, e2, e3 = c, k * hx, k * hy, k * hz
        n0 = q0 * e0 - q1 * e1 - q2 * e2 - q3 * e3
        n1 = q0 * e1 + q1 * e0 + q2 * e3 - q3 * e2
        n2 = q0 * e2 + q2 * e0 + q3 * e1 - q1 * e3
        n3 = q0 * e3 + q3 * e0 + q1 * e2 - q2 * e1
        nn = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2 + n3 * n3)
        return np.array([w0_ + d[3], w1_ + d[4], w2_ + d[5], n0 / nn, n1 / nn, n2 / nn, n3 / nn, t0 + d[6], t1 + d[7]])


FILTERS: dict[str, type[GyrolessEKF] | type[GyrolessMEKF]] = {"ekf": GyrolessEKF, "mekf": GyrolessMEKF}


@dataclass(frozen=True)
class FilterRun:
    """History of a filter pass over K steps.

    kind: "ekf" | "mekf". x_filt (K, 9): (w_BI^B, q_OB, tau_d,x, tau_d,y) after each update;
    P_filt (K, n, n); x_pred (K, 9), P_pred (K, n, n): predicted for step k from k-1 (k = 0: the
    initial values); Phi (K, n, n): Phi[k] maps errors at k-1 to k (Phi[0] = I).
    attitude_sigma_rad, rate_sigma_rad_s (K, 3): 1-sigma from P_filt (attitude about the B axes).
    nis (K,), nis_dof (K,) (NaN and 0 where no measurement was used), whitened (K, 6): whitened
    innovation components (NaN padded), used_mag, used_sun (K,) bool; residual_rad (K, 2): angle between
    the measured and the predicted (prior) field and Sun directions (NaN where not measured).
    """

    kind: str
    t_s: NDArray
    x_filt: NDArray
    P_filt: NDArray
    x_pred: NDArray
    P_pred: NDArray
    Phi: NDArray
    attitude_sigma_rad: NDArray
    rate_sigma_rad_s: NDArray
    nis: NDArray
    nis_dof: NDArray
    whitened: NDArray
    used_mag: NDArray
    used_sun: NDArray
    residual_rad: NDArray

    @property
    def q_OB(self) -> NDArray:
        return self.x_filt[:, 3:7]

    @property
    def omega_BI_B(self) -> NDArray:
        return self.x_filt[:, 0:3]

    @property
    def tau_d_O(self) -> NDArray:
        return self.x_filt[:, 7:9]


def initial_covariance(kind: FilterKind, q_OB: ArrayLike, attitude_sigma_rad: float, rate_sigma_rad_s: float,
                       disturbance_sigma_N_m: float) -> NDArray:
    """Diagonal initial covariance for a filter kind (attitude error isotropic in B)."""
    if kind == "mekf":
        return np.diag([attitude_sigma_rad**2] * 3 + [rate_sigma_rad_s**2] * 3 + [disturbance_sigma_N_m**2] * 2)
    q0, q1, q2, q3 = (float(v) for v in np.asarray(q_OB, dtype=float) / np.linalg.norm(q_OB))
    xi = np.array([[-q1, -q2, -q3], [q0, -q3, q2], [q3, q0, -q1], [-q2, q1, q0]])
    P = np.zeros((9, 9))
    P[0:3, 0:3] = np.eye(3) * rate_sigma_rad_s**2
    P[3:7, 3:7] = 0.25 * attitude_sigma_rad**2 * (xi @ xi.T) + 1e-12 * np.eye(4)
    P[7:9, 7:9] = np.eye(2) * disturbance_sigma_N_m**2
    return P


def run_filter(
    kind: FilterKind,
    inputs: GyrolessInputs,
    J: ArrayLike,
    q0_OB: ArrayLike,
    omega0_BI_B: ArrayLike,
    *,
    attitude_sigma_rad: float = math.radians(10.0),
    rate_sigma_rad_s: float = 1e-3,
    disturbance_sigma_N_m: float = 1e-5,
    tuning: FilterTuning = FilterTuning(),
) -> FilterRun:
    """Run the EKF of 004 ("ekf") or the multiplicative EKF ("mekf") over all steps of ``inputs``.

    q0_OB (4,), omega0_BI_B (3,): initial estimate at inputs.t_s[0], with the given 1-sigma
    uncertainties (attitude isotropic, rad; rate, rad/s; disturbance, N m). Returns :class:`FilterRun`.
    """
    if kind not in FILTERS:
        raise ValueError(f"kind must be one of {sorted(FILTERS)}, got {kind!r}")
    cls = FILTERS[kind]
    P0 = initial_covariance(kind, q0_OB, attitude_sigma_rad, rate_sigma_rad_s, disturbance_sigma_N_m)
    f = cls(J, q0_OB, omega0_BI_B, P0, tuning)
    K, n = inputs.n_steps, cls.n
    x_filt, x_pred = np.empty((K, 9)), np.empty((K, 9))
    P_filt, P_pred, Phi_all = np.empty((K, n, n)), np.empty((K, n, n)), np.empty((K, n, n))
    nis, dof = np.full(K, np.nan), np.zeros(K, dtype=np.int64)
    whitened = np.full((K, 6), np.nan)
    used_mag, used_sun = np.zeros(K, bool), np.zeros(K, bool)
    residual = np.full((K, 2), np.nan)
    t = np.asarray(inputs.t_s, dtype=float)
    b_ok = np.all(np.isfinite(inputs.b_B), axis=1)
    s_ok = np.all(np.isfinite(inputs.s_B), axis=1)
    b_B, b_O, s_B, s_O = inputs.b_B, inputs.b_O, inputs.s_B, inputs.s_O
    sb, ss = inputs.sigma_b_rad, inputs.sigma_s_rad
    w0s, n2s, torque = inputs.w0_rad_s, inputs.n2_rad2_s2, inputs.torque_B_N_m
    eye = np.eye(n)
    for k in range(K):
        if k == 0:
            Phi_all[0] = eye
        else:
            Phi_all[k] = f.predict(float(t[k] - t[k - 1]), float(w0s[k - 1]), float(n2s[k - 1]), torque[k - 1])
        x_pred[k] = f.state()
        P_pred[k] = f.P
        st = f.update(b_B[k] if b_ok[k] else None, b_O[k], float(sb[k]),
                      s_B[k] if s_ok[k] else None, s_O[k], float(ss[k]))
        if st.dof:
            nis[k], dof[k] = st.nis, st.dof
            whitened[k, : len(st.whitened)] = st.whitened
        used_mag[k], used_sun[k] = st.used_mag, st.used_sun
        residual[k] = st.residual_rad
        x_filt[k] = f.state()
        P_filt[k] = f.P
    att_sig, rate_sig = covariance_sigmas(kind, x_filt, P_filt)
    return FilterRun(kind=kind, t_s=t, x_filt=x_filt, P_filt=P_filt, x_pred=x_pred, P_pred=P_pred, Phi=Phi_all,
                     attitude_sigma_rad=att_sig, rate_sigma_rad_s=rate_sig, nis=nis, nis_dof=dof.astype(float),
                     whitened=whitened, used_mag=used_mag, used_sun=used_sun, residual_rad=residual)


def covariance_sigmas(kind: str, x: NDArray, P: NDArray) -> tuple[NDArray, NDArray]:
    """1-sigma attitude error about the B axes [rad] and rate [rad/s] (K, 3) from states x (K, 9) and
    covariances P (K, n, n) of a filter kind (EKF: dtheta = 2 Xi(q)^T dq)."""
    if kind == "mekf":
        return np.sqrt(np.einsum("kii->ki", P[:, 0:3, 0:3])), np.sqrt(np.einsum("kii->ki", P[:, 3:6, 3:6]))
    q0, q1, q2, q3 = (x[:, i] for i in range(3, 7))
    xi = np.stack([np.stack([-q1, -q2, -q3], -1), np.stack([q0, -q3, q2], -1),
                   np.stack([q3, q0, -q1], -1), np.stack([-q2, q1, q0], -1)], axis=-2)  # (K, 4, 3)
    att = 4.0 * np.einsum("kai,kab,kbi->ki", xi, P[:, 3:7, 3:7], xi)
    return np.sqrt(np.maximum(att, 0.0)), np.sqrt(np.einsum("kii->ki", P[:, 0:3, 0:3]))


def triad_q_OB(b_O: ArrayLike, s_O: ArrayLike, b_B: ArrayLike, s_B: ArrayLike) -> NDArray:
    """Coarse q_OB (4,) from two vector pairs (TRIAD, b primary): dcm_BO b_O = b_B exactly, s_O -> s_B
    in the plane of b. Vectors (3,) in O and B; used to initialise the filters."""
    def frame(a: ArrayLike, c: ArrayLike) -> NDArray:
        a, c = np.asarray(a, dtype=float), np.asarray(c, dtype=float)
        t1 = a / np.linalg.norm(a)
        t2 = np.cross(a, c)
        t2 /= np.linalg.norm(t2)
        return np.stack([t1, t2, np.cross(t1, t2)], axis=-1)

    dcm_OB = frame(b_O, s_O) @ frame(b_B, s_B).T
    return rotations.dcm_to_quat(dcm_OB)


def attitude_errors_rad(q_OB_est: ArrayLike, q_OB_true: ArrayLike) -> NDArray:
    """Attitude error rotation vector dtheta (..., 3) [rad] in B: q_true = q_est o exp(dtheta/2).

    The convention of the filters' attitude covariance (NEES uses it directly).
    """
    dq = rotations.quat_multiply(rotations.quat_conjugate(q_OB_est), q_OB_true)
    return rotations.quat_to_rotvec(dq)
