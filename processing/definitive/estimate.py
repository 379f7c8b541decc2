"""Definitive attitude over a whole arc: MEKF + RTS smoother with every star-tracker head and the gyros,
the augmented calibration states, the noise levels from the data, observability and consistency.

:func:`estimate_definitive_attitude` runs ``settings.passes`` filter/smoother passes (at most; it stops
when nothing changes any more):

1. epochs: the star-tracker times of all heads (a head measured at the same time as another is one
   stacked update), plus propagation-only epochs so that no block holds more than ``max_block_steps``
   gyro steps; the gyro steps are refined onto them (processing.definitive.gyro);
2. block quantities about the reference calibration (processing.definitive.propagation; pass 1: zero bias,
   K = 0; later passes: the previous pass's smoothed bias history and calibration);
3. forward MEKF (processing.definitive.filter) and RTS smoother (processing.definitive.smoother);
4. star-tracker noise per head and sensor axis from the smoothed residuals r (those not given):
   sigma² = mean(r²) + mean(diag(H P_s H^T)) (smoothed residuals are smaller than the noise by the
   smoothed covariance they share with it, as least-squares residuals are);
5. after the last pass: NIS (per epoch, chi² with 3 x heads dof) and whiteness of the whitened
   innovations per head and axis (processing.estimation.consistency), observability of every state
   (processing.definitive.observability).

Times: int64 TAI ns; angles rad, rates rad/s; quaternions scalar first, q_IB body -> inertial.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from processing.attitude import rotations
from processing.definitive.filter import FilterModel, ForwardRun, Measurements, run_filter
from processing.definitive.gyro import GyroSteps, RefinedSteps, refine
from processing.definitive.model import (
    DefinitiveError,
    DefinitiveSettings,
    FloatArray,
    StateLayout,
    k_matrix,
    layout_for,
)
from processing.definitive.observability import Observability, observability
from processing.definitive.propagation import Blocks, block_quantities
from processing.definitive.smoother import SmoothedRun, rts_smooth
from processing.estimation.chi2 import chi2_isf
from processing.estimation.consistency import ChiSquareStats, WhitenessStats, chi_square_stats, whiteness
from processing.gyro_calibration.bias_fit import estimate_gyro_arw
from processing.units import NS_PER_S

NOISE_CHANGE_TOLERANCE = 0.05
"""Passes stop when no star-tracker sigma changed by more than this fraction and the propagation's
first-order correction is negligible."""


@dataclass(frozen=True)
class StarTrackerHead:
    """One head's samples: name, time_tai_ns (N,), q_IS (N, 4) measured, q_BS (4,) configured mounting."""

    name: str
    time_tai_ns: NDArray[np.int64]
    q_IS: FloatArray
    q_BS: FloatArray


