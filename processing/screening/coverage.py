"""Telemetry coverage and gaps of a sampled stream.

A gap is a pair of consecutive samples further apart than ``factor`` times the nominal sampling
period (the median interval unless given). It is reported by the last sample before and the first
sample after it, and the number of samples missing at the nominal rate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.tasks import TaskError


@dataclass(frozen=True)
class Gaps:
    """Gaps of one series; times in TAI ns."""

    nominal_period_ns: int
    before_tai_ns: NDArray[np.int64]  # last sample before each gap
    after_tai_ns: NDArray[np.int64]  # first sample after each gap
    missing: NDArray[np.int64]  # samples missing at the nominal rate

    @property
    def count(self) -> int:
        return len(self.before_tai_ns)

    @property
    def duration_ns(self) -> NDArray[np.int64]:
        return self.after_tai_ns - self.before_tai_ns


def nominal_period_ns(t_tai_ns: NDArray[np.int64]) -> int:
    """Median sampling interval (ns) of sorted times; TaskError with fewer than two samples."""
    t = np.asarray(t_tai_ns, dtype=np.int64)
    if t.size < 2:
        raise TaskError(f"need at least 2 samples to find the sampling period, got {t.size}")
    return int(np.median(np.diff(t)))


def find_gaps(t_tai_ns: NDArray[np.int64], *, period_ns: int | None = None, factor: float = 1.5) -> Gaps:
    """Gaps of a sorted time series.

    t_tai_ns: (N,) increasing int64 TAI ns. period_ns: nominal sampling period (default: median
    interval). factor: an interval longer than factor * period is a gap (> 1).
    """
    if factor <= 1.0:
        raise TaskError(f"gap factor must be > 1, got {factor}")
    t = np.asarray(t_tai_ns, dtype=np.int64)
    period = nominal_period_ns(t) if period_ns is None else int(period_ns)
    if period <= 0:
        raise TaskError(f"sampling period must be positive, got {period} ns")
    dt = np.diff(t)
    idx = np.flatnonzero(dt > factor * period)
    missing = np.rint(dt[idx] / period).astype(np.int64) - 1
    return Gaps(period, t[idx], t[idx + 1], np.maximum(missing, 0))
