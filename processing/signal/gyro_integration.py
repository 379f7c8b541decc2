"""Integration of the calibrated gyro spline between star-tracker times (000, eq. 7).

The two-pass filtered quasi-coordinates (processing.signal.two_pass_filter) give the rate as a quintic
spline; :func:`interval_rotations` integrates the MRP kinematics over it by one Dormand-Prince 5(4) step
per spline segment (the segments are split at the output times, once, by :func:`plan_substeps`), for all
segments at once (processing.attitude.mrp_kinematics), with the calibration of 000 eq. 2 applied to the
rate, and multiplies the step rotations of each output interval in order; the local error estimates are
summed per interval. :func:`interval_rate_maxima` gives the motion class of 000 without integrating.

Times are float64 seconds from any epoch; rates rad/s; quaternions scalar first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.attitude.mrp_kinematics import DP45_NODES, dp45_mrp_step, quat_cumprod, quat_product
from processing.signal.two_pass_filter import QuasiCoordinateSpline, TwoPassFilterError

__all__ = [
    "IntervalRotations",
    "SubstepPlan",
    "interval_rate_maxima",
    "interval_rotations",
    "plan_substeps",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class IntervalRotations:
    """Rotations over consecutive output intervals [t_k, t_k+1] from integrating eq. (7).

    q (K - 1, 4): rotation of the frame from t_k to t_k+1 (q(t_k+1) = q(t_k) o q_k); rotvec_rad
    (K - 1, 3) its rotation vector; valid (K - 1,) False where the interval leaves the spline or crosses
    a gap; max_rate_rad_s (K - 1,) the largest |w^| at the spline nodes inside the interval and at its
    ends; error_rad (K - 1,) the sum over the interval of the Dormand-Prince local error estimates
    (x 4: MRP to angle), a measured bound of the integration error.
    """

    q: FloatArray
    rotvec_rad: FloatArray
    valid: NDArray[np.bool_]
    max_rate_rad_s: FloatArray
    error_rad: FloatArray


@dataclass(frozen=True)
class SubstepPlan:
    """Sub-steps of the integration of a spline between output times (see :func:`plan_substeps`).

    poly (5, 3, N): rate polynomial of each sub-step in its coordinate c in [0, 1] (spline frame; axis
    before sub-step, so that each component is contiguous for the integrator);
    h_s (N,) sub-step lengths; ok (N,) inside a valid spline segment; idx (K,) sub-step index of each
    output time; t_out_s (K,); node_lo, node_hi (K - 1,): spline nodes inside each interval;
    node_rate (M, 3): the spline rate at its nodes; end_rate (K, 3): the rate at the output times.
    """

    poly: FloatArray
    h_s: FloatArray
    ok: NDArray[np.bool_]
    idx: NDArray[np.intp]
    t_out_s: FloatArray
    node_lo: NDArray[np.intp]
    node_hi: NDArray[np.intp]
    node_rate: FloatArray
    end_rate: FloatArray


def plan_substeps(spline: QuasiCoordinateSpline, t_out_s: ArrayLike) -> SubstepPlan:
    """Split the spline segments at the output times t_out_s (K,) [s] (strictly increasing) into the
    sub-steps of :func:`interval_rotations`; done once, reused for every calibration."""
    t_out = np.asarray(t_out_s, dtype=np.float64)
    if t_out.ndim != 1 or t_out.size < 2 or not np.all(np.diff(t_out) > 0):
        raise TwoPassFilterError(f"t_out_s must be (K >= 2,) strictly increasing, got shape {t_out.shape}")
    nodes = spline.t_s
    inner = nodes[(nodes > t_out[0]) & (nodes < t_out[-1])]
    points = np.union1d(inner, t_out)
    a, b = points[:-1], points[1:]
    j, _, inside = spline.locate(0.5 * (a + b))
    h_seg = nodes[j + 1] - nodes[j]
    u_a = (a - nodes[j]) / h_seg
    u_b = (b - nodes[j]) / h_seg
    ok = inside & (a >= nodes[j] - 1e-9 * h_seg) & (b <= nodes[j + 1] + 1e-9 * h_seg)
    return SubstepPlan(
        poly=np.ascontiguousarray(spline.rate_polynomial(j, u_a, u_b - u_a).transpose(0, 2, 1)), h_s=b - a, ok=ok,
        idx=np.searchsorted(points, t_out),
        t_out_s=t_out, node_lo=np.searchsorted(nodes, t_out[:-1], side="left"),
        node_hi=np.searchsorted(nodes, t_out[1:], side="right"), node_rate=spline.d1,
        end_rate=np.nan_to_num(spline.rate(t_out)),
    )


def _interval_products(kappa: FloatArray, idx: NDArray[np.intp]) -> FloatArray:
    """Ordered products of kappa[idx[k]:idx[k+1]] for every k: a pairwise tree over the padded
    (intervals, steps) array when the counts are regular, else differences of the prefix product."""
    counts = np.diff(idx)
    width = 1 << int(np.ceil(np.log2(max(int(counts.max()), 1))))
    if counts.size * width <= 2.5 * kappa.shape[0]:
        ext = np.concatenate([kappa, [[1.0, 0.0, 0.0, 0.0]]])
        pos = np.arange(width)
        gather = np.where(pos < counts[:, None], idx[:-1, None] + pos, kappa.shape[0])
        x = ext[gather]
        while x.shape[1] > 1:
            x = quat_product(x[:, 0::2], x[:, 1::2])
        return rotations.quat_normalize(x[:, 0])
    c_ext = np.concatenate([[[1.0, 0.0, 0.0, 0.0]], quat_cumprod(kappa)])
    return rotations.quat_normalize(
        rotations.quat_multiply(rotations.quat_conjugate(c_ext[idx[:-1]]), c_ext[idx[1:]])
    )


def interval_rate_maxima(
    plan: SubstepPlan, *, scale_factor_error: float = 0.0, drift: ArrayLike = (0.0, 0.0, 0.0)
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Largest calibrated rate |(w~ - drift) / (1 + m)| [rad/s] at the spline nodes inside each interval of
    the plan and at its ends (K - 1,), and whether the interval lies inside valid spline segments (the
    motion class of 000 needs no integration)."""
    b = np.asarray(drift, dtype=np.float64)
    inv = 1.0 / (1.0 + float(scale_factor_error))
    node_rate = np.append(np.linalg.norm(plan.node_rate - b, axis=-1) * inv, 0.0)  # sentinel for reduceat
    lo, hi = plan.node_lo, plan.node_hi
    bounds = np.empty(2 * lo.size, dtype=np.intp)
    bounds[0::2], bounds[1::2] = lo, hi
    max_rate = np.where(hi > lo, np.maximum.reduceat(node_rate, bounds)[0::2], 0.0)
    ends = np.linalg.norm(plan.end_rate - b, axis=-1) * inv
    bad = np.concatenate([[0], np.cumsum(~plan.ok)])
    return np.maximum(max_rate, np.maximum(ends[:-1], ends[1:])), bad[plan.idx[1:]] - bad[plan.idx[:-1]] == 0


