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

- :class:`processing.gyroless.ekf004.GyrolessEKF` -- the filter of 004 (fig. 2): state z = (w_BI^B, q, tau_d,x,
  tau_d,y) (9), the quaternion updated additively and normalised after each update (004, after [4], [10];
  the covariance is left as the additive update gives it, as in 004);
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
update) costs ~0.1 ms of CPU, see bench/gyroless_ekf.py. Layout: the shared filter machinery here, the EKF
of 004 in processing.gyroless.ekf004, the MEKF in processing.gyroless.mekf, running either over the steps
(with the initial covariance, the TRIAD start and the attitude-error convention) in
processing.gyroless.filtering.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg.lapack import dpotrf as _dpotrf
from scipy.linalg.lapack import dtrtri as _dtrtri

from processing.attitude.rigid_body import RigidBody004, dcm_BO_columns

__all__ = [
    "FilterBase",
    "FilterTuning",
    "ModelErrorStates",
    "UpdateStats",
    "Vector",
    "rotate_BO",
    "tangent_basis",
]

Vector = Sequence[float] | NDArray[np.float64]
"""A 3-vector as floats or a (3,) array."""


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
class ModelErrorStates:
    """Model errors the filters carry as extra states, appended after the core state (both filters).

    magnetometer_bias: estimate a constant (or slowly walking) magnetometer bias beta_B [nT] in B
    (3 states), B_meas = dcm_BO B_O + beta_B + n; bias_sigma_nT its prior 1-sigma per axis,
    bias_walk_nT_sqrt_s its random walk (0: constant).
    field_error_sigma_nT > 0: the reference field's error g_O [nT] in O as a first-order Gauss-Markov
    process (3 states), B_O,true = B_O,model + g_O, g' = -g / field_error_tau_s + white noise, steady
    1-sigma field_error_sigma_nT per axis (it also absorbs the slow part of scale-factor errors).
    With either, the field measurement is the predicted unit vector of dcm_BO (B_O + g_O) + beta_B, which
    needs the reference magnitude |B_O| per step (GyrolessInputs.b_O_norm_nT). The control torque computed
    from the measured field is corrected by the bias when the dipole is given to ``predict``:
    tau = mu x (B_meas - beta_B) (its Jacobian -J^-1 [mu x] couples the bias into the rates).
    """

    magnetometer_bias: bool = False
    bias_sigma_nT: float = 1000.0
    bias_walk_nT_sqrt_s: float = 0.0
    field_error_sigma_nT: float = 0.0
    field_error_tau_s: float = 1800.0

    def __post_init__(self) -> None:
        if not (self.bias_sigma_nT > 0 and self.bias_walk_nT_sqrt_s >= 0 and self.field_error_sigma_nT >= 0
                and self.field_error_tau_s > 0):
            raise ValueError("ModelErrorStates: bias_sigma_nT and field_error_tau_s must be > 0, the walk and "
                             f"field_error_sigma_nT >= 0, got {self!r}")

    @property
    def has_bias(self) -> bool:
        return bool(self.magnetometer_bias)

    @property
    def has_field_error(self) -> bool:
        return self.field_error_sigma_nT > 0

    @property
    def n_states(self) -> int:
        return 3 * int(self.has_bias) + 3 * int(self.has_field_error)

    def prior_sigmas(self) -> list[float]:
        """Initial 1-sigma of the extra states (bias, then field error) [nT]."""
        return [self.bias_sigma_nT] * (3 * self.has_bias) + [self.field_error_sigma_nT] * (3 * self.has_field_error)


NO_MODEL_ERRORS = ModelErrorStates()



def rotate_BO(cols: tuple, v: Vector) -> tuple[float, float, float]:
    """dcm_BO v for the columns (c1, c2, c3) of dcm_BO."""
    c1, c2, c3 = cols
    x, y, z = float(v[0]), float(v[1]), float(v[2])
    return (x * c1[0] + y * c2[0] + z * c3[0], x * c1[1] + y * c2[1] + z * c3[1], x * c1[2] + y * c2[2] + z * c3[2])


def tangent_basis(b: tuple[float, float, float]) -> tuple[tuple[float, ...], tuple[float, ...]]:
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
class UpdateStats:
    nis: float = math.nan
    dof: int = 0
    whitened: list[float] = field(default_factory=list)
    used_sun: bool = False
    used_mag: bool = False
    residual_rad: list[float] = field(default_factory=lambda: [math.nan, math.nan])