@dataclass(frozen=True)
class DefinitiveResult:
    """Smoothed attitude and calibration of an arc (module docstring). Per epoch (E,): time_tai_ns,
    measured (a star-tracker update was used), q_IB (E, 4) and attitude_sigma_rad (E, 3) about the body
    axes (smoothed), the filtered ones, rate_B_rad_s (E, 3), bias_G_rad_s / bias_sigma_G_rad_s (E, 3) in
    the gyro frame, covariance (E, n, n) smoothed. Parameters: K (3, 3), head mountings (name ->
    (q_BS, rotvec from the configured one, sigma)), time_offset_s and sigma (None unless estimated);
    parameter_covariance (n - 6, n - 6) of (k, phi, dt) at the end of the arc. Per measurement (S,):
    time, head index, innovation (before the update) and smoothed residual (S, 3) in sensor axes, nis,
    used. Statistics: nis_stats, whiteness_stats, observability. Noise: star_tracker_sigma_rad (name ->
    (3,)) with its source, gyro_arw_rad_sqrt_s (3,) with its source, bias random walk."""

    layout: StateLayout
    time_tai_ns: NDArray[np.int64]
    measured: NDArray[np.bool_]
    q_IB: FloatArray
    attitude_sigma_rad: FloatArray
    q_IB_filtered: FloatArray
    attitude_sigma_filtered_rad: FloatArray
    rate_B_rad_s: FloatArray
    bias_G_rad_s: FloatArray
    bias_sigma_G_rad_s: FloatArray
    covariance: FloatArray
    prior_sigma: FloatArray
    K: FloatArray
    calibration: FloatArray
    parameter_covariance: FloatArray
    head_mountings: dict[str, tuple[FloatArray, FloatArray, FloatArray | None]]
    time_offset_s: float | None
    time_offset_sigma_s: float | None
    meas_time_tai_ns: NDArray[np.int64]
    meas_head: NDArray[np.intp]
    innovation_rad: FloatArray
    residual_rad: FloatArray
    nis: FloatArray
    used: NDArray[np.bool_]
    nis_epoch: FloatArray
    dof_epoch: FloatArray
    nis_stats: ChiSquareStats
    whiteness_stats: WhitenessStats
    observability: Observability
    star_tracker_sigma_rad: dict[str, FloatArray]
    star_tracker_sigma_source: dict[str, str]
    gyro_arw_rad_sqrt_s: FloatArray
    gyro_arw_source: str
    bias_random_walk_rad_s_sqrt_s: float
    q_BG: FloatArray
    gyro_kind: str
    passes: int
    max_second_order_rad: float
    notes: tuple[str, ...] = field(default=())

    @property
    def state_names(self) -> list[str]:
        return self.layout.names()

    @property
    def bias_B_rad_s(self) -> FloatArray:
        """Bias history in the body frame (E, 3): R_BG b (w_meas,B = w_B + b_B to first order)."""
        return self.bias_G_rad_s @ rotations.quat_to_dcm(self.q_BG).T


def _epochs(steps: GyroSteps, times: NDArray[np.int64], max_block: int) -> NDArray[np.int64]:
    """Star-tracker times plus gyro nodes every max_block steps inside longer blocks."""
    nodes = steps.t_ns
    idx = np.searchsorted(nodes, times)
    gap = np.diff(idx)
    long = np.flatnonzero(gap > max_block)
    fill = [nodes[idx[j] + max_block: idx[j + 1]: max_block] for j in long]
    return np.union1d(times, np.concatenate([np.zeros(0, dtype=np.int64), *fill]))


def _measurements(heads: Sequence[StarTrackerHead], steps: GyroSteps, notes: list[str]
                  ) -> tuple[NDArray[np.int64], NDArray[np.intp], FloatArray]:
    t_all, h_all, q_all = [], [], []
    for h, head in enumerate(heads):
        t = np.asarray(head.time_tai_ns, dtype=np.int64)
        q = np.asarray(head.q_IS, dtype=np.float64)
        if q.shape != (t.size, 4) or not np.all(np.isfinite(q)):
            raise DefinitiveError(f"star tracker {head.name}: quaternions must be finite (N, 4)")
        keep = (t >= steps.t_ns[0]) & (t <= steps.t_ns[-1])
        keep[1:] &= np.diff(t) > 0
        if np.count_nonzero(~keep):
            notes.append(f"{head.name}: {int(np.count_nonzero(~keep))} samples outside the gyro span or repeated "
                         "were not used")
        t_all.append(t[keep])
        h_all.append(np.full(int(keep.sum()), h, dtype=np.intp))
        q_all.append(q[keep] / np.linalg.norm(q[keep], axis=1, keepdims=True))
    t = np.concatenate(t_all)
    if t.size < 2:
        raise DefinitiveError(f"need at least 2 star-tracker samples within the gyro span, got {t.size}")
    order = np.argsort(t, kind="stable")
    return t[order], np.concatenate(h_all)[order], np.concatenate(q_all)[order]


@dataclass(frozen=True)
class _Problem:
    steps: RefinedSteps
    epochs: NDArray[np.int64]
    meas: Measurements
    meas_t: NDArray[np.int64]
    layout: StateLayout
    R_BG: FloatArray
    q_BS: FloatArray
    arw: FloatArray
    prior: FloatArray


@dataclass(frozen=True)
class _Reference:
    """The linearisation point: bias per sub-step (M, 3), K, parameters p (n - 3,) at the first epoch."""

    b_steps: FloatArray
    K: FloatArray
    p0: FloatArray


