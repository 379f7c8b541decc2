"""What a job processed: per input stream and sensor, samples, period, gaps (for the report header).

:func:`describe_inputs` is meant to run where the inputs are at hand (the job runner stores its result
as ``result["input_coverage"]``); reports of jobs that lack it compute the same from the telemetry
store at report time (:func:`describe_stored_window`) and say so.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sqlalchemy.orm import Session

from app.reports.summary import iso
from processing.samples import sensor_index
from processing.screening.coverage import find_gaps
from processing.streams import STREAMS
from processing.units import NS_PER_S
from storage.models import IngestRetraction
from storage.parquet_store import ParquetStore
from storage.telemetry import read_window, retracted_inputs

GAP_FACTOR = 1.5
MAX_LISTED_GAPS = 20


def _distinct_times(t: NDArray[np.int64]) -> NDArray[np.int64]:
    """``np.unique(t)``; in one pass when ``t`` is already in order (as the telemetry store reads it)."""
    if t.size < 2:
        return t
    step = np.diff(t)
    if np.all(step >= 0):
        return t[np.concatenate(([True], step != 0))]
    return np.unique(t)


def _describe_series(t: NDArray[np.int64], n_rows: int, start_tai_ns: int, end_tai_ns: int) -> dict[str, Any]:
    t = _distinct_times(np.asarray(t, dtype=np.int64))  # rows sharing a time (panels, satellites) count once
    entry: dict[str, Any] = {"n_samples": int(n_rows), "first_tai_ns": int(t[0]), "last_tai_ns": int(t[-1]),
                             "period_s": None, "n_gaps": 0, "gap_total_s": 0.0, "missing_samples": 0,
                             "largest_gaps": [],
                             "leading_s": (int(t[0]) - start_tai_ns) / NS_PER_S,
                             "trailing_s": (end_tai_ns - int(t[-1])) / NS_PER_S}
    if t.size >= 2:
        gaps = find_gaps(t, factor=GAP_FACTOR)
        order = np.argsort(-gaps.duration_ns, kind="stable")[:MAX_LISTED_GAPS]
        entry.update(period_s=gaps.nominal_period_ns / NS_PER_S, n_gaps=gaps.count,
                     gap_total_s=float(gaps.duration_ns.sum()) / NS_PER_S, missing_samples=int(gaps.missing.sum()),
                     largest_gaps=[{"before_tai_ns": int(gaps.before_tai_ns[i]),
                                    "after_tai_ns": int(gaps.after_tai_ns[i]),
                                    "duration_s": float(gaps.duration_ns[i]) / NS_PER_S,
                                    "missing": int(gaps.missing[i])} for i in sorted(order.tolist())])
    return entry


def describe_inputs(streams: Mapping[str, Mapping[str, Any]], start_tai_ns: int,
                    end_tai_ns: int) -> dict[str, dict[str, dict[str, Any]]]:
    """stream -> sensor -> {n_samples, first/last_tai_ns, period_s, n_gaps, gap_total_s, missing_samples,
    largest_gaps (up to 20, by duration), leading_s/trailing_s (uncovered start/end of the window)}.

    ``streams`` as in ``TaskInputs.streams`` (columns ``time_tai_ns`` and ``sensor``). Gaps are intervals
    longer than 1.5 nominal periods (processing.screening.coverage).
    """
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for name in sorted(streams):
        cols = streams[name]
        t_all = np.asarray(cols["time_tai_ns"], dtype=np.int64)
        if t_all.size == 0:
            continue
        sensors, index = sensor_index(cols["sensor"])
        out[name] = {}
        for i, sensor in enumerate(sensors):
            mask = index == i
            out[name][sensor] = _describe_series(t_all[mask], int(mask.sum()), start_tai_ns, end_tai_ns)
    return out


def describe_stored_window(session: Session, store: ParquetStore, spacecraft_id: int, streams: Iterable[str],
                           start_tai_ns: int, end_tai_ns: int) -> dict[str, dict[str, dict[str, Any]]]:
    """:func:`describe_inputs` of what the telemetry store holds now in the window, for ``streams``."""
    columns: dict[str, dict[str, Any]] = {}
    for name in streams:
        spec = STREAMS.get(name)
        if spec is None:
            continue
        table = read_window(session, store, spacecraft_id, spec, start_tai_ns, end_tai_ns)
        if table.num_rows:
            columns[name] = {c: table.column(c).to_numpy(zero_copy_only=False) for c in ("time_tai_ns", "sensor")}
    return describe_inputs(columns, start_tai_ns, end_tai_ns)


def describe_retraction(r: IngestRetraction) -> dict[str, Any]:
    """A retracted ingest for reports, pages and the API (times as ISO 8601 UTC)."""
    return {"retraction_id": r.id, "ingest_id": r.ingest_id, "stream": r.stream, "sensor": r.sensor,
            "rows": r.rows, "samples_removed": r.inserted, "start": iso(r.start_tai_ns), "end": iso(r.end_tai_ns),
            "filename": r.filename, "checksum_sha256": r.checksum_sha256, "files_removed": r.files_removed,
            "reason": r.reason, "retracted_by": r.retracted_by_name or r.retracted_by,
            "retracted_by_key": r.retracted_by, "retracted_at": r.retracted_at.isoformat(),
            "uploaded_at": r.uploaded_at.isoformat()}


def retracted_by_job(session: Session, job_ids: Iterable[str]) -> dict[str, list[dict[str, Any]]]:
    """job id -> the retracted ingests whose samples it had read (jobs without any left out)."""
    return {j: [describe_retraction(r) for r in rs] for j, rs in retracted_inputs(session, job_ids).items()}
