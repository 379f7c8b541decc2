"""A straightforward per-gyro-step MEKF + RTS smoother (attitude and bias only): the yardstick of the block
estimator (processing.definitive.estimate) in the benchmark and the tests.

Textbook form (Crassidis & Junkins, Optimal Estimation of Dynamic Systems, 2nd ed., Table 7.1): every gyro
sub-step (the refined grid of processing.definitive.gyro, with the star-tracker times as nodes) propagates
q^ <- q^ o exp(w^ dt) with w^ = R_BG (da / dt - b^) and P <- Phi P Phi^T + Q with Phi = [[R(exp(w^ dt))^T,
-R_BG dt], [0, I]] and Farrenkopf's Q; star-tracker heads measured at a node update one after the other;
the RTS pass runs over every sub-step. No vectorisation across steps, no reference calibration: the
estimate itself is the linearisation point, as in the textbook. Noise levels must be given.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.attitude import rotations
from processing.definitive.estimate import StarTrackerHead
from processing.definitive.filter import dcm, qconj, qexp, qlog, qmul
from processing.definitive.gyro import GyroSteps, refine
from processing.definitive.model import DefinitiveError, FloatArray


@dataclass(frozen=True)
class ReferenceResult:
    """Smoothed attitude q_IB (K, 4), its sigma (K, 3), bias (K, 3) in G at the star-tracker epochs (K,)."""

    time_tai_ns: NDArray[np.int64]
    q_IB: FloatArray
    attitude_sigma_rad: FloatArray
    bias_G_rad_s: FloatArray


def reference_smoother(steps: GyroSteps, heads: Sequence[StarTrackerHead], q_BG: FloatArray,
                       sigma_rad: dict[str, FloatArray], arw_rad_sqrt_s: float, sigma_u: float,
                       attitude_sigma_rad: float = 0.017, bias_sigma_rad_s: float = 1e-4) -> ReferenceResult:
    """Per-step MEKF + RTS over the gyro grid (module docstring); isotropic angle random walk."""
    t_all = np.unique(np.concatenate([np.asarray(h.time_tai_ns, dtype=np.int64) for h in heads]))
    t_all = t_all[(t_all >= steps.t_ns[0]) & (t_all <= steps.t_ns[-1])]
    if t_all.size < 2:
        raise DefinitiveError("need star-tracker samples within the gyro span")
    rs = refine(steps, t_all)
    first = int(rs.epoch_node[0])
    node_meas: dict[int, list[tuple[int, FloatArray]]] = {}
    for h, head in enumerate(heads):
        t = np.asarray(head.time_tai_ns, dtype=np.int64)
        for ti, q in zip(t, np.asarray(head.q_IS, dtype=np.float64), strict=True):
            if t_all[0] <= ti <= t_all[-1]:
                node_meas.setdefault(int(rs.epoch_node[np.searchsorted(t_all, ti)]), []).append((h, q))
    R_BG = rotations.quat_to_dcm(np.asarray(q_BG, dtype=np.float64))
    C_SB = [dcm(np.asarray(h.q_BS, dtype=np.float64)).T for h in heads]
    r_var = [np.asarray(sigma_rad[h.name], dtype=np.float64) ** 2 for h in heads]
    last = int(rs.epoch_node[-1])
    n_nodes = last - first + 1
    q_f, q_p = np.empty((n_nodes, 4)), np.empty((n_nodes, 4))
    b_f = np.empty((n_nodes, 3))
    P_f, Phis = np.empty((n_nodes, 6, 6)), np.empty((n_nodes, 6, 6))
    h0, qm0 = node_meas[first][0]
    q = qmul(qm0, qconj(np.asarray(heads[h0].q_BS, dtype=np.float64)))
    b = np.zeros(3)
    P = np.diag([attitude_sigma_rad**2] * 3 + [bias_sigma_rad_s**2] * 3)
    arw2, su2 = arw_rad_sqrt_s**2, sigma_u**2
    for i in range(n_nodes):
        node = first + i
        if i > 0:
            dt = rs.dt_s[node - 1]
            w = R_BG @ (rs.da_G[node - 1] / dt - b)
            dq = qexp(w * dt)
            q = qmul(q, dq)
            Phi = np.eye(6)
            Phi[:3, :3] = dcm(dq).T
            Phi[:3, 3:] = -R_BG * dt
            Q = np.zeros((6, 6))
            Q[:3, :3] = (arw2 * dt + su2 * dt**3 / 3) * np.eye(3)
            Q[:3, 3:] = Q[3:, :3] = -0.5 * su2 * dt**2 * R_BG
            Q[3:, 3:] = su2 * dt * np.eye(3)
            P = Phi @ P @ Phi.T + Q
            Phis[i] = Phi
        q_p[i] = q
        for h, qm in node_meas.get(node, []) if i > 0 else node_meas[node]:
            z = qlog(qmul(qconj(qmul(q, np.asarray(heads[h].q_BS, dtype=np.float64))), qm))
            H = np.zeros((3, 6))
            H[:, :3] = C_SB[h]
            S = H @ P @ H.T + np.diag(r_var[h])
            K = np.linalg.solve(S, H @ P).T
            dx = K @ z
            IKH = np.eye(6) - K @ H
            P = IKH @ P @ IKH.T + K @ np.diag(r_var[h]) @ K.T
            q = qmul(q, qexp(dx[:3]))
            q = q / np.linalg.norm(q)
            b = b + dx[3:]
        q_f[i], b_f[i], P_f[i] = q, b, P
    q_s, b_s, P_s = q_f.copy(), b_f.copy(), P_f.copy()
    for i in range(n_nodes - 2, -1, -1):
        Phi = Phis[i + 1]
        node = first + i + 1
        dt = rs.dt_s[node - 1]
        Q = np.zeros((6, 6))
        Q[:3, :3] = (arw2 * dt + su2 * dt**3 / 3) * np.eye(3)
        Q[:3, 3:] = Q[3:, :3] = -0.5 * su2 * dt**2 * R_BG
        Q[3:, 3:] = su2 * dt * np.eye(3)
        Pp = Phi @ P_f[i] @ Phi.T + Q
        C = np.linalg.solve(Pp, Phi @ P_f[i]).T
        e = np.concatenate([qlog(qmul(qconj(q_p[i + 1]), q_s[i + 1])), b_s[i + 1] - b_f[i]])
        dx = C @ e
        qq = qmul(q_f[i], qexp(dx[:3]))
        q_s[i] = qq / np.linalg.norm(qq)
        b_s[i] = b_f[i] + dx[3:]
        P_s[i] = P_f[i] + C @ (P_s[i + 1] - Pp) @ C.T
    at = rs.epoch_node - first
    sig = np.sqrt(np.einsum("kii->ki", P_s[at, :3, :3]))
    return ReferenceResult(time_tai_ns=t_all, q_IB=rotations.quat_canonical(q_s[at]), attitude_sigma_rad=sig,
                           bias_G_rad_s=b_s[at])
