"""Per-sample screening flags as a table, and the inputs of later jobs filtered by it (002)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from processing.screening.criteria import ScreeningResult

Columns = Mapping[str, Any]

# ------------------------------------------------------------------------------------------------
# Flags table and filtering of later jobs' inputs.


def sample_keys(stream: str, cols: Columns) -> NDArray[np.object_]:
    """The key of each row besides (sensor, time): the panel number, the satellite ("G05"), or ""."""
    n = len(cols["time_tai_ns"])
    if stream == "panel_currents":
        return np.array([str(int(x)) for x in np.asarray(cols["panel"])], dtype=object)
    if stream == "gnss_visibility":
        return np.array([f"{s}{int(k):02d}" for s, k in zip(np.asarray(cols["system"]), np.asarray(cols["prn"]),
                                                             strict=True)], dtype=object)
    return np.full(n, "", dtype=object)


def _shared_strings(values: ArrayLike) -> NDArray[np.object_]:
    """``values`` as an object array of str, one str object per distinct value (not one per row)."""
    codes, uniques = pd.factorize(np.asarray(values, dtype=object), use_na_sentinel=False)
    return np.array([str(u) for u in uniques], dtype=object)[codes]


def flags_table(result: ScreeningResult, streams: Mapping[str, Columns]) -> dict[str, NDArray[Any]]:
    """One row per screened sample: time_tai_ns, stream, sensor, key, accepted, reasons (';'-joined
    criterion names, "" when accepted). Rows in stream order, then the stream's own row order."""
    parts: dict[str, list[NDArray[Any]]] = {k: [] for k in ("time_tai_ns", "stream", "sensor", "key", "accepted",
                                                             "reasons")}
    for name in result.n_rows:
        cols = streams[name]
        n = result.n_rows[name]
        rej = result.rejected(name)
        parts["time_tai_ns"].append(np.asarray(cols["time_tai_ns"], dtype=np.int64))
        parts["stream"].append(np.full(n, name, dtype=object))
        parts["sensor"].append(_shared_strings(cols["sensor"]))
        parts["key"].append(sample_keys(name, cols))
        parts["accepted"].append(~rej)
        parts["reasons"].append(result.reasons(name))
    if not parts["stream"]:
        return {"time_tai_ns": np.zeros(0, np.int64), "stream": np.zeros(0, object), "sensor": np.zeros(0, object),
                "key": np.zeros(0, object), "accepted": np.zeros(0, bool), "reasons": np.zeros(0, object)}
    return {k: np.concatenate(v) for k, v in parts.items()}


def accepted_mask(flags: Mapping[str, ArrayLike], stream: str, cols: Columns,
                  rejected: NDArray[np.bool_] | None = None) -> NDArray[np.bool_]:
    """Rows of ``cols`` (a stream's columns) that a stored flags table does not reject.

    flags: the columns of :func:`flags_table` (as stored: time_tai_ns, stream, sensor, key, accepted).
    A row is rejected when the table has a row with the same (stream, sensor, key, time) and
    accepted False; rows the table does not know (other window, stream not screened) are kept.
    rejected: the flags rows of ``stream`` with accepted False, when the caller has them (:func:`filter_streams`).
    """
    sel = _rejected_rows(flags, stream) if rejected is None else rejected
    n = len(cols["time_tai_ns"])
    keep = np.ones(n, dtype=bool)
    if not np.any(sel):
        return keep
    bad_t = np.asarray(flags["time_tai_ns"], dtype=np.int64)[sel]
    t = np.asarray(cols["time_tai_ns"], dtype=np.int64)
    # only rows at a rejected time can match: their strings are compared, not the whole stream's
    cand = np.flatnonzero(np.isin(t, bad_t))
    if cand.size == 0:
        return keep
    bad = pd.MultiIndex.from_arrays([np.asarray(flags["sensor"])[sel].astype(str),
                                     np.asarray(flags["key"])[sel].astype(str), bad_t])
    sub = {k: np.asarray(v)[cand] for k, v in cols.items()}
    rows = pd.MultiIndex.from_arrays([sub["sensor"].astype(str), sample_keys(stream, sub).astype(str), t[cand]])
    keep[cand] = ~np.asarray(rows.isin(bad), dtype=bool)
    return keep


def _rejected_rows(flags: Mapping[str, ArrayLike], stream: str) -> NDArray[np.bool_]:
    return (np.asarray(flags["stream"], dtype=object) == stream) & ~np.asarray(flags["accepted"], dtype=bool)


def filter_streams(streams: Mapping[str, Columns], flags: Mapping[str, ArrayLike]) -> dict[str, dict[str, Any]]:
    """Streams with the rows a flags table rejects removed (streams left empty are dropped)."""
    out: dict[str, dict[str, Any]] = {}
    # the table's stream column compared once (not once per stream): its codes, per stream the rejected rows
    codes, names = pd.factorize(np.asarray(flags["stream"], dtype=object), use_na_sentinel=False)
    refused = ~np.asarray(flags["accepted"], dtype=bool)
    index = {str(v): i for i, v in enumerate(names)}
    for name, cols in streams.items():
        code = index.get(name)
        rejected = np.zeros(codes.size, dtype=bool) if code is None else (codes == code) & refused
        keep = accepted_mask(flags, name, cols, rejected)
        if np.any(keep):
            out[name] = {k: np.asarray(v)[keep] for k, v in cols.items()}
    return out
