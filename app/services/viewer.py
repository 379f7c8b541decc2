"""The telemetry viewer: one stream and sensor over a time range, decimated on the server for plotting.

A day of 10 Hz samples is 864,000 points per column; the browser gets at most a few thousand per column,
chosen per pixel column by MinMaxLTTB (``tsdownsample``): every column's extremes are kept, so spikes
and dropouts stay visible at any zoom. Samples rejected by a screening job (the ``flags`` table of a
data_screening job, or of a reconstruction's screening stage) are marked and listed with the criterion,
the tested value and the threshold. The download is exactly the view: every stored sample of the stream
and sensor in the window (the plot is a decimation of them), with the screening verdict per sample.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
from numpy.typing import NDArray
from sqlalchemy import select
from sqlalchemy.orm import Session

from app.services.access import Principal
from app.services.errors import Invalid, NotFound
from app.services.spacecraft import get_spacecraft
from app.services.telemetry import get_stream
from app.services.times import iso, parse_window
from processing.streams import SENSOR_COLUMN, TIME_COLUMN, StreamSpec
from processing.time import timescales
from processing.units import NS_PER_S
from storage.jobs import ArtifactStore
from storage.models import Artifact, Job, Spacecraft, TelemetryFile
from storage.parquet_store import ParquetStore
from storage.telemetry import read_series

MAX_POINTS = 8000  # per series and request, whatever the width asked for
MAX_SERIES = 12  # streams keyed by more than sensor and time (panels, satellites): the first groups
MAX_LISTED = 1000  # rejected samples listed per view
FLAGS_ARTIFACTS = {"data_screening": "flags.parquet", "reconstruction": "data_screening__flags.parquet"}


@dataclass(frozen=True)
class Selection:
    """What the viewer shows: a stream of a spacecraft, one sensor, a window [start, end] in TAI ns."""

    spacecraft: Spacecraft
    spec: StreamSpec
    sensor: str
    sensors: list[str]
    start_tai_ns: int
    end_tai_ns: int
    screening_job: Job | None
    screening_jobs: list[Job] = field(default_factory=list)


def stream_sensors(session: Session, sc: Spacecraft) -> dict[str, list[str]]:
    """stream -> sensors with stored samples (from the catalog), streams by name."""
    out: dict[str, set[str]] = {}
    for stream, sensors in session.execute(select(TelemetryFile.stream, TelemetryFile.sensors)
                                           .where(TelemetryFile.spacecraft_id == sc.id).distinct()):
        out.setdefault(stream, set()).update(s for s in sensors.split(",") if s)
    return {k: sorted(v) for k, v in sorted(out.items())}


def _extent(session: Session, sc: Spacecraft, stream: str) -> tuple[int, int] | None:
    row = session.execute(select(TelemetryFile.t_min_tai_ns, TelemetryFile.t_max_tai_ns).where(
        TelemetryFile.spacecraft_id == sc.id, TelemetryFile.stream == stream)).all()
    if not row:
        return None
    return min(int(r[0]) for r in row), max(int(r[1]) for r in row)


def screening_jobs(session: Session, sc: Spacecraft, start: int, end: int) -> list[Job]:
    """Succeeded screening jobs (data_screening, reconstruction) whose windows overlap [start, end], newest first."""
    return list(session.scalars(select(Job).where(
        Job.spacecraft_id == sc.id, Job.status == "succeeded", Job.type.in_(list(FLAGS_ARTIFACTS)),
        Job.start_tai_ns <= end, Job.end_tai_ns >= start).order_by(Job.finished_at.desc()).limit(20)))


def select_view(session: Session, name: str, who: Principal, stream: str | None, sensor: str | None,
                start: str | None, end: str | None, screening: str | None) -> Selection:
    """The viewer's selection; defaults: the first stream and sensor with samples, the last hour of it,
    the newest screening job over the window (``screening="none"``: no marks)."""
    sc = get_spacecraft(session, name, who)
    available = stream_sensors(session, sc)
    if not available:
        raise NotFound(f"spacecraft {name!r} has no telemetry yet")
    stream = stream or next(iter(available))
    spec = get_stream(stream)
    sensors = available.get(spec.name, [])
    if not sensors:
        raise NotFound(f"spacecraft {name!r} has no {spec.name} samples; streams: {', '.join(available)}")
    sensor = sensor or sensors[0]
    if sensor not in sensors:
        raise Invalid(f"sensor: {spec.name} has sensors {', '.join(sensors)}, not {sensor!r}")
    extent = _extent(session, sc, spec.name)
    assert extent is not None
    t0, t1 = parse_window(start, end, "utc")
    t1 = extent[1] if t1 is None else t1
    t0 = max(extent[0], t1 - 3600 * NS_PER_S) if t0 is None else t0
    if t1 <= t0:
        raise Invalid("end must be after start")
    jobs = screening_jobs(session, sc, t0, t1)
    chosen: Job | None = None
    if screening not in ("none", None, ""):
        chosen = next((j for j in jobs if j.id == screening), None) or session.get(Job, screening)
        if chosen is None or chosen.spacecraft_id != sc.id or chosen.type not in FLAGS_ARTIFACTS:
            raise Invalid(f"screening: no screening job {screening!r} of {name}")
    elif screening is None and jobs:
        chosen = jobs[0]
    return Selection(sc, spec, sensor, sensors, t0, t1, chosen, jobs)


def read_view(session: Session, store: ParquetStore, sel: Selection) -> pa.Table:
    """Every stored sample of the selection, sorted by time."""
    return read_series(session, store, sel.spacecraft.id, sel.spec, sel.sensor, sel.start_tai_ns, sel.end_tai_ns)


def _groups(table: pa.Table, spec: StreamSpec) -> list[tuple[str, NDArray[np.bool_] | None]]:
    """("", None) for streams keyed by sensor and time; else one (label, row mask) per extra key value."""
    extra = [k for k in spec.key_columns if k not in (SENSOR_COLUMN, TIME_COLUMN)]
    if not extra or table.num_rows == 0:
        return [("", None)]
    keys = [table.column(k).to_numpy(zero_copy_only=False).astype(str) for k in extra]
    combined = keys[0] if len(keys) == 1 else np.char.add(np.char.add(keys[0], "/"), keys[1])
    labels = sorted(set(combined.tolist()), key=lambda v: (len(v), v))[:MAX_SERIES]
    name = "/".join(extra)
    return [(f"{name}={v}", combined == v) for v in labels]


def decimate(t_ns: NDArray[np.int64], y: NDArray[np.float64], n_out: int) -> NDArray[np.int64]:
    """Indices of at most ``n_out`` samples keeping the extremes of every bin (MinMaxLTTB, tsdownsample)."""
    if y.size <= n_out:
        return np.arange(y.size, dtype=np.int64)
    from tsdownsample import MinMaxLTTBDownsampler

    n_out = max(4, n_out - n_out % 2)
    return np.asarray(MinMaxLTTBDownsampler().downsample(t_ns, y, n_out=n_out), dtype=np.int64)


def plot_data(table: pa.Table, sel: Selection, width_px: int) -> dict[str, Any]:
    """The decimated series of every numeric column (times in seconds since the window start)."""
    n_out = int(min(MAX_POINTS, max(200, 2 * width_px)))
    t_all = np.asarray(table.column(TIME_COLUMN).to_numpy(), dtype=np.int64)
    numeric = [c.name for c in sel.spec.columns if c.kind in ("float", "int", "bool")
               and c.name not in sel.spec.key_columns]
    panels = []
    n_plotted = 0
    for column in numeric:
        series = []
        values = np.asarray(table.column(column).to_numpy(zero_copy_only=False), dtype=np.float64)
        for label, mask in _groups(table, sel.spec):
            t, y = (t_all, values) if mask is None else (t_all[mask], values[mask])
            ok = np.isfinite(y)
            if not ok.all():
                t, y = t[ok], y[ok]
            idx = decimate(t, y, n_out)
            n_plotted += idx.size
            series.append({"label": label or column, "n": int(t.size),
                           "x": np.round((t[idx] - sel.start_tai_ns) / NS_PER_S, 4).tolist(),
                           "y": [float(f"{v:.7g}") for v in y[idx]]})
        panels.append({"column": column, "series": series})
    return {"panels": panels, "n_samples": int(table.num_rows), "n_plotted": n_plotted}


def _flags(store: ArtifactStore, session: Session, job: Job) -> pa.Table | None:
    """The rejected rows of the job's ``flags`` table (every screened sample has a row there)."""
    art = session.scalar(select(Artifact).where(Artifact.job_id == job.id, Artifact.name == FLAGS_ARTIFACTS[job.type]))
    if art is None:
        return None
    path = store.path(art)
    if not path.is_file():
        return None
    st = path.stat()
    return _rejected_rows(str(path), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=16)
