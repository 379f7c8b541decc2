"""Telemetry coverage of one spacecraft: per stream and sensor, covered spans and gaps.

Spans come from the catalog (each published Parquet file's first and last sample): consecutive files
closer than 1.5 sampling periods merge into one span, and what lies between spans is a gap "between
uploads". Gaps inside files are not in the catalog; they come from the succeeded
``telemetry_coverage`` jobs overlapping the view, when there are any. The UI draws it
(app/web/timeline.py).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

from sqlalchemy import select
from sqlalchemy.orm import Session

from processing.units import NS_PER_S
from storage.models import Job, TelemetryFile

GAP_FACTOR = 1.5
MAX_COVERAGE_JOBS = 50


@dataclass
class Row:
    stream: str
    sensor: str
    samples: int = 0
    first_tai_ns: int = 0
    last_tai_ns: int = 0
    spans: list[tuple[int, int]] = field(default_factory=list)
    gaps: list[tuple[int, int, str]] = field(default_factory=list)  # (last before, first after, source)


@dataclass
class Timeline:
    start_tai_ns: int
    end_tai_ns: int
    rows: list[Row]
    coverage_jobs: list[str] = field(default_factory=list)


def _merge(files: list[tuple[int, int, int]]) -> list[tuple[int, int]]:
    """Spans of (t_min, t_max, rows) files: overlapping or closer than 1.5 periods are merged."""
    spans: list[list[int]] = []
    for t0, t1, n in sorted(files):
        period = (t1 - t0) / (n - 1) if n > 1 else 0.0
        if spans and t0 - spans[-1][1] <= GAP_FACTOR * max(period, spans[-1][2]):
            spans[-1][1] = max(spans[-1][1], t1)
            spans[-1][2] = int(max(period, spans[-1][2]))
        else:
            spans.append([t0, t1, int(period)])
    return [(a, b) for a, b, _ in spans]


def build(session: Session, spacecraft_id: int, start_tai_ns: int | None = None,
          end_tai_ns: int | None = None) -> Timeline | None:
    """The timeline of the catalog's telemetry in [start, end] (default: everything); None if empty."""
    q = select(TelemetryFile.stream, TelemetryFile.sensors, TelemetryFile.t_min_tai_ns, TelemetryFile.t_max_tai_ns,
               TelemetryFile.rows).where(TelemetryFile.spacecraft_id == spacecraft_id)
    if start_tai_ns is not None:
        q = q.where(TelemetryFile.t_max_tai_ns >= start_tai_ns)
    if end_tai_ns is not None:
        q = q.where(TelemetryFile.t_min_tai_ns <= end_tai_ns)
    files: dict[tuple[str, str], list[tuple[int, int, int]]] = defaultdict(list)
    for stream, sensors, t0, t1, n in session.execute(q):
        names = [s for s in sensors.split(",") if s] or [stream]
        for sensor in names:
            files[(stream, sensor)].append((int(t0), int(t1), max(1, int(n) // len(names))))
    if not files:
        return None
    lo = start_tai_ns if start_tai_ns is not None else min(f[0] for fs in files.values() for f in fs)
    hi = end_tai_ns if end_tai_ns is not None else max(f[1] for fs in files.values() for f in fs)
    if hi <= lo:
        hi = lo + NS_PER_S
    rows = []
    for (stream, sensor), fs in sorted(files.items()):
        spans = _merge(fs)
        row = Row(stream, sensor, samples=sum(f[2] for f in fs), first_tai_ns=min(f[0] for f in fs),
                  last_tai_ns=max(f[1] for f in fs), spans=spans)
        row.gaps = [(a[1], b[0], "between uploads") for a, b in zip(spans, spans[1:], strict=False)]
        rows.append(row)
    tl = Timeline(lo, hi, rows)
    _add_job_gaps(session, spacecraft_id, tl)
    return tl


def _add_job_gaps(session: Session, spacecraft_id: int, tl: Timeline) -> None:
    """Gaps inside uploads found by the newest coverage jobs (up to 50) whose windows overlap the view."""
    jobs = list(session.scalars(select(Job).where(
        Job.spacecraft_id == spacecraft_id, Job.type == "telemetry_coverage", Job.status == "succeeded",
        Job.end_tai_ns >= tl.start_tai_ns, Job.start_tai_ns <= tl.end_tai_ns)
        .order_by(Job.created_at.desc()).limit(MAX_COVERAGE_JOBS)))
    tl.coverage_jobs = [j.id for j in jobs]
    by_key = {(r.stream, r.sensor): r for r in tl.rows}
    known = {key: {(a, b) for a, b, _ in r.gaps} for key, r in by_key.items()}
    for job in jobs:
        for s in ((job.result or {}).get("summary") or {}).get("streams") or []:
            key = (s.get("stream"), s.get("sensor"))
            row = by_key.get(key)
            if row is None:
                continue
            for g in s.get("gaps") or []:
                a, b = int(g["before_tai_ns"]), int(g["after_tai_ns"])
                if (a, b) not in known[key]:
                    known[key].add((a, b))
                    row.gaps.append((a, b, f"coverage job {job.id[:8]}"))
    for r in tl.rows:
        r.gaps.sort()
