"""Forward pass: the multiplicative EKF over the filter epochs (Markley 2003, "Attitude error
representations for Kalman filtering", J. Guidance 26(2); Crassidis & Junkins, Optimal Estimation of
Dynamic Systems, 2nd ed., §7.2, with the augmented calibration states of Pittelkau 2001).

Per epoch j: propagate with the block quantities (processing.definitive.propagation), q^ <- q^ o Q_j o
exp(G (p^ - p_ref)), P <- Phi P Phi^T + Q; then update with every star-tracker head measured at that
time, stacked: the residual of head h is the rotation vector z = rotvec((q^_IB o exp(w_B dt^) o
q^_BS_h)^-1 o q_IS,meas) in the sensor axes, with H = [R_SB, 0, ..., I (mounting of h), ..., R_SB w_B (dt)]
and R_h = diag(sigma_h²) (anisotropic about the boresight). Covariance update (I - K H) P, symmetrised; the
attitude error is folded into the quaternion after each update (the reset, to first order the identity).
A head's measurement whose own NIS exceeds the gate is rejected (after ``WARMUP_UPDATES`` updates, so that
the diffuse start cannot reject everything). The loop runs once per epoch and touches no gyro sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.definitive.model import FloatArray, StateLayout
from processing.definitive.propagation import Blocks

WARMUP_UPDATES = 20


@dataclass(frozen=True)
class Measurements:
    """Star-tracker samples sorted by epoch: epoch (S,) index, head (S,) index into the layout's heads,
    q_IS (S, 4) measured; ptr (E + 1,) so that epoch j has rows ptr[j]:ptr[j+1]."""

    epoch: NDArray[np.intp]
    head: NDArray[np.intp]
    q_IS: FloatArray
    ptr: NDArray[np.intp]


@dataclass(frozen=True)
class ForwardRun:
    """Forward pass: q_pred, q_filt (E, 4); p_filt (E, n-3) = (b, k, phi, dt); P (E, n, n) filtered
    covariances (the smoother overwrites them with the smoothed ones); per measurement (S,): innovation
    (S, 3) before the update, whitened (S, 3) by the head's innovation covariance, nis (S,) of the head
    alone, used (S,) False where gated out; per epoch nis_epoch, dof_epoch of the joint update (NaN / 0
    without one)."""

    q_pred: FloatArray
    q_filt: FloatArray
    p_filt: FloatArray
    P: FloatArray
    innovation: FloatArray
    whitened: FloatArray
    nis: FloatArray
    used: NDArray[np.bool_]
    nis_epoch: FloatArray
    dof_epoch: FloatArray


def qmul(p: FloatArray, q: FloatArray) -> FloatArray:
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    return np.array([p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3, p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
                     p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1, p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0])


def qexp(v: FloatArray) -> FloatArray:
    """Quaternion of a rotation vector (3,)."""
    x, y, z = v
    th = math.sqrt(x * x + y * y + z * z)
    if th < 1e-8:
        k = 0.5 - th * th / 48.0
        return np.array([1.0 - th * th / 8.0, k * x, k * y, k * z])
    k = math.sin(0.5 * th) / th
    return np.array([math.cos(0.5 * th), k * x, k * y, k * z])


def qlog(q: FloatArray) -> FloatArray:
    """Rotation vector (3,) of a unit quaternion (the shorter rotation)."""
    w, x, y, z = q
    if w < 0:
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    k = 2.0 / w if s < 1e-8 else 2.0 * math.atan2(s, w) / s
    return np.array([k * x, k * y, k * z])


def qconj(q: FloatArray) -> FloatArray:
    return np.array([q[0], -q[1], -q[2], -q[3]])


def dcm(q: FloatArray) -> FloatArray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


@dataclass(frozen=True)
class FilterModel:
    """What the loop needs besides the blocks: the layout, the configured mountings q_BS (H, 4), the
    measurement variances (H, 3), the reference parameters per epoch for the propagation correction
    (p_ref_bk (E, 3 + n_cal): b_ref of the block and k_ref), the initial state and covariance, the gate."""

    layout: StateLayout
    q_BS: FloatArray
    r_var: FloatArray
    p_ref_bk: FloatArray
    p0: FloatArray
    P0: FloatArray
    gate: float

    @property
    def C_SB(self) -> FloatArray:
        """R_SB (H, 3, 3) of the configured mountings."""
        c = self.__dict__.get("_c_sb")
        if c is None:
            c = np.stack([dcm(q).T for q in self.q_BS])
            object.__setattr__(self, "_c_sb", c)
        return c


def head_mounting(model: FilterModel, p: FloatArray, h: int) -> FloatArray:
    sl = model.layout.mount(h)
    q = model.q_BS[h]
    return q if sl is None else qmul(q, qexp(p[sl.start - 3:sl.stop - 3]))


def _update(model: FilterModel, q: FloatArray, p: FloatArray, P: FloatArray, meas: Measurements, rows: range,
            rate: FloatArray, out: dict[str, np.ndarray], warm: bool) -> tuple[FloatArray, FloatArray, FloatArray,
                                                                               float, int]:
    lay = model.layout
    n = lay.n
    dt_i = lay.dt
    dt_hat = p[dt_i - 3] if dt_i is not None else 0.0
    q_t = qmul(q, qexp(rate * dt_hat)) if dt_i is not None else q
    zs, Hs, rs, idx = [], [], [], []
    for i in rows:
        h = int(meas.head[i])
        if lay.mount(h) is None:
            q_BS, C_SB = model.q_BS[h], model.C_SB[h]
        else:
            q_BS = head_mounting(model, p, h)
            C_SB = dcm(q_BS).T
        z = qlog(qmul(qconj(qmul(q_t, q_BS)), meas.q_IS[i]))
        H = np.zeros((3, n))
        H[:, 0:3] = C_SB
        sl = lay.mount(h)
        if sl is not None:
            H[:, sl] = np.eye(3)
        if dt_i is not None:
            H[:, dt_i] = C_SB @ rate
        S = H @ P @ H.T + np.diag(model.r_var[h])
        L = np.linalg.cholesky(S)
        w = np.linalg.solve(L, z)
        nis = float(w @ w)
        out["innovation"][i], out["whitened"][i], out["nis"][i] = z, w, nis
        if warm and model.gate > 0 and nis > model.gate:
            out["used"][i] = False
            continue
        zs.append(z)
        Hs.append(H)
        rs.append(model.r_var[h])
        idx.append(i)
    if not zs:
        return q, p, P, math.nan, 0
    z = np.concatenate(zs)
    H = np.vstack(Hs)
    R = np.diag(np.concatenate(rs))
    PHt = P @ H.T
    S = H @ PHt + R
    K = np.linalg.solve(S, PHt.T).T
    dx = K @ z
    P = P - K @ PHt.T  # (I - K H) P; symmetrised below (the Joseph form costs three more products per epoch)
    P = 0.5 * (P + P.T)
    nis_joint = float(z @ np.linalg.solve(S, z))
    q = qmul(q, qexp(dx[0:3]))
    q = q / math.sqrt(float(q @ q))
    return q, p + dx[3:], P, nis_joint, z.size


def run_filter(blocks: Blocks, meas: Measurements, model: FilterModel) -> ForwardRun:
    """The forward pass over the E epochs of ``blocks`` (see the module docstring)."""
    lay = model.layout
    E, n, nbk = blocks.Q.shape[0], lay.n, 3 + lay.n_cal
    S = meas.epoch.size
    q_pred, q_filt = np.empty((E, 4)), np.empty((E, 4))
    p_filt = np.empty((E, n - 3))
    Ps = np.empty((E, n, n))
    out = {"innovation": np.full((S, 3), np.nan), "whitened": np.full((S, 3), np.nan),
           "nis": np.full(S, np.nan), "used": np.ones(S, dtype=bool)}
    nis_epoch, dof_epoch = np.full(E, np.nan), np.zeros(E)
    first = meas.ptr[0]
    h0 = int(meas.head[first])
    q = qmul(meas.q_IS[first], qconj(head_mounting(model, model.p0, h0)))
    p, P = model.p0.copy(), model.P0.copy()
    eye = np.eye(n)
    updates = 0
    Qb, phi_top, q6, rates, pref = blocks.Q, blocks.phi_top, blocks.q6, blocks.rate_B, model.p_ref_bk
    for j in range(E):
        if j > 0:
            corr = phi_top[j, :, 3:] @ (p[:nbk] - pref[j])
            q = qmul(qmul(q, Qb[j]), qexp(corr))
            Phi = eye.copy()
            Phi[:3, :nbk + 3] = phi_top[j]
            P = Phi @ P @ Phi.T
            P[:6, :6] += q6[j]
        q_pred[j] = q
        a, b = meas.ptr[j], meas.ptr[j + 1]
        if b > a:
            q, p, P, nis_epoch[j], dof = _update(model, q, p, P, meas, range(a, b), rates[j], out,
                                                 updates >= WARMUP_UPDATES)
            dof_epoch[j] = dof
            updates += dof > 0
        q_filt[j], p_filt[j], Ps[j] = q, p, P
    return ForwardRun(q_pred=q_pred, q_filt=q_filt, p_filt=p_filt, P=Ps, innovation=out["innovation"],
                      whitened=out["whitened"], nis=out["nis"], used=out["used"], nis_epoch=nis_epoch,
                      dof_epoch=dof_epoch)