def _rejected_rows(path: str, _mtime_ns: int, _size: int) -> pa.Table:
    """Rejected rows of a stored flags table (a finished job's artifact never changes: cached by path,
    modification time and size). Only the columns needed, strings kept dictionary-encoded."""
    table = pq.read_table(path, columns=[TIME_COLUMN, "stream", "sensor", "accepted", "reasons"],
                          read_dictionary=["stream", "sensor", "reasons"])
    bad = table.filter(pc.invert(table.column("accepted")))
    return pa.table({c: bad.column(c).cast(pa.string()) if c in ("stream", "sensor", "reasons") else bad.column(c)
                     for c in bad.column_names})


def _statistics(store: ArtifactStore, session: Session, job: Job) -> pa.Table | None:
    name = FLAGS_ARTIFACTS[job.type].replace("flags", "statistics")
    art = session.scalar(select(Artifact).where(Artifact.job_id == job.id, Artifact.name == name))
    path = store.path(art) if art is not None else None
    return pq.read_table(path) if path is not None and path.is_file() else None


def _screening_summary(job: Job) -> dict[str, Any]:
    summary = (job.result or {}).get("summary") or {}
    if job.type == "reconstruction":
        summary = ((summary.get("stages") or {}).get("data_screening") or {}).get("summary") or {}
    streams = summary.get("streams")
    return streams if isinstance(streams, dict) else {}


