"""Rauch-Tung-Striebel fixed-interval smoother for the gyroless filters (post-processing of 004).

What a ground service can do that the on-board filter of 004 cannot: use the measurements after
each instant too. Backward pass over a :class:`processing.gyroless.filtering.FilterRun` (Rauch, Tung &
Striebel 1965; for the multiplicative error state e.g. Crassidis & Junkins, Optimal Estimation of
Dynamic Systems, 2nd ed., §5.5 and §7.2):

    C_k   = P_k|k Phi_k+1^T P_k+1|k^-1
    x_k|N = x_k|k (+) C_k (x_k+1|N (-) x_k+1|k)
    P_k|N = P_k|k + C_k (P_k+1|N - P_k+1|k) C_k^T

with (+)/(-) the filter's own error coordinates (additive for the 9-state EKF of 004, the
3-component multiplicative attitude error for the MEKF), so the attitude stays a unit quaternion.
The same Phi as the forward pass is used (the linearisation about the filtered trajectory).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.gyroless.filtering import FILTERS, FilterRun, covariance_sigmas

__all__ = ["SmoothedRun", "rts_smooth"]


@dataclass(frozen=True)
class SmoothedRun:
    """Smoothed states x (K, 9) = (w_BI^B, q_OB, tau_d,x, tau_d,y), covariances P (K, n, n) in the
    filter's error coordinates, 1-sigma attitude (about the B axes, rad) and rate (rad/s) (K, 3)."""

    kind: str
    t_s: NDArray
    x: NDArray
    P: NDArray
    attitude_sigma_rad: NDArray
    rate_sigma_rad_s: NDArray

    @property
    def q_OB(self) -> NDArray:
        return self.x[:, 3:7]

    @property
    def omega_BI_B(self) -> NDArray:
        return self.x[:, 0:3]

    @property
    def tau_d_O(self) -> NDArray:
        return self.x[:, 7:9]


def rts_smooth(run: FilterRun) -> SmoothedRun:
    """Smooth a forward filter pass (any kind); returns :class:`SmoothedRun` on the same steps."""
    cls = FILTERS[run.kind]
    K = run.x_filt.shape[0]
    x_s = np.empty_like(run.x_filt)
    P_s = np.empty_like(run.P_filt)
    if K == 0:
        return SmoothedRun(run.kind, run.t_s, x_s, P_s, np.empty((0, 3)), np.empty((0, 3)))
    x_s[-1], P_s[-1] = run.x_filt[-1], run.P_filt[-1]
    # Gains for all steps at once (they do not depend on the smoothed values):
    # C_k = P_k|k Phi_k+1^T P_k+1|k^-1  <=>  C_k^T = P_k+1|k^-1 (Phi_k+1 P_k|k)
    C = np.swapaxes(np.linalg.solve(run.P_pred[1:], run.Phi[1:] @ run.P_filt[:-1]), -1, -2)
    dP = run.P_filt[:-1] - C @ run.P_pred[1:] @ np.swapaxes(C, -1, -2)  # P_f - C P_p C^T
    error_between, apply_error = cls.error_between, cls.apply_error
    x_filt, x_pred = run.x_filt, run.x_pred
    for k in range(K - 2, -1, -1):
        Ck = C[k]
        x_s[k] = apply_error(x_filt[k], Ck @ error_between(x_s[k + 1], x_pred[k + 1]))
        P_s[k] = dP[k] + Ck @ P_s[k + 1] @ Ck.T
    P_s = 0.5 * (P_s + np.swapaxes(P_s, -1, -2))
    att, rate = covariance_sigmas(run.kind, x_s, P_s)
    return SmoothedRun(kind=run.kind, t_s=run.t_s, x=x_s, P=P_s, attitude_sigma_rad=att, rate_sigma_rad_s=rate)