def interval_rotations(
    spline_or_plan: QuasiCoordinateSpline | SubstepPlan,
    t_out_s: ArrayLike | None = None,
    *,
    q_GX: ArrayLike | None = None,
    scale_factor_error: float = 0.0,
    drift: ArrayLike = (0.0, 0.0, 0.0),
) -> IntervalRotations:
    """Integrate the MRP kinematics (000, eq. 7) over the calibrated spline rate between output times.

    spline_or_plan: the raw spline (gyro frame G) with t_out_s (K,) [s], or a :class:`SubstepPlan`.
    Calibration (000, eq. 2): the integrated rate is (w~ - drift) / (1 + scale_factor_error) in G,
    and the rotations are expressed in the frame X with v_G = q_GX o v_X o q_GX^-1 (q_GX = q_GS for the
    star-tracker frame A of 000) by conjugation, q_X = q_GX^-1 o q_G o q_GX (exact: rotating the rate
    by a constant rotation conjugates the solution). One Dormand-Prince 5(4) step per sub-step, all at
    once (processing.attitude.mrp_kinematics.dp45_mrp_step), then ordered products per interval.
    """
    if isinstance(spline_or_plan, SubstepPlan):
        plan = spline_or_plan
    elif t_out_s is None:
        raise TwoPassFilterError("t_out_s must be (K >= 2,) strictly increasing output times with a spline, got None")
    else:
        plan = plan_substeps(spline_or_plan, t_out_s)
    poly = plan.poly
    b = np.asarray(drift, dtype=np.float64)
    inv = 1.0 / (1.0 + float(scale_factor_error))
    # the rate at the six distinct stage nodes of every sub-step at once: one (6 x 5) @ (5 x 3N) product
    nodes = sorted(set(DP45_NODES))
    vander = np.array(nodes)[:, None] ** np.arange(5)
    stage_rates = (vander @ poly.reshape(5, -1)).reshape((len(nodes),) + poly.shape[1:])  # (6, 3, N)
    stage_rates -= b[:, None]
    stage_rates *= inv

    def rate_at(c: float) -> FloatArray:
        return stage_rates[nodes.index(c)].T  # (N, 3) view with contiguous components
    sigma, err = dp45_mrp_step(rate_at, plan.h_s)
    kappa = rotations.mrp_to_quat(sigma)
    kappa[~plan.ok] = (1.0, 0.0, 0.0, 0.0)
    q = _interval_products(kappa, plan.idx)
    if q_GX is not None:
        qx = rotations.quat_normalize(np.asarray(q_GX, dtype=np.float64))
        q = rotations.quat_multiply(rotations.quat_multiply(rotations.quat_conjugate(qx), q), qx)
    idx = plan.idx
    err_sum = np.concatenate([[0.0], np.cumsum(4.0 * err)])
    max_rate, valid = interval_rate_maxima(plan, scale_factor_error=scale_factor_error, drift=drift)
    return IntervalRotations(
        q=q, rotvec_rad=rotations.quat_to_rotvec(q), valid=valid,
        max_rate_rad_s=max_rate, error_rad=err_sum[idx[1:]] - err_sum[idx[:-1]],
    )
