"""Running the gyroless filters (paper 004's EKF or the MEKF) over the steps of prepared inputs.

:func:`run_filter` predicts and updates step by step and keeps the history (:class:`FilterRun`) that the
RTS smoother (processing.gyroless.rts_smoother) and the consistency statistics use; the initial
covariance (:func:`initial_covariance`), the two-vector start (:func:`triad_q_OB`) and the attitude
error convention of the filters' covariance (:func:`attitude_errors_rad`) are here too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.gyroless.ekf import NO_MODEL_ERRORS, FilterTuning, ModelErrorStates
from processing.gyroless.ekf004 import GyrolessEKF
from processing.gyroless.mekf import GyrolessMEKF

__all__ = [
    "FILTERS",
    "FilterKind",
    "FilterRun",
    "GyrolessInputs",
    "attitude_errors_rad",
    "covariance_sigmas",
    "initial_covariance",
    "model_error_series",
    "run_filter",
    "triad_q_OB",
]

FilterKind = Literal["ekf", "mekf"]
DEFAULT_TUNING = FilterTuning()


@dataclass(frozen=True)
class GyrolessInputs:
    """Per-step inputs of the filters, K steps (times need not be uniform).

    t_s (K,): time [s] since an epoch. b_O, s_O (K, 3): unit reference field and Sun directions in O.
    b_B, s_B (K, 3): measured unit directions in B; NaN rows = no measurement at that step.
    sigma_b_rad, sigma_s_rad (K,): 1-sigma direction noise [rad] per tangent axis.
    torque_B_N_m (K, 3): known torque in B over [t_k, t_k+1) (e.g. mu x B_measured).
    w0_rad_s (K,): orbital rate (w_OI^O = (0, -w0, 0)); n2_rad2_s2 (K,): mu / r^3.
    b_O_norm_nT (K,) or None: magnitude of the reference field [nT] (needed by the model-error states).
    dipole_B_A_m2 (K, 3) or None: the magnetorquer dipole behind torque_B_N_m (the bias states correct the
    torque with it).
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
    b_O_norm_nT: NDArray | None = None
    dipole_B_A_m2: NDArray | None = None

    def __post_init__(self) -> None:
        k = np.shape(self.t_s)[0]
        for name in ("b_O", "b_B", "s_O", "s_B", "torque_B_N_m", "dipole_B_A_m2"):
            if name == "dipole_B_A_m2" and self.dipole_B_A_m2 is None:
                continue
            if np.shape(getattr(self, name)) != (k, 3):
                raise ValueError(f"{name} must have shape ({k}, 3), got {np.shape(getattr(self, name))}")
        for name in ("sigma_b_rad", "sigma_s_rad", "w0_rad_s", "n2_rad2_s2", "b_O_norm_nT"):
            if name == "b_O_norm_nT" and self.b_O_norm_nT is None:
                continue
            if np.shape(getattr(self, name)) != (k,):
                raise ValueError(f"{name} must have shape ({k},), got {np.shape(getattr(self, name))}")
        if k and np.any(np.diff(self.t_s) <= 0):
            raise ValueError("t_s must increase strictly")

    @property
    def n_steps(self) -> int:
        return int(np.shape(self.t_s)[0])


FILTERS: dict[str, type[GyrolessEKF] | type[GyrolessMEKF]] = {"ekf": GyrolessEKF, "mekf": GyrolessMEKF}


