"""Backward pass: the Rauch-Tung-Striebel smoother over the forward MEKF run (Rauch, Tung & Striebel 1965;
for the multiplicative error state Crassidis & Junkins, Optimal Estimation of Dynamic Systems, 2nd ed.,
§5.5 and §7.2):

    C_j   = P_j|j Phi_j+1^T P_j+1|j^-1
    x_j|N = x_j|j (+) C_j (x_j+1|N (-) x_j+1|j)
    P_j|N = P_j|j + C_j (P_j+1|N - P_j+1|j) C_j^T

with (+)/(-) the attitude error rotation (x (-) y = rotvec(q_y^-1 o q_x)) and plain differences for the
parameters. Memory: only the filtered covariances are stored by the forward pass (and overwritten in place
by the smoothed ones); P_j+1|j = Phi P_j|j Phi^T + Q and the gains are recomputed here in chunks of
``CHUNK`` epochs, vectorised, so the peak stays near one (E, n, n) array.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from processing.definitive.filter import ForwardRun, qconj, qexp, qlog, qmul
from processing.definitive.model import FloatArray, StateLayout
from processing.definitive.propagation import Blocks

CHUNK = 2048


@dataclass(frozen=True)
class SmoothedRun:
    """Smoothed q_IB (E, 4), parameters p (E, n-3) and covariances P (E, n, n) (the forward run's array,
    overwritten)."""

    q: FloatArray
    p: FloatArray
    P: FloatArray


def _full_phi(blocks: Blocks, lo: int, hi: int, n: int) -> FloatArray:
    phi = np.broadcast_to(np.eye(n), (hi - lo, n, n)).copy()
    m = blocks.phi_top.shape[2]
    phi[:, :3, :m] = blocks.phi_top[lo:hi]
    return phi


def rts_smooth(run: ForwardRun, blocks: Blocks, layout: StateLayout) -> SmoothedRun:
    """Smooth ``run`` in place of its covariances (module docstring)."""
    E, n = run.q_filt.shape[0], layout.n
    P = run.P
    q_s = np.empty_like(run.q_filt)
    p_s = np.empty_like(run.p_filt)
    q_s[-1], p_s[-1] = run.q_filt[-1], run.p_filt[-1]
    hi = E - 1
    while hi > 0:
        lo = max(0, hi - CHUNK)
        # epochs j = lo..hi-1 use Phi_{j+1}, Q_{j+1} and P_j|j
        phi = _full_phi(blocks, lo + 1, hi + 1, n)
        pf = P[lo:hi].copy()
        pp = phi @ pf @ np.swapaxes(phi, 1, 2)
        pp[:, :6, :6] += blocks.q6[lo + 1:hi + 1]
        C = np.swapaxes(np.linalg.solve(pp, phi @ pf), 1, 2)  # P_f Phi^T P_p^-1 (P_p symmetric)
        dP = pf - C @ pp @ np.swapaxes(C, 1, 2)
        for j in range(hi - 1, lo - 1, -1):
            k = j - lo
            Cj = C[k]
            e = np.empty(n)
            e[0:3] = qlog(qmul(qconj(run.q_pred[j + 1]), q_s[j + 1]))
            e[3:] = p_s[j + 1] - run.p_filt[j]
            dx = Cj @ e
            q = qmul(run.q_filt[j], qexp(dx[0:3]))
            q_s[j] = q / np.sqrt(q @ q)
            p_s[j] = run.p_filt[j] + dx[3:]
            P[j] = dP[k] + Cj @ P[j + 1] @ Cj.T
        hi = lo
    for a in range(0, E, CHUNK):  # symmetrise in chunks (no second (E, n, n) array)
        P[a:a + CHUNK] = 0.5 * (P[a:a + CHUNK] + np.swapaxes(P[a:a + CHUNK], 1, 2))
    return SmoothedRun(q=q_s, p=p_s, P=P)
