"""Gyro offsets on sub-intervals (003 §2.4, figs. 15-16): the fit of processing.gyro_calibration.bias_fit
repeated on halves, quarters and sliding windows, to see whether the offsets drift.

Times float64 seconds from any epoch; quaternions scalar first.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.gyro_calibration.bias_fit import GyroBiasFit, GyroBiasFitError, fit_gyro_bias

__all__ = ["fit_subintervals", "subinterval_edges"]

FloatArray = NDArray[np.float64]


def subinterval_edges(
    start_s: float,
    end_s: float,
    *,
    splits: Sequence[int] = (2, 4),
    window_s: float | None = None,
    step_s: float | None = None,
) -> FloatArray:
    """(K, 2) [start, end] s of sub-intervals: each n in ``splits`` cuts [start, end] into n equal parts
    (003 §2.4: halves, quarters), then sliding windows of window_s every step_s (default window_s/2)."""
    if end_s <= start_s:
        raise GyroBiasFitError(f"end_s must exceed start_s, got [{start_s}, {end_s}]")
    parts = []
    for n in splits:
        if int(n) < 1:
            raise GyroBiasFitError(f"splits must be >= 1, got {n}")
        e = np.linspace(start_s, end_s, int(n) + 1)
        parts.append(np.column_stack([e[:-1], e[1:]]))
    if window_s is not None:
        step = window_s / 2.0 if step_s is None else step_s
        if window_s <= 0 or step <= 0:
            raise GyroBiasFitError(f"window_s and step_s must be > 0, got {window_s}, {step}")
        starts = np.arange(start_s, end_s - window_s + 1e-9 * window_s, step)
        parts.append(np.column_stack([starts, starts + window_s]))
    return np.concatenate(parts) if parts else np.zeros((0, 2))


def fit_subintervals(
    t_gyro_s: ArrayLike,
    w_G: ArrayLike,
    t_st_s: ArrayLike,
    q_IS: ArrayLike,
    edges_s: ArrayLike,
    *,
    q_RS: ArrayLike | None = None,
    sensor_index: ArrayLike | None = None,
    min_samples: int = 10,
    **kwargs: object,
) -> list[GyroBiasFit | None]:
    """:func:`fit_gyro_bias` on each [start, end] row of edges_s (K, 2) s (003 §2.4, offsets drifting).

    Star-tracker samples with start <= t <= end are used; a sub-interval with fewer than min_samples of
    them gives None. Other keyword arguments go to :func:`fit_gyro_bias` (pass gyro_arw_rad_sqrt_s so that
    every sub-interval uses the same noise level).
    """
    ts = np.asarray(t_st_s, dtype=np.float64)
    qm = np.asarray(q_IS, dtype=np.float64)
    m = ts.size
    q_rs = None if q_RS is None else np.broadcast_to(np.asarray(q_RS, dtype=np.float64), (m, 4))
    sens = None if sensor_index is None else np.asarray(sensor_index)
    out: list[GyroBiasFit | None] = []
    for a, b in np.asarray(edges_s, dtype=np.float64).reshape(-1, 2):
        sel = (ts >= a) & (ts <= b)
        if np.count_nonzero(sel) < min_samples:
            out.append(None)
            continue
        out.append(
            fit_gyro_bias(
                t_gyro_s, w_G, ts[sel], qm[sel],
                q_RS=None if q_rs is None else q_rs[sel],
                sensor_index=None if sens is None else sens[sel],
                **kwargs,  # type: ignore[arg-type]
            )
        )
    return out
