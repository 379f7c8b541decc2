"""The multiplicative EKF of the gyroless estimation (beyond paper 004, its "further work").

Same state and dynamics as the EKF of 004 (processing.gyroless.ekf), but the attitude is carried as
q_OB = q_ref o exp(dtheta/2) with the 3-component error dtheta in B; error state (dtheta, dw, dtau) (8);
each vector measurement is used as its two components perpendicular to the predicted direction (the
measured unit vector has no noise along itself), so NIS has exactly 2 degrees of freedom per vector.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from processing.attitude.rigid_body import dcm_BO_columns
from processing.gyroless.ekf import FilterBase, Vector, rotate_BO, tangent_basis

__all__ = ["GyrolessMEKF"]


class GyrolessMEKF(FilterBase):
    """Multiplicative EKF: error state (dtheta (3, in B), dw_BI (3), dtau_d,x, dtau_d,y) (8).

    q_OB = q_ref o exp(dtheta / 2). ``predict`` uses Phi = I + F dt + (F dt)^2 / 2; ``update`` uses two
    tangent components per unit vector (R = sigma^2 I2).
    """

    n_core = 8
    kind = "mekf"
    _w_rows = slice(3, 6)

    def jacobian(self, w0: float, n2: float) -> NDArray:
        """Error-state Jacobian F (8, 8) at the current estimate:
        dtheta' = -[w x] dtheta + dw; dw' = J^-1 (d tau_g/d c3 [c3 x] + [tau_d^B x]) dtheta + F_ww dw + F_wtau dtau."""
        cols = dcm_BO_columns(self.q)
        f_ww, g, f_wt = self._rate_rows(n2, cols)
        c3 = cols[2]
        tx, ty, tz = rotate_BO(cols, (self.tau[0], self.tau[1], 0.0))
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

    def predict(self, dt: float, w0: float, n2: float, torque_B: Vector, dipole_B: Vector | None = None) -> NDArray:
        """Propagate over dt [s]; returns Phi (n, n). dipole_B [A m^2]: the magnetorquer dipole behind
        torque_B (used with the bias states)."""
        F = self.jacobian(w0, n2) * dt
        torque_B, C = self._bias_torque(torque_B, dipole_B)
        self._propagate_state(dt, w0, n2, torque_B)
        return self._propagate_covariance(self._I_core + F + 0.5 * (F @ F), self._q_diag(dt), dt, C)

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

    def _vector_rows(self, cols: tuple, meas: Vector, ref: Vector) -> tuple[list[list[float]], list[float]]:
        """Two rows of H and the residual of one unit vector in the tangent plane of its prediction."""
        pred = rotate_BO(cols, ref)
        e1, e2 = tangent_basis(pred)
        mx, my, mz = float(meas[0]), float(meas[1]), float(meas[2])
        rows = [[-e2[0], -e2[1], -e2[2], 0.0, 0.0, 0.0, 0.0, 0.0], [e1[0], e1[1], e1[2], 0.0, 0.0, 0.0, 0.0, 0.0]]
        return rows, [e1[0] * mx + e1[1] * my + e1[2] * mz, e2[0] * mx + e2[1] * my + e2[2] * mz]

    def _field_rows(self, cols: tuple, meas: Vector, ref: Vector, norm_nT: float
                    ) -> tuple[list[list[float]], list[float]]:
        """Two tangent rows of H and residuals of the field with the model-error states: p = unit(u + beta_B),
        u = dcm_BO (|B_O| ref + g_O); e.dp/d dtheta = (e x u) / |v| (u -> u + u x dtheta)."""
        _, u, p, m = self._field_prediction(cols, ref, norm_nT)
        e1, e2 = tangent_basis(p)
        aug = self._aug_rows(cols, (e1, e2), m)
        rows = []
        for e, a in zip((e1, e2), aug, strict=True):
            rows.append([(e[1] * u[2] - e[2] * u[1]) / m, (e[2] * u[0] - e[0] * u[2]) / m,
                         (e[0] * u[1] - e[1] * u[0]) / m, 0.0, 0.0, 0.0, 0.0, 0.0, *a])
        mx, my, mz = float(meas[0]), float(meas[1]), float(meas[2])
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
        if self.na:
            self.aug = [a + b for a, b in zip(self.aug, d[8:], strict=True)]

    def attitude_cov(self) -> NDArray:
        return self.P[0:3, 0:3]

    def rate_cov(self) -> NDArray:
        return self.P[3:6, 3:6]

    @staticmethod
    def error_between(xa: NDArray, xb: NDArray) -> NDArray:
        """Error (8 + model errors) taking xb to xa: (rotation vector of q_b^-1 o q_a, w_a - w_b, tau_a - tau_b,
        then the model-error states' differences)."""
        w_a0, w_a1, w_a2, a0, a1, a2, a3, t_a0, t_a1 = xa[:9].tolist()
        w_b0, w_b1, w_b2, b0, b1, b2, b3, t_b0, t_b1 = xb[:9].tolist()
        # q_b^-1 o q_a
        d0 = b0 * a0 + b1 * a1 + b2 * a2 + b3 * a3
        d1 = b0 * a1 - b1 * a0 - (b2 * a3 - b3 * a2)
        d2 = b0 * a2 - b2 * a0 - (b3 * a1 - b1 * a3)
        d3 = b0 * a3 - b3 * a0 - (b1 * a2 - b2 * a1)
        if d0 < 0.0:
            d0, d1, d2, d3 = -d0, -d1, -d2, -d3
        sn = math.sqrt(d1 * d1 + d2 * d2 + d3 * d3)
        s = 2.0 * math.atan2(sn, d0) / sn if sn > 1e-12 else 2.0 / d0  # rotation vector (inverse of exp)
        out = np.array([s * d1, s * d2, s * d3, w_a0 - w_b0, w_a1 - w_b1, w_a2 - w_b2, t_a0 - t_b0, t_a1 - t_b1])
        return out if xa.size == 9 else np.concatenate([out, xa[9:] - xb[9:]])

    @staticmethod
    def apply_error(x: NDArray, dx: NDArray) -> NDArray:
        """x with the error dx applied: q o exp(dtheta/2) (exact), w + dw, tau + dtau."""
        d = dx.tolist()
        w0_, w1_, w2_, q0, q1, q2, q3, t0, t1 = x[:9].tolist()
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
        out = np.array([w0_ + d[3], w1_ + d[4], w2_ + d[5], n0 / nn, n1 / nn, n2 / nn, n3 / nn, t0 + d[6], t1 + d[7]])
        return out if x.size == 9 else np.concatenate([out, x[9:] + dx[8:]])
