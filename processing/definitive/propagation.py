"""Gyro propagation between filter epochs, vectorised over the whole arc.

The filter steps from epoch to epoch (star-tracker times, plus propagation-only epochs in long gaps);
between two epochs lies a block of gyro sub-steps (processing.definitive.gyro.refine). Everything a block
contributes is computed here for all blocks at once, about a reference calibration p_ref (bias b_ref per
sub-step, calibration matrix K_ref):

- corrected increments in G, dG_k = M (da_k - b_ref,k dt_k) with M = (I + K_ref)^-1, in the body frame
  dB_k = R_BG dG_k plus the two-sample coning term dB_{k-1} x dB_k / 12 (Savage 1998);
- the attitude F_k = exp(dB_1) o ... o exp(dB_k) at every node, as one associative prefix product over the
  arc (processing.gyro_calibration.propagation.quat_cumprod), and the DCMs D_k = R(F_k);
- per block j (nodes a -> c): the relative rotation Q_j = F_a^-1 o F_c; the error transition
  Phi_tt = D_c^T D_a (Crassidis & Junkins §7.2.2: dtheta' = -w x dtheta + dw); the sensitivities of the
  block end attitude to the bias and K errors, by transporting every sub-step's rate error to the block end
  (A_k = D_c^T D_k, evaluated at the sub-step midpoint):

      G_b = -D_c^T (sum_k D_k dt_k) W,     G_K[:, (r, c)] = -D_c^T (sum_k D_k dG_k,c) W[:, r],     W = R_BG M,

  segmented sums over the sub-steps (np.add.reduceat), so the Python loop of the filter never touches a
  gyro sample;
- process noise: angle random walk Q_tt = D_c^T (sum_k D_k W diag(arw²) W^T D_k^T dt_k) D_c, bias random walk
  Q_bb = sigma_u² T I, Q_tb = -sigma_u² D_c^T (sum_k D_k (t_k - t_a) dt_k) W, Q_tt += sigma_u² T³/3 I
  (Farrenkopf's terms with the transport kept in the cross term).

The filter then propagates the estimate as q^_c = q^_a o Q_j o exp(G_b (b^ - b_ref) + G_K (k^ - k_ref)): the
first-order correction for the distance of the current estimate from the reference; the neglected
second-order term is reported (``max_second_order_rad``) and a later pass re-linearises about the smoothed
calibration. Body rate at each epoch: the corrected increments next to its node over their duration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.attitude import rotations
from processing.definitive.gyro import RefinedSteps
from processing.definitive.model import K_ENTRIES, FloatArray
from processing.gyro_calibration.propagation import quat_cumprod

CHUNK = 1 << 16
"""Sub-steps per chunk of the noise sums (bounds the temporaries)."""


@dataclass(frozen=True)
class Blocks:
    """Per epoch j (E,) (index 0: the first epoch, no block before it): Q (E, 4) the block rotation,
    phi_top (E, 3, 3 + 3 + n_cal) the attitude rows of the transition without the zero columns of the
    head mountings and the time offset ([Phi_tt | G_b | G_K]), q6 (E, 6, 6) the process noise of
    (theta, b), duration_s (E,), rate_B (E, 3) the reference-corrected body rate at the epoch, b_ref
    (E, 3) the reference bias over the block (duration-weighted mean)."""

    Q: FloatArray
    phi_top: FloatArray
    q6: FloatArray
    duration_s: FloatArray
    rate_B: FloatArray
    b_ref: FloatArray


def _dcm_rows(q: FloatArray) -> FloatArray:
    """R(q) (n, 3, 3) of unit quaternions (n, 4), without the input checks of processing.attitude."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    out = np.empty((q.shape[0], 3, 3))
    out[:, 0, 0] = 1 - 2 * (y * y + z * z)
    out[:, 0, 1] = 2 * (x * y - w * z)
    out[:, 0, 2] = 2 * (x * z + w * y)
    out[:, 1, 0] = 2 * (x * y + w * z)
    out[:, 1, 1] = 1 - 2 * (x * x + z * z)
    out[:, 1, 2] = 2 * (y * z - w * x)
    out[:, 2, 0] = 2 * (x * z - w * y)
    out[:, 2, 1] = 2 * (y * z + w * x)
    out[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return out


def body_increments(steps: RefinedSteps, R_BG: FloatArray, M: FloatArray, b_ref: FloatArray) -> FloatArray:
    """Corrected body-frame increments dB (M, 3) with the coning term; b_ref (M, 3) or (3,)."""
    dG = (steps.da_G - np.asarray(b_ref) * steps.dt_s[:, None]) @ M.T
    dB = dG @ R_BG.T
    dB[1:] += np.cross(dB[:-1], dB[1:]) / 12.0
    return dB


def node_attitudes(dB: FloatArray) -> FloatArray:
    """F (M+1, 4): gyro-propagated attitude at every node relative to node 0."""
    F = np.empty((dB.shape[0] + 1, 4))
    F[0] = (1.0, 0.0, 0.0, 0.0)
    F[1:] = quat_cumprod(rotations.rotvec_to_quat(dB))
    F[1:] /= np.linalg.norm(F[1:], axis=1, keepdims=True)
    return F


def _segment_sums(values: FloatArray, starts: NDArray[np.intp]) -> FloatArray:
    """Sums of values (M, ...) over the sub-steps of each block: rows [starts[j], starts[j+1]) ... last: to M."""
    return np.add.reduceat(values, starts, axis=0)


def block_quantities(steps: RefinedSteps, R_BG: FloatArray, K_ref: FloatArray, b_ref: FloatArray,
                     arw_rad_sqrt_s: FloatArray, sigma_u: float, calibration: tuple[int, ...]) -> Blocks:
    """The per-epoch block quantities of the module docstring. b_ref (M, 3) per sub-step or (3,)."""
    M = np.linalg.inv(np.eye(3) + K_ref)
    W = R_BG @ M
    b_steps = np.broadcast_to(np.asarray(b_ref, dtype=np.float64), steps.da_G.shape)
    dG = (steps.da_G - b_steps * steps.dt_s[:, None]) @ M.T
    dB = dG @ R_BG.T
    dB[1:] += np.cross(dB[:-1], dB[1:]) / 12.0
    F = node_attitudes(dB)
    D = _dcm_rows(F)
    D_mid = 0.5 * (D[:-1] + D[1:])  # (M, 3, 3), sub-step k spans nodes k -> k+1
    en = steps.epoch_node
    E = en.size
    starts = en[:-1] - en[0]  # block j (1..E-1) = sub-steps en[j-1] .. en[j]-1 (counted from en[0])
    dt = steps.dt_s
    n_cal = len(calibration)
    phi_top = np.zeros((E, 3, 6 + n_cal))
    q6 = np.zeros((E, 6, 6))
    duration = np.zeros(E)
    b_blk = np.zeros((E, 3))
    Q = np.zeros((E, 4))
    Q[:, 0] = 1.0
    if E > 1:
        lo, last = en[0], en[-1]  # sub-steps outside the epochs are not part of any block
        Dm, dtm, dGm, bm = D_mid[lo:last], dt[lo:last], dG[lo:last], b_steps[lo:last]
        Dc = D[en[1:]]  # (E-1, 3, 3)
        DcT = np.swapaxes(Dc, 1, 2)
        Da = D[en[:-1]]
        phi_top[1:, :, 0:3] = DcT @ Da
        S1 = _segment_sums(Dm * dtm[:, None, None], starts)
        phi_top[1:, :, 3:6] = -(DcT @ S1) @ W
        for col, entry in enumerate(calibration):
            r, c = K_ENTRIES[entry]
            S2 = _segment_sums(Dm * dGm[:, c, None, None], starts)
            phi_top[1:, :, 6 + col] = -np.einsum("jab,jbc,c->ja", DcT, S2, W[:, r])
        T = _segment_sums(dtm, starts)
        duration[1:] = T
        b_blk[1:] = _segment_sums(bm * dtm[:, None], starts) / T[:, None]
        t_rel = 0.5 * (steps.t_s[:-1] + steps.t_s[1:])[lo:last] - np.repeat(steps.t_s[en[:-1]], np.diff(en))
        S3 = _segment_sums(Dm * (t_rel * dtm)[:, None, None], starts)
        qtt = DcT @ _noise_sum(Dm, dtm, W, np.asarray(arw_rad_sqrt_s, dtype=np.float64), starts) @ Dc
        su2 = float(sigma_u) ** 2
        q6[1:, 0:3, 0:3] = qtt + (su2 * T**3 / 3.0)[:, None, None] * np.eye(3)
        qtb = -su2 * (DcT @ S3) @ W
        q6[1:, 0:3, 3:6] = qtb
        q6[1:, 3:6, 0:3] = np.swapaxes(qtb, 1, 2)
        q6[1:, 3:6, 3:6] = (su2 * T)[:, None, None] * np.eye(3)
        Q[1:] = rotations.quat_multiply(rotations.quat_conjugate(F[en[:-1]]), F[en[1:]])
    rate = _epoch_rates(dB, dt, en)
    return Blocks(Q=Q, phi_top=phi_top, q6=q6, duration_s=duration, rate_B=rate, b_ref=b_blk)


def _noise_sum(Dm: FloatArray, dt: FloatArray, W: FloatArray, arw: FloatArray,
               starts: NDArray[np.intp]) -> FloatArray:
    """Segmented sums of D_k V D_k^T dt_k, V = W diag(arw²) W^T (isotropic V: the scalar sum times I)."""
    V = W @ np.diag(np.broadcast_to(arw, (3,)) ** 2) @ W.T
    if np.allclose(V, V[0, 0] * np.eye(3), rtol=1e-12, atol=0.0):
        return _segment_sums(dt, starts)[:, None, None] * V
    out = np.zeros((starts.size, 3, 3))
    block_of = np.repeat(np.arange(starts.size), np.diff(np.append(starts, Dm.shape[0])))
    for a in range(0, Dm.shape[0], CHUNK):
        d = Dm[a:a + CHUNK]
        x = np.einsum("kij,jl,kml->kim", d, V, d) * dt[a:a + CHUNK, None, None]
        np.add.at(out, block_of[a:a + CHUNK], x)
    return out


def _epoch_rates(dB: FloatArray, dt: FloatArray, en: NDArray[np.intp]) -> FloatArray:
    """Body rate at each epoch node from the corrected increments of the sub-steps on either side."""
    m = dB.shape[0]
    before = np.clip(en - 1, 0, m - 1)
    after = np.clip(en, 0, m - 1)
    num = dB[before] + dB[after]
    den = dt[before] + dt[after]
    return num / den[:, None]