def rejected(session: Session, artifacts: ArtifactStore, sel: Selection, table: pa.Table) -> dict[str, Any]:
    """The samples of the view that the selected screening job rejected: one entry per sample and
    criterion (time, stream, criterion, value, threshold, unit), and the rejection reasons per sample."""
    out: dict[str, Any] = {"job": None, "items": [], "total": 0, "reasons": {}}
    job = sel.screening_job
    if job is None:
        return out
    out["job"] = {"id": job.id, "type": job.type, "start": iso(job.start_tai_ns), "end": iso(job.end_tai_ns)}
    flags = _flags(artifacts, session, job)
    if flags is None:
        return out
    t = flags.column(TIME_COLUMN).to_numpy()
    ours = pc.and_(pc.equal(flags.column("stream"), sel.spec.name), pc.equal(flags.column("sensor"), sel.sensor))
    keep = pc.and_(ours, pc.invert(flags.column("accepted")))
    keep = pc.and_(keep, pa.array((t >= sel.start_tai_ns) & (t <= sel.end_tai_ns)))
    bad = flags.filter(keep).sort_by(TIME_COLUMN)
    times = bad.column(TIME_COLUMN).to_numpy().astype(np.int64)
    reasons = [str(r) for r in bad.column("reasons").to_pylist()]
    out["reasons"] = {int(a): r for a, r in zip(times.tolist(), reasons, strict=True)}
    thresholds = _screening_summary(job).get(sel.spec.name, {})
    stats = _statistics(artifacts, session, job)
    by_key: dict[tuple[int, str], float] = {}
    if stats is not None:
        s = stats.filter(pc.and_(pc.equal(stats.column("stream"), sel.spec.name), stats.column("flagged")))
        for a, c, v in zip(s.column(TIME_COLUMN).to_pylist(), s.column("criterion").to_pylist(),
                           s.column("statistic").to_pylist(), strict=True):
            by_key[(int(a), str(c))] = v
    items = []
    for a, r in zip(times.tolist(), reasons, strict=True):
        for criterion in [c for c in r.split(";") if c]:
            info = thresholds.get(criterion, {})
            items.append({"time": iso(a), "t": (a - sel.start_tai_ns) / NS_PER_S, "stream": sel.spec.name,
                          "criterion": criterion, "value": by_key.get((a, criterion)),
                          "threshold": info.get("threshold"), "unit": info.get("unit", "")})
    out["total"] = len(items)
    out["items"] = items[:MAX_LISTED]
    return out


