"""Attitude from vector observations with the algorithm chosen per epoch (002, figure 1).

Three body/orbital vector pairs (002, eq. 8):
- antenna: the GNSS antenna axis, a_B from the configuration (``Spacecraft.antenna_axis_B``) and a_O from
  the visibility of the navigation satellites (eqs. 5-7, processing.vector_attitude.antenna_axis);
- magnetometer: the measured field h_B = R(q_BM) h_M (q_BM: ``Spacecraft.magnetometer_mounting``) and the
  model field in O (IGRF-14 at the GNSS position, or with ``field_model="dipole"`` the paper's axial
  dipole of eq. 2, whose directions are off by up to ~15-20 deg in LEO: give it a field_model_error_nT of
  several thousand nT);
- sun: the sun vector s_B from the panel currents (I = I_max max(0, n . s), processing.screening.panels.
  sun_from_currents) and the Sun direction in O from the ephemeris, in full sunlight only.

Per epoch (figure 1), by which measurements exist and passed the screening (002 eqs. 15-17 and
the generic checks of processing.screening.criteria):
- all three -> strongly coupled scheme: Wahba's problem (eq. 8), by default the q-method (eq. 9);
- magnetometer + antenna -> loosely coupled scheme (eqs. 10-14), or a two-vector Wahba solution when
  a Wahba method is asked for;
- magnetometer + sun or antenna + sun -> two-vector Wahba solution (beyond the paper's figure);
- fewer -> no attitude, the epoch flagged with the reason.

Frames: O is 002's orbital frame (Z2 radial, Y2 orbital angular momentum of the inertial motion,
X2 = Y2 x Z2), built in ITRF axes from the GNSS state (processing.vector_attitude.antenna_axis.dcm_EO_002). Output
q_OB (v_O = q_OB o v_B o q_OB^-1) and 002's angles (pitch J, yaw psi, roll phi of matrix (3) = dcm_BO).

Uncertainty: each vector has a direction error sigma_i (rad, per tangential axis): magnetometer
sqrt(noise^2 + model error^2) / |H|; sun (current noise + model error) / I_max (the sun components of
a body-axis panel set are I / I_max); antenna ``antenna_sigma_deg``. With weights a_i (default
1 / sigma_i^2) the covariance of the body-frame rotation-vector error is the sandwich
P = H^-1 G H^-1, H = sum a_i (I - b_i b_i^T), G = sum a_i^2 sigma_i^2 (I - b_i b_i^T) (= H^-1 for the
default weights; Shuster & Oh 1981). The loosely coupled solution is given the two-vector P.

Layout: the options, the vector pairs and their assembly from the streams are in
processing.vector_attitude.vector_pairs (re-exported here); this module holds the choice of the algorithm,
the solvers' use, the covariance and the result.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations, wahba
from processing.vector_attitude.loosely_coupled import loosely_coupled
from processing.vector_attitude.vector_pairs import (
    METHODS,
    VECTORS,
    Observations,
    VectorAttitudeError,
    VectorAttitudeParams,
    observations,
)

__all__ = [
    "CHI2_3_99",
    "VECTORS",
    "Observations",
    "VectorAttitudeError",
    "VectorAttitudeParams",
    "VectorAttitudeResult",
    "attitude_errors",
    "observations",
    "select_methods",
    "vector_attitude",
]

CHI2_3_99 = 11.344866730144373
"""99 % quantile of the chi-square distribution with 3 degrees of freedom."""


@dataclass(frozen=True)
class VectorAttitudeResult:
    """Per epoch: q_OB (T, 4) NaN where none; pitch/yaw/roll_rad (T,) of matrix (3); method (T,) str
    ("none" where no attitude); loss (T,) of eq. 8 with the weights used; covariance_rad2 (T, 3, 3)
    body-frame error covariance; residual_rad (T, 3) angle between b_i and dcm_BO r_i (NaN where the
    vector was not used); used (T, 3) vectors used; reason (T,) why there is no attitude."""

    time_tai_ns: NDArray[np.int64]
    q_OB: NDArray[np.float64]
    pitch_rad: NDArray[np.float64]
    yaw_rad: NDArray[np.float64]
    roll_rad: NDArray[np.float64]
    method: NDArray[np.object_]
    loss: NDArray[np.float64]
    covariance_rad2: NDArray[np.float64]
    residual_rad: NDArray[np.float64]
    used: NDArray[np.bool_]
    reason: NDArray[np.object_]

    @property
    def ok(self) -> NDArray[np.bool_]:
        return self.method != "none"

    def bound_rad(self, quantile_chi2: float = CHI2_3_99) -> NDArray[np.float64]:
        """Per-epoch bound on the total error angle: sqrt(chi2 quantile * largest eigenvalue of P)."""
        ev = np.full(self.time_tai_ns.size, np.nan)
        good = np.isfinite(self.covariance_rad2).all(axis=(1, 2))
        if np.any(good):
            ev[good] = np.linalg.eigvalsh(self.covariance_rad2[good])[:, -1]
        return np.sqrt(quantile_chi2 * ev)



def select_methods(available: ArrayLike, method: str = "auto") -> NDArray[np.object_]:
    """Figure 1 of 002: the algorithm per epoch from which vectors (antenna, magnetometer, sun) exist.

    available: (T, 3) bool. method: "auto" or a forced algorithm. Returns (T,) names: a Wahba method
    (strongly coupled with three vectors, two-vector solution with two), "loosely_coupled", or "none".
    """
    av = np.asarray(available, dtype=bool)
    if method not in METHODS:
        raise VectorAttitudeError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    ant, mag, sun = av[:, 0], av[:, 1], av[:, 2]
    n_vec = av.sum(axis=1)
    out = np.full(av.shape[0], "none", dtype=object)
    if method == "loosely_coupled":
        out[ant & mag] = "loosely_coupled"
        return out
    wahba_name = "q_method" if method == "auto" else method
    out[n_vec >= 2] = wahba_name
    if method == "auto":
        out[ant & mag & ~sun] = "loosely_coupled"
    return out


def _sandwich(b: NDArray[np.float64], w: NDArray[np.float64], sigma: NDArray[np.float64]) -> NDArray[np.float64]:
    """P = H^-1 G H^-1 with H = sum a (I - b b^T), G = sum a^2 sigma^2 (I - b b^T); (T, 3, 3), NaN if singular."""
    proj = np.eye(3) - b[..., :, None] * b[..., None, :]
    h = np.einsum("tn,tnij->tij", w, proj)
    g = np.einsum("tn,tnij->tij", w * w * np.nan_to_num(sigma) ** 2, proj)
    det = np.linalg.det(h)
    scale = np.maximum(w.sum(axis=1), 1e-300) ** 3
    ok = det > 1e-10 * scale
    hinv = np.linalg.inv(np.where(ok[:, None, None], h, np.eye(3)))
    p = hinv @ g @ hinv
    return np.where(ok[:, None, None], p, np.nan)


def vector_attitude(obs: Observations, params: VectorAttitudeParams | None = None) -> VectorAttitudeResult:
    """Attitude per epoch by the algorithm of :func:`select_methods` (002, figure 1, eqs. 8-14)."""
    p = params or VectorAttitudeParams()
    n = obs.time_tai_ns.size
    methods = select_methods(obs.available, p.method)
    if p.weights is not None:
        unknown = set(p.weights) - set(VECTORS)
        if unknown:
            raise VectorAttitudeError(f"weights for unknown vectors {sorted(unknown)}; expected {list(VECTORS)}")
        w_fixed = np.array([float(p.weights.get(v, 0.0)) for v in VECTORS])
        w = np.broadcast_to(w_fixed, (n, 3)).copy()
    else:
        with np.errstate(divide="ignore"):
            w = 1.0 / obs.sigma_rad**2
    w = np.where(obs.available, np.nan_to_num(w, posinf=0.0), 0.0)
    q_BO = np.full((n, 4), np.nan)
    used = np.zeros((n, 3), bool)
    b_safe = np.where(np.isfinite(obs.b_B), obs.b_B, 0.0)
    r_safe = np.where(np.isfinite(obs.r_O), obs.r_O, 0.0)
    for name in ("q_method", "quest", "svd", "esoq2"):
        sel = methods == name
        if np.any(sel):
            res = wahba.solve(name, b_safe[sel], r_safe[sel], w[sel], covariance=False)
            q_BO[sel] = res.q
            used[sel] = w[sel] > 0
    sel = methods == "loosely_coupled"
    if np.any(sel):
        a_B = obs.b_B[sel, 0]
        # the antenna axis in B is the same at every epoch (configuration)
        res_lc = loosely_coupled(obs.r_O[sel, 0], obs.b_B[sel, 1], obs.r_O[sel, 1], a_B[0])
        q_BO[sel] = res_lc.q_BO
        used[sel, 0] = used[sel, 1] = True
        failed = np.flatnonzero(sel)[~res_lc.ok]
        methods[failed] = "none"
        used[failed] = False
    have = np.isfinite(q_BO).all(axis=1)
    methods[~have] = "none"
    wu = np.where(used, w, 0.0)
    cov = _sandwich(b_safe, wu, obs.sigma_rad)
    cov[~have] = np.nan
    dcm_BO = rotations.quat_to_dcm(np.where(have[:, None], q_BO, [1.0, 0, 0, 0]))
    pred = np.einsum("tij,tnj->tni", dcm_BO, r_safe)
    cosr = np.clip(np.einsum("tni,tni->tn", pred, b_safe), -1.0, 1.0)
    residual = np.where(used & have[:, None], np.arccos(cosr), np.nan)
    loss = np.where(have, np.sum(wu * np.sum((b_safe - pred) ** 2, axis=2), axis=1), np.nan)
    q_OB = np.where(have[:, None], rotations.quat_canonical(rotations.quat_conjugate(
        np.where(have[:, None], q_BO, [1.0, 0, 0, 0]))), np.nan)
    pitch, yaw, roll = rotations.angles_002_from_dcm(dcm_BO)
    nan = np.where(have, 0.0, np.nan)
    reason = np.full(n, "", dtype=object)
    missing = ~have
    if np.any(missing):
        reason[missing] = ["; ".join(f"{v}: {obs.why[i, j] or 'not used'}" for j, v in enumerate(VECTORS)
                                     if not obs.available[i, j]) or "solver failed" for i in np.flatnonzero(missing)]
    return VectorAttitudeResult(time_tai_ns=obs.time_tai_ns, q_OB=q_OB, pitch_rad=pitch + nan, yaw_rad=yaw + nan,
                                roll_rad=roll + nan, method=methods, loss=loss, covariance_rad2=cov,
                                residual_rad=residual, used=used & have[:, None], reason=reason)


def attitude_errors(result: VectorAttitudeResult, q_OB_true: ArrayLike) -> tuple[NDArray[np.float64],
                                                                                  NDArray[np.float64]]:
    """Error angle (T,) rad and NEES (T,) = d^T P^-1 d of the body-frame rotation-vector error d,
    for simulations with known truth q_OB_true (T, 4). NaN where there is no attitude."""
    qt = np.asarray(q_OB_true, dtype=np.float64)
    have = result.ok
    q_est = np.where(have[:, None], result.q_OB, [1.0, 0, 0, 0])
    # body-frame error: q_err = q_BO_est o q_OB_true = q_OB_est^-1 o q_OB_true
    d = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(q_est), qt))
    angle = np.where(have, np.linalg.norm(d, axis=1), np.nan)
    good = have & np.isfinite(result.covariance_rad2).all(axis=(1, 2))
    nees = np.full(have.size, np.nan)
    if np.any(good):
        pinv = np.linalg.inv(result.covariance_rad2[good])
        nees[good] = np.einsum("ti,tij,tj->t", d[good], pinv, d[good])
    return angle, nees
