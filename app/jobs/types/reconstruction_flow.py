"""What flows between the stages of the ``reconstruction`` pipeline (app/jobs/types/reconstruction.py): the
screened streams (data_screening's rejections removed, rejected gyro rates bridged) and the gyro rates with
gyro_bias_fit's bias removed."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from processing.attitude import rotations
from processing.samples import sensor_index
from processing.screening.flags import filter_streams
from processing.spacecraft import Spacecraft
from processing.tasks import TaskResult
from processing.units import NS_PER_S


def apply_screening(streams: Mapping[str, Mapping[str, NDArray[Any]]],
                    result: TaskResult, *, bridge_gyro_s: float | None = None
                    ) -> tuple[dict[str, dict[str, NDArray[Any]]], dict[str, int]]:
    """Remove the samples data_screening's ``flags`` table rejects, with the runner's mechanism
    (:func:`processing.screening.flags.filter_streams`: rows matched by stream, sensor, key and time).

    bridge_gyro_s: rejected gyro rates are not removed but replaced by the linear interpolation of the
    accepted neighbours (of the same sensor) where those are at most this far apart, so that rejections do
    not open gaps in the integrated rates; longer holes are removed (a real gap). Returns the screened
    streams and the removed samples per stream (streams without removals left out; bridged gyro samples
    count under ``gyro_bridged``); without a ``flags`` table nothing is removed."""
    flags = result.tables.get("flags")
    if flags is None:
        return {k: dict(v) for k, v in streams.items()}, {}
    screened = filter_streams(streams, flags)
    bridged = 0
    if bridge_gyro_s is not None and "gyro" in streams:
        screened["gyro"], bridged = _bridge_gyro(streams["gyro"], screened.get("gyro"), bridge_gyro_s)
    removed = {n: len(cols["time_tai_ns"]) - (len(screened[n]["time_tai_ns"]) if n in screened else 0)
               for n, cols in streams.items()}
    out = {n: c for n, c in removed.items() if c}
    if bridged:
        out["gyro_bridged"] = bridged
    return screened, out


def _bridge_gyro(raw: Mapping[str, NDArray[Any]], kept: Mapping[str, NDArray[Any]] | None,
                 max_s: float) -> tuple[dict[str, NDArray[Any]], int]:
    """The gyro rows with rejected rates interpolated from the accepted ones where the accepted neighbours are
    at most max_s apart (the others removed); (columns, number bridged)."""
    t = np.asarray(raw["time_tai_ns"], dtype=np.int64)
    sensors, index = sensor_index(raw["sensor"])
    kt = np.zeros(0, np.int64) if kept is None else np.asarray(kept["time_tai_ns"], dtype=np.int64)
    kept_sensors, kept_index = ([], np.zeros(0, np.intp)) if kept is None else sensor_index(kept["sensor"])
    keep = np.zeros(t.size, dtype=bool)
    values = {c: np.asarray(raw[c], dtype=np.float64).copy() for c in ("wx", "wy", "wz")}
    n_bridged = 0
    for code, name in enumerate(sensors):
        rows = np.flatnonzero(index == code)
        rows = rows[np.argsort(t[rows], kind="stable")]
        k = kept_sensors.index(name) if name in kept_sensors else -1
        acc_t = np.sort(kt[kept_index == k])
        accepted = _in_sorted(t[rows], acc_t)
        keep[rows[accepted]] = True
        rej = rows[~accepted]
        if rej.size == 0 or acc_t.size < 2:
            continue
        i = np.searchsorted(acc_t, t[rej])
        inside = (i > 0) & (i < acc_t.size)
        span = acc_t[np.minimum(i, acc_t.size - 1)] - acc_t[np.maximum(i - 1, 0)]
        ok = inside & (span <= max_s * NS_PER_S)
        good = rows[accepted]
        for c in values:
            values[c][rej[ok]] = np.interp(t[rej[ok]], t[good], values[c][good])
        keep[rej[ok]] = True
        n_bridged += int(ok.sum())
    out = {k: np.asarray(v)[keep] for k, v in raw.items()}
    for c in values:
        out[c] = values[c][keep]
    return out, n_bridged


def _in_sorted(x: NDArray[np.int64], sorted_values: NDArray[np.int64]) -> NDArray[np.bool_]:
    """``np.isin(x, sorted_values)`` for a sorted right-hand side, by binary search (no sort of both)."""
    if sorted_values.size == 0:
        return np.zeros(x.shape, dtype=bool)
    i = np.minimum(np.searchsorted(sorted_values, x), sorted_values.size - 1)
    return np.asarray(sorted_values[i] == x)


def correct_gyro_bias(gyro: Mapping[str, NDArray[Any]], bias_B: NDArray[np.float64],
                      spacecraft: Spacecraft) -> dict[str, NDArray[Any]]:
    """Gyro rates in the gyro frame with a body-frame bias removed: w_G - R(q_BG)^T b_B (rad/s)."""
    b_G = rotations.quat_rotate(rotations.quat_conjugate(spacecraft.gyro_mounting()), bias_B)
    out = dict(gyro)
    for i, c in enumerate(("wx", "wy", "wz")):
        out[c] = np.asarray(gyro[c], dtype=np.float64) - b_G[i]
    return out


def bias_from(summary: Mapping[str, Any]) -> NDArray[np.float64] | None:
    value = summary.get("gyro_bias_rad_s")
    try:
        bias = np.asarray(value, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        return None
    return bias if np.all(np.isfinite(bias)) else None