def mark_positions(table: pa.Table, sel: Selection, reasons: dict[int, str]) -> list[dict[str, Any]]:
    """Per numeric column, the (x, y) of the rejected samples (for the markers on the plot)."""
    if not reasons or table.num_rows == 0:
        return []
    t_all = table.column(TIME_COLUMN).to_numpy().astype(np.int64)
    wanted = np.array(sorted(reasons), dtype=np.int64)
    rows = np.flatnonzero(np.isin(t_all, wanted))[: MAX_LISTED * 4]
    out = []
    for c in sel.spec.columns:
        if c.kind in ("float", "int", "bool") and c.name not in sel.spec.key_columns:
            y = table.column(c.name).to_numpy(zero_copy_only=False).astype(np.float64)[rows]
            out.append({"column": c.name, "x": ((t_all[rows] - sel.start_tai_ns) / NS_PER_S).tolist(),
                        "y": [None if not np.isfinite(v) else float(v) for v in y]})
    return out


def utc_ms(tai_ns: int) -> float:
    """Milliseconds since 1970 UTC of a TAI instant (for the browser's clock)."""
    return float(timescales.tai_ns_to_epoch_ns(np.array([tai_ns], dtype=np.int64), "utc")[0]) / 1e6


def view_json(session: Session, store: ParquetStore, artifacts: ArtifactStore, sel: Selection,
              width_px: int) -> dict[str, Any]:
    """Everything the viewer page draws for one window."""
    table = read_view(session, store, sel)
    data = plot_data(table, sel, width_px)
    screening = rejected(session, artifacts, sel, table)
    return {"spacecraft": sel.spacecraft.name, "stream": sel.spec.name, "sensor": sel.sensor,
            "start": iso(sel.start_tai_ns), "end": iso(sel.end_tai_ns),
            "duration_s": (sel.end_tai_ns - sel.start_tai_ns) / NS_PER_S, "t0_utc_ms": utc_ms(sel.start_tai_ns),
            **data, "marks": mark_positions(table, sel, screening.pop("reasons")), "screening": screening}


def download_table(session: Session, store: ParquetStore, artifacts: ArtifactStore, sel: Selection) -> pa.Table:
    """Exactly the view as a table: every stored sample in the window, and ``rejected_by`` (the criteria
    of the selected screening job that rejected it; empty when accepted or not screened)."""
    table = read_view(session, store, sel)
    screening = rejected(session, artifacts, sel, table)
    reasons: dict[int, str] = screening["reasons"]
    t = table.column(TIME_COLUMN).to_numpy().astype(np.int64)
    flags = [reasons.get(int(a), "") for a in t] if reasons else [""] * table.num_rows
    return table.append_column("rejected_by", pa.array(flags, pa.string()))