@dataclass(frozen=True)
class _Pass:
    blocks: Blocks
    run: ForwardRun
    smoothed: SmoothedRun
    sigma_filtered: FloatArray
    pref: FloatArray
    second_order: float


def _run_pass(pb: _Problem, ref: _Reference, r_var: FloatArray, s: DefinitiveSettings, gating: bool) -> _Pass:
    lay = pb.layout
    blocks = block_quantities(pb.steps, pb.R_BG, ref.K, ref.b_steps, pb.arw, s.bias_random_walk_rad_s_sqrt_s,
                              lay.calibration)
    k_ref = ref.p0[3:3 + lay.n_cal]
    pref = np.concatenate([blocks.b_ref, np.broadcast_to(k_ref, (blocks.b_ref.shape[0], lay.n_cal))], axis=1)
    gate = float(chi2_isf(s.gate_probability, 3)) if gating and s.gate_probability > 0 else 0.0
    model = FilterModel(layout=lay, q_BS=pb.q_BS, r_var=r_var, p_ref_bk=pref, p0=ref.p0,
                        P0=np.diag(pb.prior**2), gate=gate)
    run = run_filter(blocks, pb.meas, model)
    sigma_f = np.sqrt(np.einsum("kii->ki", run.P[:, :3, :3]))
    sm = rts_smooth(run, blocks, lay)
    nbk = 3 + lay.n_cal
    corr = np.einsum("kij,kj->ki", blocks.phi_top[:, :, 3:], sm.p[:, :nbk] - pref)
    second = float(0.5 * np.max(np.sum(corr**2, axis=1))) if corr.size else 0.0
    return _Pass(blocks=blocks, run=run, smoothed=sm, sigma_filtered=sigma_f, pref=pref, second_order=second)


def _mountings(pb: _Problem, p: FloatArray) -> FloatArray:
    """Current q_BS (H, 4) with the estimated mounting corrections."""
    q = pb.q_BS.copy()
    for h in range(1, q.shape[0]):
        sl = pb.layout.mount(h)
        if sl is not None:
            q[h] = rotations.quat_multiply(q[h], rotations.rotvec_to_quat(p[sl.start - 3:sl.stop - 3]))
    return q


def _residuals(pb: _Problem, ps: _Pass) -> tuple[FloatArray, FloatArray]:
    """Smoothed residuals (S, 3) in sensor axes and the sensor-axis variances of H P_s H^T (S, 3)."""
    sm, lay, meas = ps.smoothed, pb.layout, pb.meas
    p_end = sm.p[-1]
    q_BS = _mountings(pb, p_end)[meas.head]
    j = meas.epoch
    q = sm.q[j]
    if lay.dt is not None:
        q = rotations.quat_multiply(q, rotations.rotvec_to_quat(ps.blocks.rate_B[j] * sm.p[j, lay.dt - 3, None]))
    pred = rotations.quat_multiply(q, q_BS)
    r = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(pred), meas.q_IS))
    C_SB = np.swapaxes(rotations.quat_to_dcm(q_BS), 1, 2)
    hph = np.einsum("kia,kab,kib->ki", C_SB, sm.P[j, :3, :3], C_SB)
    return r, hph


def _noise_update(pb: _Problem, ps: _Pass, fixed: dict[int, FloatArray], r_var: FloatArray) -> FloatArray:
    r, hph = _residuals(pb, ps)
    out = r_var.copy()
    used = ps.run.used
    for h in range(r_var.shape[0]):
        if h in fixed:
            continue
        sel = (pb.meas.head == h) & used
        if np.count_nonzero(sel) >= 10:
            out[h] = np.mean(r[sel] ** 2, axis=0) + np.mean(hph[sel], axis=0)
    return out


def _next_reference(pb: _Problem, ps: _Pass) -> _Reference:
    sm, lay, steps = ps.smoothed, pb.layout, pb.steps
    t_epoch = steps.t_s[steps.epoch_node]
    t_mid = 0.5 * (steps.t_s[:-1] + steps.t_s[1:])
    b = np.stack([np.interp(t_mid, t_epoch, sm.p[:, i]) for i in range(3)], axis=-1)
    p0 = sm.p[0].copy()
    p0[3:] = sm.p[-1, 3:]  # constants: the estimate with all the data
    return _Reference(b_steps=b, K=k_matrix(p0[3:3 + lay.n_cal], lay), p0=p0)