class FilterBase:
    """Shared state and bookkeeping. Subclasses define the covariance layout."""

    n_core: ClassVar[int]
    kind: ClassVar[str]
    n: int
    """Size of the error state: n_core + the model-error states."""
    _w_rows: ClassVar[slice]
    """Rows of the rate error in the error state."""

    def __init__(
        self,
        J: ArrayLike,
        q_OB: ArrayLike,
        omega_BI_B: ArrayLike,
        P0: NDArray,
        tuning: FilterTuning = FilterTuning(),
        tau_d_O: ArrayLike = (0.0, 0.0),
        model_errors: ModelErrorStates = NO_MODEL_ERRORS,
    ) -> None:
        self.model_errors = model_errors
        self.na = model_errors.n_states
        self.n = self.n_core + self.na
        self.aug: list[float] = [0.0] * self.na
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
        self._I_core = np.eye(self.n_core)
        self._I4 = np.eye(4)
        self._diag = np.arange(self.n) * (self.n + 1)
        self._q_cache: dict[float, NDArray] = {}
        self._aug_cache: dict[float, tuple[NDArray, NDArray]] = {}

    # -- state as a vector (w, q, tau, model errors) for storage and smoothing ---------------------------------
    def state(self) -> NDArray:
        return np.array(self.w + self.q + self.tau + tuple(self.aug))

    def set_state(self, x: ArrayLike) -> None:
        x = np.asarray(x, dtype=float)
        q = x[3:7] / np.linalg.norm(x[3:7])
        self.w = (float(x[0]), float(x[1]), float(x[2]))
        self.q = (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
        self.tau = (float(x[7]), float(x[8]))
        self.aug = [float(v) for v in x[9:]]

    def _aug_transition(self, dt: float) -> tuple[NDArray, NDArray]:
        """Transition factors (na,) and process-noise variances (na,) of the model-error states over dt."""
        c = self._aug_cache.get(dt)
        if c is None:
            me = self.model_errors
            phi, qv = [], []
            if me.has_bias:
                phi += [1.0] * 3
                qv += [max(me.bias_walk_nT_sqrt_s**2 * dt, 1e-8)] * 3
            if me.has_field_error:
                a = math.exp(-dt / me.field_error_tau_s)
                phi += [a] * 3
                qv += [max(me.field_error_sigma_nT**2 * (1.0 - a * a), 1e-8)] * 3
            c = (np.array(phi), np.array(qv))
            self._aug_cache[dt] = c
        return c

    def _bias_torque(self, torque_B: Vector, dipole_B: Vector | None) -> tuple[Vector, NDArray | None]:
        """The known torque corrected by the estimated bias, mu x (B_meas - beta) = torque - mu x beta, and
        d w' / d beta = -J^-1 [mu x] 1e-9 (beta in nT), or (torque, None) without bias states or dipole."""
        if dipole_B is None or not self.model_errors.has_bias:
            return torque_B, None
        mx, my, mz = float(dipole_B[0]), float(dipole_B[1]), float(dipole_B[2])
        if mx == 0.0 and my == 0.0 and mz == 0.0:
            return torque_B, None
        bx, by, bz = (1e-9 * v for v in self.aug[0:3])
        tb = (float(torque_B[0]) - (my * bz - mz * by), float(torque_B[1]) - (mz * bx - mx * bz),
              float(torque_B[2]) - (mx * by - my * bx))
        ji = np.array(self._jinv)[:, None]
        C = -1e-9 * ji * np.array([[0.0, -mz, my], [mz, 0.0, -mx], [-my, mx, 0.0]])
        return tb, C

    def _propagate_covariance(self, Phi_core: NDArray, q_core: NDArray, dt: float,
                              coupling: NDArray | None = None) -> NDArray:
        """P <- Phi P Phi^T + Q with the model-error block appended; the model-error means propagated.
        coupling (3, 3): d w'/d beta (bias into the rates), entered as dt C (and dt^2/2 C into the attitude
        for the MEKF's second-order Phi). Returns the full Phi (n, n)."""
        if not self.na:
            P = Phi_core @ self.P @ Phi_core.T
            P.flat[self._diag] += q_core
            self.P = P
            return Phi_core
        nc = self.n_core
        phi, qv = self._aug_transition(dt)
        Phi = np.zeros((self.n, self.n))
        Phi[:nc, :nc] = Phi_core
        Phi[nc:, nc:] = np.diag(phi)
        if coupling is not None:
            Phi[self._w_rows, nc:nc + 3] = dt * coupling
            if self.kind == "mekf":
                Phi[0:3, nc:nc + 3] = 0.5 * dt * dt * coupling
        P = Phi @ self.P @ Phi.T
        P.flat[self._diag] += np.concatenate([q_core, qv])
        self.P = P
        self.aug = [a * f for a, f in zip(self.aug, phi.tolist(), strict=True)]
        return Phi

    def _field_prediction(self, cols: tuple, ref: Vector, norm_nT: float
                          ) -> tuple[tuple[float, float, float], tuple[float, float, float],
                                     tuple[float, float, float], float]:
        """With model-error states: v_O = |B_O| ref + g_O [nT], u = dcm_BO v_O, the predicted unit vector p of
        u + beta_B and its norm m [nT]."""
        me, a = self.model_errors, self.aug
        nb = 3 if me.has_bias else 0
        v_O = (norm_nT * float(ref[0]), norm_nT * float(ref[1]), norm_nT * float(ref[2]))
        if me.has_field_error:
            v_O = (v_O[0] + a[nb], v_O[1] + a[nb + 1], v_O[2] + a[nb + 2])
        u = rotate_BO(cols, v_O)
        v = (u[0] + a[0], u[1] + a[1], u[2] + a[2]) if nb else u
        m = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        return v_O, u, (v[0] / m, v[1] / m, v[2] / m), m

    def _aug_rows(self, cols: tuple, dirs: Sequence[Sequence[float]], m: float) -> list[list[float]]:
        """Rows of H for the model-error states of a field measurement whose rows are the directions dirs
        (d/d beta = dir / m, d/d g_O = dcm_OB dir / m)."""
        me = self.model_errors
        c1, c2, c3 = cols
        out = []
        for e in dirs:
            row: list[float] = []
            if me.has_bias:
                row += [e[0] / m, e[1] / m, e[2] / m]
            if me.has_field_error:
                row += [(c1[0] * e[0] + c1[1] * e[1] + c1[2] * e[2]) / m,
                        (c2[0] * e[0] + c2[1] * e[1] + c2[2] * e[2]) / m,
                        (c3[0] * e[0] + c3[1] * e[1] + c3[2] * e[2]) / m]
            out.append(row)
        return out

    def _field_rows(self, cols: tuple, meas: Vector, ref: Vector, norm_nT: float
                    ) -> tuple[list[list[float]], list[float]]:
        raise NotImplementedError  # pragma: no cover - overridden

    def _propagate_state(self, dt: float, w0: float, n2: float, torque_B: Vector) -> None:
        tb = (float(torque_B[0]), float(torque_B[1]), float(torque_B[2]))
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

    def _gain(self, H: NDArray, y: NDArray, var: list[float], stats: UpdateStats) -> tuple[NDArray, NDArray]:
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
        b_B: Vector | None,
        b_O: Vector,
        sigma_b: float,
        s_B: Vector | None = None,
        s_O: Vector | None = None,
        sigma_s: float = math.nan,
        b_norm_nT: float = math.nan,
    ) -> UpdateStats:
        """Fuse unit vectors b (field) and s (Sun); either may be None (skipped). 004 eq. (4).

        Each filter gives the rows of H and the residuals of one vector (``_vector_rows``, or
        ``_field_rows`` for the field with model-error states, which needs the reference magnitude
        b_norm_nT) and applies the correction to its state (``_correct``)."""
        stats = UpdateStats()
        rows: list[list[float]] = []
        res: list[float] = []
        var: list[float] = []
        cols = dcm_BO_columns(self.q)
        for meas, ref, sig, tag in ((b_B, b_O, sigma_b, "mag"), (s_B, s_O, sigma_s, "sun")):
            if meas is None or ref is None:
                continue
            if self.na and tag == "mag":
                if not b_norm_nT > 0:
                    raise ValueError(f"the model-error states need the reference field magnitude, got {b_norm_nT}")
                h, r = self._field_rows(cols, meas, ref, b_norm_nT)
            else:
                h, r = self._vector_rows(cols, meas, ref)
                if self.na:
                    h = [row + [0.0] * self.na for row in h]
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

    def _vector_rows(self, cols: tuple, meas: Vector, ref: Vector) -> tuple[list[list[float]], list[float]]:
        raise NotImplementedError  # pragma: no cover - overridden

    def _correct(self, d: list[float]) -> None:
        raise NotImplementedError  # pragma: no cover - overridden

    def attitude_cov(self) -> NDArray:  # pragma: no cover - overridden
        raise NotImplementedError

    def omega_BO_B(self, w0: float) -> tuple[float, float, float]:
        c2 = dcm_BO_columns(self.q)[1]
        return (self.w[0] + w0 * c2[0], self.w[1] + w0 * c2[1], self.w[2] + w0 * c2[2])
