"""Gyro telemetry as contiguous angle increments, and their refinement onto the filter epochs.

Rates (stream ``gyro``) at times t_i become trapezoid increments over (t_{i-1}, t_i] (the rate taken as
linear between samples, as gyro_bias_fit's scheme 2 does); increments (stream ``gyro_increments``) are
used as they come, each over (t_i - interval_i, t_i]. Gaps up to ``max_gap_s`` are bridged (rates: by the
linear interpolation the trapezoid implies; increments: at the mean rate of the two neighbours); a longer
gap is an error (split the window there).

:func:`refine` inserts the filter epochs (star-tracker times) as nodes: a step split by an epoch is
divided by the linearly interpolated rate (rates) or in proportion to time (increments, constant rate
within the interval), so that every epoch is a node and every block between epochs is a run of whole
sub-steps (processing.definitive.propagation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.definitive.model import DefinitiveError, FloatArray
from processing.units import NS_PER_S

GAP_FACTOR = 2.5
"""A step longer than this many median steps is a gap (noted; bridged up to max_gap_s)."""


@dataclass(frozen=True)
class GyroSteps:
    """Angle increments in the configured gyro frame G on a contiguous grid: node times t_ns (M+1,) int64,
    da_G (M, 3) rad over (t_{k-1}, t_k]; rate_G (M+1, 3) rad/s at the nodes for rate telemetry (None for
    increments); kind "rates" or "increments"; rate_samples_G: the measured rates (for the noise estimate,
    (N, 3)) and their times; notes on gaps bridged."""

    t_ns: NDArray[np.int64]
    da_G: FloatArray
    rate_G: FloatArray | None
    kind: str
    sample_t_ns: NDArray[np.int64]
    rate_samples_G: FloatArray
    notes: tuple[str, ...] = ()

    @property
    def n_samples(self) -> int:
        return int(self.sample_t_ns.size)


def _check_times(t: NDArray[np.int64], what: str) -> None:
    if t.ndim != 1 or t.size < 3:
        raise DefinitiveError(f"need at least 3 {what} samples, got {t.size}")
    if np.any(np.diff(t) <= 0):
        raise DefinitiveError(f"{what} times must increase; {int(np.sum(np.diff(t) <= 0))} repeated or "
                              "decreasing time stamps")


def _gap_note(dt_s: FloatArray, max_gap_s: float, what: str) -> tuple[str, ...]:
    step = float(np.median(dt_s))
    gaps = dt_s > GAP_FACTOR * step
    if not np.any(gaps):
        return ()
    longest = float(dt_s.max())
    if longest > max_gap_s:
        raise DefinitiveError(f"{what} gap of {longest:.3g} s exceeds max_gyro_gap_s = {max_gap_s} s; split the "
                              "window at the gap")
    return (f"{int(np.sum(gaps))} {what} gaps (longest {longest:.3g} s) bridged",)


def from_rates(t_ns: NDArray[np.int64], w_G: FloatArray, max_gap_s: float) -> GyroSteps:
    """Trapezoid increments of rate samples w_G (N, 3) rad/s at t_ns (N,)."""
    t = np.asarray(t_ns, dtype=np.int64)
    w = np.asarray(w_G, dtype=np.float64)
    _check_times(t, "gyro")
    if w.shape != (t.size, 3) or not np.all(np.isfinite(w)):
        raise DefinitiveError(f"gyro rates must be finite (N, 3) = ({t.size}, 3), got shape {w.shape}")
    dt = np.diff(t).astype(np.float64) / NS_PER_S
    notes = _gap_note(dt, max_gap_s, "gyro")
    da = 0.5 * (w[:-1] + w[1:]) * dt[:, None]
    return GyroSteps(t_ns=t, da_G=da, rate_G=w, kind="rates", sample_t_ns=t, rate_samples_G=w, notes=notes)


def from_increments(t_end_ns: NDArray[np.int64], da_G: FloatArray, interval_s: FloatArray,
                    max_gap_s: float) -> GyroSteps:
    """Increments da_G (N, 3) rad over (t_end - interval, t_end]; gaps between intervals are bridged at the
    mean rate of the neighbouring intervals."""
    t_end = np.asarray(t_end_ns, dtype=np.int64)
    da = np.asarray(da_G, dtype=np.float64)
    iv = np.asarray(interval_s, dtype=np.float64)
    _check_times(t_end, "gyro_increments")
    if da.shape != (t_end.size, 3) or iv.shape != (t_end.size,) or not (np.all(np.isfinite(da))
                                                                       and np.all(np.isfinite(iv))):
        raise DefinitiveError("gyro increments must be finite (N, 3) with interval_s (N,)")
    if np.any(iv <= 0):
        raise DefinitiveError(f"interval_s must be > 0, got min {iv.min():g}")
    iv_ns = np.round(iv * NS_PER_S).astype(np.int64)
    start = t_end - iv_ns
    tol = np.maximum(iv_ns // 100, 1)
    gap_ns = start[1:] - t_end[:-1]
    gaps = gap_ns > tol[1:]
    rates = da / iv[:, None]
    notes: tuple[str, ...] = ()
    if np.any(gaps):
        longest = float(gap_ns[gaps].max()) / NS_PER_S
        if longest > max_gap_s:
            raise DefinitiveError(f"gyro_increments gap of {longest:.3g} s exceeds max_gyro_gap_s = {max_gap_s} s; "
                                  "split the window at the gap")
        notes = (f"{int(np.sum(gaps))} gyro_increments gaps (longest {longest:.3g} s) bridged at the neighbours' "
                 "mean rate",)
    nodes = [t_end[:1] - iv_ns[:1], t_end]
    incs = [da]
    if np.any(gaps):  # bridging steps (prev end, next start]
        g = np.flatnonzero(gaps)
        bridge_rate = 0.5 * (rates[g] + rates[g + 1])
        nodes.append(start[g + 1])
        incs.append(bridge_rate * (gap_ns[g].astype(np.float64) / NS_PER_S)[:, None])
    t_nodes = np.concatenate(nodes)
    inc = np.concatenate(incs)
    order = np.argsort(t_nodes[1:], kind="stable")
    t_sorted = np.concatenate([t_nodes[:1], t_nodes[1:][order]])
    if np.any(np.diff(t_sorted) <= 0):
        raise DefinitiveError("gyro_increments intervals overlap: each interval must start at or after the end of "
                              "the previous one")
    return GyroSteps(t_ns=t_sorted, da_G=inc[order], rate_G=None, kind="increments", sample_t_ns=t_end,
                     rate_samples_G=rates, notes=notes)


@dataclass(frozen=True)
class RefinedSteps:
    """Sub-steps after inserting the epochs: node times t_s (M+1,) float s from t0_ns, dt_s (M,),
    da_G (M, 3) increments, epoch_node (E,) the node index of each epoch."""

    t0_ns: int
    t_s: FloatArray
    dt_s: FloatArray
    da_G: FloatArray
    epoch_node: NDArray[np.intp]


def refine(steps: GyroSteps, epoch_ns: NDArray[np.int64]) -> RefinedSteps:
    """Insert epoch times (E,) int64, inside [t_ns[0], t_ns[-1]], as nodes (see the module docstring)."""
    t = steps.t_ns
    e = np.asarray(epoch_ns, dtype=np.int64)
    if e.size and (e[0] < t[0] or e[-1] > t[-1]):
        raise DefinitiveError("filter epochs must lie within the gyro time span")
    new = np.setdiff1d(e, t, assume_unique=False)
    nodes = np.union1d(t, new)
    step_of = np.searchsorted(t, nodes[1:], side="left")  # original step k (1..M) containing sub-step end
    t0 = int(nodes[0])
    t_s = (nodes - t0).astype(np.float64) / NS_PER_S
    dt = np.diff(t_s)
    if steps.rate_G is not None:
        w = np.stack([np.interp(t_s, (t - t0).astype(np.float64) / NS_PER_S, steps.rate_G[:, i]) for i in range(3)],
                     axis=-1)
        da = 0.5 * (w[:-1] + w[1:]) * dt[:, None]
    else:
        full = np.diff((t - t0).astype(np.float64) / NS_PER_S)
        da = steps.da_G[step_of - 1] * (dt / full[step_of - 1])[:, None]
    epoch_node = np.searchsorted(nodes, e).astype(np.intp)
    return RefinedSteps(t0_ns=t0, t_s=t_s, dt_s=dt, da_G=da, epoch_node=epoch_node)