def _arw(steps: GyroSteps, s: DefinitiveSettings) -> tuple[FloatArray, str]:
    if s.gyro_arw_rad_sqrt_s is not None:
        arw = np.broadcast_to(np.asarray(s.gyro_arw_rad_sqrt_s, dtype=np.float64), (3,)).copy()
        if np.any(arw <= 0) or not np.all(np.isfinite(arw)):
            raise DefinitiveError(f"gyro_arw_rad_sqrt_s must be > 0, got {s.gyro_arw_rad_sqrt_s!r}")
        return arw, "given"
    t = (steps.sample_t_ns - steps.sample_t_ns[0]).astype(np.float64) / NS_PER_S
    arw = estimate_gyro_arw(t, steps.rate_samples_G)
    return np.maximum(arw, 1e-12), "estimated from the second differences of the gyro rates"


def _problem(steps: GyroSteps, heads: Sequence[StarTrackerHead], q_BG: FloatArray, s: DefinitiveSettings,
             notes: list[str]) -> _Problem:
    if not heads:
        raise DefinitiveError("no star-tracker head given")
    meas_t, meas_h, meas_q = _measurements(heads, steps, notes)
    epochs = _epochs(steps, np.unique(meas_t), s.max_block_steps)
    e_idx = np.searchsorted(epochs, meas_t).astype(np.intp)
    ptr = np.searchsorted(e_idx, np.arange(epochs.size + 1)).astype(np.intp)
    layout = layout_for(tuple(h.name for h in heads), s)
    refined = refine(steps, epochs)
    arw, _ = _arw(steps, s)
    return _Problem(steps=refined, epochs=epochs, meas=Measurements(e_idx, meas_h, meas_q, ptr), meas_t=meas_t,
                    layout=layout, R_BG=rotations.quat_to_dcm(np.asarray(q_BG, dtype=np.float64)),
                    q_BS=np.stack([np.asarray(h.q_BS, dtype=np.float64) for h in heads]), arw=arw,
                    prior=layout.prior_sigmas(s))


def estimate_definitive_attitude(steps: GyroSteps, heads: Sequence[StarTrackerHead], q_BG: FloatArray,
                                 settings: DefinitiveSettings | None = None,
                                 progress: Callable[[float, str], None] | None = None) -> DefinitiveResult:
    """Smoothed attitude, bias history and calibration of an arc (module docstring)."""
    s = settings or DefinitiveSettings()
    report = progress or (lambda f, stage: None)
    notes = list(steps.notes)
    pb = _problem(steps, heads, q_BG, s, notes)
    fixed = {h: np.asarray(s.star_tracker_sigma_rad[hd.name], dtype=np.float64) ** 2
             for h, hd in enumerate(heads) if hd.name in s.star_tracker_sigma_rad}
    r_var = np.stack([fixed.get(h, np.asarray(s.initial_star_tracker_sigma_rad) ** 2) for h in range(len(heads))])
    ref = _Reference(b_steps=np.zeros(3), K=np.zeros((3, 3)), p0=np.zeros(pb.layout.n_param))
    ps: _Pass | None = None
    passes = 0
    for k in range(s.passes):
        report(0.05 + 0.8 * k / s.passes, f"pass {k + 1}: filter and smoother")
        # no gating while the noise is still a guess: a wrong guess must not reject good samples
        ps = _run_pass(pb, ref, r_var, s, gating=k > 0 or len(fixed) == len(heads))
        passes = k + 1
        new_var = _noise_update(pb, ps, fixed, r_var)
        change = float(np.max(np.abs(np.sqrt(new_var / r_var) - 1.0)))
        small = ps.second_order < 1e-3 * float(np.sqrt(r_var.min()))
        if k + 1 < s.passes and (change > NOISE_CHANGE_TOLERANCE or not small):
            r_var = new_var
            ref = _next_reference(pb, ps)
            continue
        if change > NOISE_CHANGE_TOLERANCE:
            notes.append(f"the star-tracker noise re-estimated after the last pass differs from the one used by up to "
                         f"{100 * change:.0f} %: more passes would change the result")
        break
    assert ps is not None
    report(0.9, "consistency and observability")
    return _result(pb, ps, r_var, fixed, s, heads, q_BG, steps, passes, notes)


