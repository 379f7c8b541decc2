"""The EKF of paper 004 (fig. 2) for a gyroless microsatellite: :class:`GyrolessEKF`.

State z = (w_BI^B, q_OB, tau_d,x, tau_d,y) (9), the quaternion updated additively and normalised after each
update; Phi = I + F T_s with F the exact Jacobian of the state equations, H from h_k = d(dcm_BO v)/dq_k
(:func:`dcm_v_dq`). The model, the departures from the printed formulas and the noise are described in
:mod:`processing.gyroless.ekf`, which holds the machinery shared with the MEKF (processing.gyroless.mekf).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from processing.attitude.rigid_body import dcm_BO_columns
from processing.gyroless.ekf import FilterBase, Vector, rotate_BO

__all__ = ["GyrolessEKF", "dcm_v_dq"]


def dcm_v_dq(q: tuple[float, float, float, float], v: tuple[float, float, float]) -> list[list[float]]:
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


class GyrolessEKF(FilterBase):
    """The EKF of paper 004 (fig. 2): state (w_BI^B (3), q_OB (4), tau_d,x, tau_d,y) (9).

    ``predict(dt, w0, n2, torque_B)`` propagates the state by RK4 and P with Phi = I + F dt (004);
    ``update(...)`` fuses the field and (optionally) Sun unit vectors, then normalises q.
    """

    n_core = 9
    kind = "ekf"
    _w_rows = slice(0, 3)

    def predict(self, dt: float, w0: float, n2: float, torque_B: Vector, dipole_B: Vector | None = None) -> NDArray:
        """Propagate over dt [s]; returns the transition matrix Phi (n, n) used (004: I + F T_s). dipole_B
        [A m^2]: the magnetorquer dipole behind torque_B (used with the bias states)."""
        F = self.jacobian(w0, n2)
        qa = np.array(self.q)
        torque_B, C = self._bias_torque(torque_B, dipole_B)
        self._propagate_state(dt, w0, n2, torque_B)
        # process noise: unmodelled torque on w; attitude white noise dtheta -> dq = 1/2 Xi dtheta with
        # Xi Xi^T = I - q q^T (plus a tiny radial term that keeps P invertible for the smoother); disturbance walk
        Phi = self._propagate_covariance(self._I_core + F * dt, self._q_diag(dt), dt, C)
        self.P[3:7, 3:7] -= (0.25 * self.tuning.attitude_noise_psd_rad2_s * dt) * np.outer(qa, qa)
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
        d3 = dcm_v_dq(q, (0.0, 0.0, 1.0))
        dt_ = dcm_v_dq(q, (self.tau[0], self.tau[1], 0.0))
        d2 = dcm_v_dq(q, (0.0, 1.0, 0.0))
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

    def _vector_rows(self, cols: tuple, meas: Vector, ref: Vector) -> tuple[list[list[float]], list[float]]:
        """Three rows of H (d(R(q) ref)/dq) and the residual meas - R(q) ref of one unit vector (004 eq. 4)."""
        r = (float(ref[0]), float(ref[1]), float(ref[2]))
        pred = rotate_BO(cols, r)
        z4 = [0.0, 0.0, 0.0]
        rows = [[*z4, *d, 0.0, 0.0] for d in dcm_v_dq(self.q, r)]
        return rows, [float(meas[i]) - pred[i] for i in range(3)]

    def _field_rows(self, cols: tuple, meas: Vector, ref: Vector, norm_nT: float
                    ) -> tuple[list[list[float]], list[float]]:
        """Three rows of H and the residual of the field with the model-error states: p = unit(v),
        v = dcm_BO (|B_O| ref + g_O) + beta_B, dp/dv = (I - p p^T) / |v|."""
        v_O, _, p, m = self._field_prediction(cols, ref, norm_nT)
        dq = dcm_v_dq(self.q, v_O)
        pr = [[(1.0 if i == j else 0.0) - p[i] * p[j] for j in range(3)] for i in range(3)]
        aug = self._aug_rows(cols, pr, m)
        rows = []
        for i in range(3):
            hq = [(pr[i][0] * dq[0][j] + pr[i][1] * dq[1][j] + pr[i][2] * dq[2][j]) / m for j in range(4)]
            rows.append([0.0, 0.0, 0.0, *hq, 0.0, 0.0, *aug[i]])
        return rows, [float(meas[i]) - p[i] for i in range(3)]

    def _correct(self, d: list[float]) -> None:
        q0, q1, q2, q3 = (a + b for a, b in zip(self.q, d[3:7], strict=True))
        nn = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)  # normalised after the update (004)
        self.q = (q0 / nn, q1 / nn, q2 / nn, q3 / nn)
        self.w = (self.w[0] + d[0], self.w[1] + d[1], self.w[2] + d[2])
        self.tau = (self.tau[0] + d[7], self.tau[1] + d[8])
        if self.na:
            self.aug = [a + b for a, b in zip(self.aug, d[9:], strict=True)]

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