@dataclass(frozen=True)
class FilterRun:
    """History of a filter pass over K steps.

    kind: "ekf" | "mekf". x_filt (K, 9 + m): (w_BI^B, q_OB, tau_d,x, tau_d,y, model errors (m)) after each update;
    P_filt (K, n, n); x_pred (K, 9), P_pred (K, n, n): predicted for step k from k-1 (k = 0: the
    initial values); Phi (K, n, n): Phi[k] maps errors at k-1 to k (Phi[0] = I).
    attitude_sigma_rad, rate_sigma_rad_s (K, 3): 1-sigma from P_filt (attitude about the B axes).
    nis (K,), nis_dof (K,) (NaN and 0 where no measurement was used), whitened (K, 6): whitened
    innovation components (NaN padded), used_mag, used_sun (K,) bool; residual_rad (K, 2): angle between
    the measured and the predicted (prior) field and Sun directions (NaN where not measured).
    model_errors: the model-error states carried (:class:`processing.gyroless.ekf.ModelErrorStates`).
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
    model_errors: ModelErrorStates = NO_MODEL_ERRORS

    @property
    def q_OB(self) -> NDArray:
        return self.x_filt[:, 3:7]

    @property
    def omega_BI_B(self) -> NDArray:
        return self.x_filt[:, 0:3]

    @property
    def tau_d_O(self) -> NDArray:
        return self.x_filt[:, 7:9]


def model_error_series(x: NDArray, kind: str, P: NDArray, model_errors: ModelErrorStates
                       ) -> dict[str, tuple[NDArray, NDArray]]:
    """The model-error states of states x (K, 9 + m) with covariances P (K, n, n) of a filter kind:
    {"magnetometer_bias_B_nT" and/or "field_error_O_nT": (values (K, 3), 1-sigma (K, 3))} [nT]."""
    out: dict[str, tuple[NDArray, NDArray]] = {}
    i, j = 9, (8 if kind == "mekf" else 9)
    for name, on in (("magnetometer_bias_B_nT", model_errors.has_bias),
                     ("field_error_O_nT", model_errors.has_field_error)):
        if on:
            sig = np.sqrt(np.maximum(np.einsum("kii->ki", P[:, j:j + 3, j:j + 3]), 0.0))
            out[name] = (x[:, i:i + 3], sig)
            i, j = i + 3, j + 3
    return out


def initial_covariance(kind: FilterKind, q_OB: ArrayLike, attitude_sigma_rad: float, rate_sigma_rad_s: float,
                       disturbance_sigma_N_m: float, model_errors: ModelErrorStates = NO_MODEL_ERRORS) -> NDArray:
    """Diagonal initial covariance for a filter kind (attitude error isotropic in B), the model-error states
    appended with their prior sigmas."""
    if model_errors.n_states:
        core = initial_covariance(kind, q_OB, attitude_sigma_rad, rate_sigma_rad_s, disturbance_sigma_N_m)
        nc, na = core.shape[0], model_errors.n_states
        P = np.zeros((nc + na, nc + na))
        P[:nc, :nc] = core
        P[nc:, nc:] = np.diag(np.square(model_errors.prior_sigmas()))
        return P
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
    tuning: FilterTuning = DEFAULT_TUNING,
    model_errors: ModelErrorStates = NO_MODEL_ERRORS,
) -> FilterRun:
    """Run the EKF of 004 ("ekf") or the multiplicative EKF ("mekf") over all steps of ``inputs``.

    q0_OB (4,), omega0_BI_B (3,): initial estimate at inputs.t_s[0], with the given 1-sigma
    uncertainties (attitude isotropic, rad; rate, rad/s; disturbance, N m); model_errors: extra states
    (magnetometer bias, field-model error; they need inputs.b_O_norm_nT). Returns :class:`FilterRun`.
    """
    if kind not in FILTERS:
        raise ValueError(f"kind must be one of {sorted(FILTERS)}, got {kind!r}")
    cls = FILTERS[kind]
    if model_errors.n_states and inputs.b_O_norm_nT is None:
        raise ValueError("the model-error states need inputs.b_O_norm_nT (the reference field magnitude)")
    P0 = initial_covariance(kind, q0_OB, attitude_sigma_rad, rate_sigma_rad_s, disturbance_sigma_N_m, model_errors)
    f = cls(J, q0_OB, omega0_BI_B, P0, tuning, model_errors=model_errors)
    K, n = inputs.n_steps, f.n
    nx = 9 + model_errors.n_states
    x_filt, x_pred = np.empty((K, nx)), np.empty((K, nx))
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
    bn = inputs.b_O_norm_nT if inputs.b_O_norm_nT is not None else np.full(K, np.nan)
    w0s, n2s, torque, dipole = inputs.w0_rad_s, inputs.n2_rad2_s2, inputs.torque_B_N_m, inputs.dipole_B_A_m2
    eye = np.eye(n)
    for k in range(K):
        if k == 0:
            Phi_all[0] = eye
        else:
            Phi_all[k] = f.predict(float(t[k] - t[k - 1]), float(w0s[k - 1]), float(n2s[k - 1]), torque[k - 1],
                                   None if dipole is None else dipole[k - 1])
        x_pred[k] = f.state()
        P_pred[k] = f.P
        st = f.update(b_B[k] if b_ok[k] else None, b_O[k], float(sb[k]),
                      s_B[k] if s_ok[k] else None, s_O[k], float(ss[k]), b_norm_nT=float(bn[k]))
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
                     whitened=whitened, used_mag=used_mag, used_sun=used_sun, residual_rad=residual,
                     model_errors=model_errors)


def covariance_sigmas(kind: str, x: NDArray, P: NDArray) -> tuple[NDArray, NDArray]:
    """1-sigma attitude error about the B axes [rad] and rate [rad/s] (K, 3) from states x (K, 9 + m) and
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