def _result(pb: _Problem, ps: _Pass, r_var: FloatArray, fixed: dict[int, FloatArray], s: DefinitiveSettings,
            heads: Sequence[StarTrackerHead], q_BG: FloatArray, steps: GyroSteps, passes: int,
            notes: list[str]) -> DefinitiveResult:
    lay, sm, run = pb.layout, ps.smoothed, ps.run
    P = sm.P
    resid, _ = _residuals(pb, ps)
    obs = observability(P[0], pb.prior, s.observability_threshold)
    n_h = len(heads)
    white = np.full((pb.epochs.size, 3 * n_h), np.nan)
    for h in range(n_h):
        sel = pb.meas.head == h
        white[pb.meas.epoch[sel], 3 * h:3 * h + 3] = run.whitened[sel]
    white_stats = whiteness(white, max_lag=20)
    p_end = sm.p[-1]
    q_now = _mountings(pb, p_end)
    mounts: dict[str, tuple[FloatArray, FloatArray, FloatArray | None]] = {}
    for h, hd in enumerate(heads):
        sl = lay.mount(h)
        rv = np.zeros(3) if sl is None else p_end[sl.start - 3:sl.stop - 3].copy()
        sig = None if sl is None else np.sqrt(np.diag(P[-1, sl, sl]))
        mounts[hd.name] = (rotations.quat_canonical(q_now[h]), rv, sig)
    dt_i = lay.dt
    arw, arw_source = _arw(steps, s)
    measured = np.zeros(pb.epochs.size, dtype=bool)
    measured[pb.meas.epoch[run.used]] = True
    if np.count_nonzero(~run.used):
        notes.append(f"{int(np.count_nonzero(~run.used))} star-tracker samples rejected by the innovation gate")
    return DefinitiveResult(
        layout=lay, time_tai_ns=pb.epochs, measured=measured, q_IB=rotations.quat_canonical(sm.q),
        attitude_sigma_rad=np.sqrt(np.einsum("kii->ki", P[:, :3, :3])),
        q_IB_filtered=rotations.quat_canonical(run.q_filt), attitude_sigma_filtered_rad=ps.sigma_filtered,
        rate_B_rad_s=ps.blocks.rate_B, bias_G_rad_s=sm.p[:, 0:3].copy(),
        bias_sigma_G_rad_s=np.sqrt(np.einsum("kii->ki", P[:, 3:6, 3:6])), covariance=P, prior_sigma=pb.prior,
        K=k_matrix(p_end[3:3 + lay.n_cal], lay), calibration=p_end[3:3 + lay.n_cal].copy(),
        parameter_covariance=P[-1, 6:, 6:].copy(), head_mountings=mounts,
        time_offset_s=None if dt_i is None else float(p_end[dt_i - 3]),
        time_offset_sigma_s=None if dt_i is None else float(np.sqrt(P[-1, dt_i, dt_i])),
        meas_time_tai_ns=pb.meas_t, meas_head=pb.meas.head, innovation_rad=run.innovation, residual_rad=resid,
        nis=run.nis, used=run.used, nis_epoch=run.nis_epoch, dof_epoch=run.dof_epoch,
        nis_stats=chi_square_stats(run.nis_epoch, run.dof_epoch), whiteness_stats=white_stats, observability=obs,
        star_tracker_sigma_rad={hd.name: np.sqrt(r_var[h]) for h, hd in enumerate(heads)},
        star_tracker_sigma_source={hd.name: "given" if h in fixed else "estimated from the smoothed residuals"
                                   for h, hd in enumerate(heads)},
        gyro_arw_rad_sqrt_s=arw, gyro_arw_source=arw_source,
        bias_random_walk_rad_s_sqrt_s=s.bias_random_walk_rad_s_sqrt_s,
        q_BG=np.asarray(q_BG, dtype=np.float64), gyro_kind=steps.kind, passes=passes,
        max_second_order_rad=ps.second_order, notes=tuple(notes),
    )
