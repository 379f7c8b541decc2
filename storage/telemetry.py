"""Telemetry ingest and reads: the catalog decides which Parquet files exist.

``ingest`` de-duplicates against stored samples (identity = spacecraft, stream, sensor, extra key
columns, time), rejects conflicting values, writes the new rows and commits one ``ingest`` row with
its ``telemetry_file`` rows in one transaction. ``read_window`` returns sorted, de-duplicated rows.
"""

from __future__ import annotations

import datetime as dt
import logging
import re
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pyarrow as pa
from sqlalchemy import select, update
from sqlalchemy.orm import Session, sessionmaker

from processing.streams import TIME_COLUMN, StreamSpec
from storage.errors import DamagedFileError
from storage.locks import stream_lock
from storage.models import Ingest, IngestRetraction, Job, JobRetraction, TelemetryFile
from storage.parquet_store import ParquetStore, WrittenFile

log = logging.getLogger("attitude.storage")


class ConflictError(Exception):
    """Uploaded rows collide with stored rows of the same identity but other values."""

    def __init__(self, rows: list[dict[str, object]], total: int) -> None:
        self.rows = rows
        self.total = total
        super().__init__(f"{total} rows conflict with stored samples")


@dataclass(frozen=True)
class IngestMeta:
    filename: str | None
    content_type: str
    size_bytes: int
    checksum_sha256: str
    time_scale: str
    api_key_id: str | None


def _files_in_window(session: Session, spacecraft_id: int, stream: str, start: int | None,
                     end: int | None) -> list[TelemetryFile]:
    q = select(TelemetryFile).where(TelemetryFile.spacecraft_id == spacecraft_id,
                                    TelemetryFile.stream == stream)
    if start is not None:
        q = q.where(TelemetryFile.t_max_tai_ns >= start)
    if end is not None:
        q = q.where(TelemetryFile.t_min_tai_ns <= end)
    return list(session.scalars(q.order_by(TelemetryFile.id)))


def _sort_unique(table: pa.Table, spec: StreamSpec) -> pa.Table:
    """Sort by the identity key and keep the first row of each identity."""
    keys = list(spec.key_columns)
    table = table.sort_by([(k, "ascending") for k in keys])
    if table.num_rows < 2:
        return table
    same = np.ones(table.num_rows - 1, dtype=bool)
    for k in keys:
        col = table.column(k).to_numpy(zero_copy_only=False)
        same &= col[1:] == col[:-1]
    if not same.any():
        return table
    keep = np.concatenate([[True], ~same])
    return table.filter(pa.array(keep))


def _read_files(session: Session, store: ParquetStore, files: list[TelemetryFile], start_tai_ns: int | None,
                end_tai_ns: int | None) -> list[pa.Table]:
    """The non-empty tables of ``files`` in the window; DamagedFileError (the file quarantined, in a
    transaction of its own) when one is quarantined or cannot be read."""
    for f in files:
        if f.quarantined:
            raise DamagedFileError(f.path, f.quarantined, ingest_id=f.ingest_id, stream=f.stream)
    tables = []
    for f in files:
        try:
            (table,) = store.read([f.path], start_tai_ns, end_tai_ns)
        except DamagedFileError as exc:
            _quarantine(session, f, exc.reason)
            raise DamagedFileError(f.path, exc.reason, ingest_id=f.ingest_id, stream=f.stream) from exc
        if table.num_rows:
            tables.append(table)
    return tables


def _quarantine(session: Session, f: TelemetryFile, reason: str) -> None:
    log.error("quarantining damaged telemetry file %s (ingest %s, stream %s): %s", f.path, f.ingest_id, f.stream,
              reason)
    with Session(session.get_bind().engine) as other, other.begin():
        other.execute(update(TelemetryFile).where(TelemetryFile.id == f.id, TelemetryFile.quarantined.is_(None))
                      .values(quarantined=reason[:2000], quarantined_at=dt.datetime.now(dt.UTC)))


def quarantined_files(session: Session, spacecraft_id: int | None = None) -> list[TelemetryFile]:
    """Files found damaged, oldest first."""
    q = select(TelemetryFile).where(TelemetryFile.quarantined.is_not(None))
    if spacecraft_id is not None:
        q = q.where(TelemetryFile.spacecraft_id == spacecraft_id)
    return list(session.scalars(q.order_by(TelemetryFile.quarantined_at)))


def restore_file(session: Session, store: ParquetStore, file_id: int) -> TelemetryFile:
    """Lift the quarantine of a file that reads again (e.g. restored from a backup); DamagedFileError if not."""
    f = session.get(TelemetryFile, file_id)
    if f is None:
        raise LookupError(f"no telemetry file {file_id}")
    store.read([f.path])
    f.quarantined, f.quarantined_at = None, None
    session.flush()
    return f


USED_BY_STATUSES = ("succeeded", "failed", "running")
"""Jobs in these states may have read an ingest's samples (queued jobs will read the store as it is then)."""


def _jobs_that_used(session: Session, record: Ingest, reads: Callable[[str], Iterable[str]] | None) -> list[str]:
    """Ids of the jobs of the spacecraft whose window overlaps the ingest and that read its stream and
    sensors: by the inputs a finished job recorded, or (running jobs, which have recorded none) by
    ``reads(job type)``, the streams the type reads (every running job in the window without it)."""
    sensors = set(record.sensor.split(","))
    candidates = session.scalars(select(Job).where(
        Job.spacecraft_id == record.spacecraft_id, Job.status.in_(USED_BY_STATUSES),
        Job.start_tai_ns <= record.end_tai_ns, Job.end_tai_ns >= record.start_tai_ns))
    used = []
    for job in candidates:
        inputs = (job.result or {}).get("inputs")
        if isinstance(inputs, dict):
            if record.stream in inputs and sensors & set(inputs[record.stream] or ()):
                used.append(job.id)
        elif job.status == "running" and (reads is None or record.stream in set(reads(job.type))):
            used.append(job.id)
    return used


def retract_ingest(session: Session, store: ParquetStore, ingest_id: str, *, reason: str = "",
                   retracted_by: str | None = None, retracted_by_name: str | None = None,
                   reads: Callable[[str], Iterable[str]] | None = None) -> list[str]:
    """Delete an ingest and its files (a mistaken upload, or one whose file is damaged); commits.

    In the same transaction as the delete, the retraction is logged (an ``ingest_retraction`` row: what
    the ingest held, who, when, why) and the jobs that had read its samples are linked to it
    (``job_retraction``: their results rest on retracted data). Nothing else changes: other ingests'
    samples and other jobs stay as they are. The catalog rows go first (readers stop seeing the samples
    at the commit), then the files. Returns the paths removed; :func:`retraction_of` finds the log entry."""
    record = session.get(Ingest, ingest_id)
    if record is None:
        raise LookupError(f"no ingest {ingest_id}")
    paths = [f.path for f in record.files]
    with stream_lock(session, record.spacecraft_id, record.stream):
        log_row = IngestRetraction(
            spacecraft_id=record.spacecraft_id, ingest_id=record.id, stream=record.stream, sensor=record.sensor,
            rows=record.rows, inserted=record.inserted, start_tai_ns=record.start_tai_ns,
            end_tai_ns=record.end_tai_ns, filename=record.filename, checksum_sha256=record.checksum_sha256,
            uploaded_at=record.created_at, files_removed=len(paths), reason=reason[:4000],
            retracted_by=retracted_by, retracted_by_name=retracted_by_name)
        session.add(log_row)
        session.flush()
        for job_id in (_jobs_that_used(session, record, reads) if paths else []):
            session.add(JobRetraction(job_id=job_id, retraction_id=log_row.id))
        session.delete(record)
        session.commit()
    store.remove(paths)
    log.warning("retracted ingest %s (%s, %d files) by %s: %s", ingest_id, record.stream, len(paths),
                retracted_by_name or retracted_by or "-", reason)
    return paths


def retraction_of(session: Session, ingest_id: str) -> IngestRetraction | None:
    """The log entry of the retraction of ``ingest_id`` (None if it was not retracted)."""
    return session.scalar(select(IngestRetraction).where(IngestRetraction.ingest_id == ingest_id)
                          .order_by(IngestRetraction.retracted_at.desc()).limit(1))


def retracted_inputs(session: Session, job_ids: Iterable[str]) -> dict[str, list[IngestRetraction]]:
    """job id -> the retractions of samples it had read (jobs without any are left out)."""
    ids = list(job_ids)
    if not ids:
        return {}
    out: dict[str, list[IngestRetraction]] = {}
    rows = session.execute(select(JobRetraction.job_id, IngestRetraction).join(
        IngestRetraction, IngestRetraction.id == JobRetraction.retraction_id).where(JobRetraction.job_id.in_(ids))
        .order_by(IngestRetraction.retracted_at))
    for job_id, retraction in rows:
        out.setdefault(job_id, []).append(retraction)
    return out


class TooManyRowsToRead(ValueError):
    """A read window holds more stored rows than the caller allows (known from the catalog, before reading)."""


def read_window(session: Session, store: ParquetStore, spacecraft_id: int, spec: StreamSpec,
                start_tai_ns: int | None = None, end_tai_ns: int | None = None,
                sensor: str | None = None, max_rows: int | None = None) -> pa.Table:
    """All stored samples of one stream in [start, end], sorted by identity, without duplicates.

    ``max_rows``: TooManyRowsToRead, before any file is opened, when the files overlapping the window
    hold more rows (an upper bound: a file partly outside the window counts whole)."""
    files = _files_in_window(session, spacecraft_id, spec.name, start_tai_ns, end_tai_ns)
    if sensor is not None:
        files = [f for f in files if sensor in f.sensors.split(",")]
    if max_rows is not None and (held := sum(f.rows for f in files)) > max_rows:
        raise TooManyRowsToRead(f"the window holds up to {held} stored {spec.name} rows; at most {max_rows} are "
                                "returned per read (ATTITUDE_MAX_READ_ROWS): give a narrower start/end")
    tables = _read_files(session, store, files, start_tai_ns, end_tai_ns)
    if not tables:
        return empty_table(spec)
    table = pa.concat_tables(tables, promote_options="permissive")
    if sensor is not None:
        table = table.filter(pa.compute.equal(table.column("sensor"), sensor))
    one_sensor = sensor is not None or (len({f.sensors for f in files}) == 1 and "," not in files[0].sensors)
    if not (one_sensor and _in_identity_order(table, spec)):  # the usual case: one sensor's files in time order
        table = _sort_unique(table, spec)
    return table.select(list(empty_table(spec).schema.names))


def window_rows(session: Session, spacecraft_id: int, spec: StreamSpec, start_tai_ns: int | None = None,
                end_tai_ns: int | None = None, sensor: str | None = None) -> int:
    """Stored rows of the files that overlap the window (an upper bound of a read's rows), from the catalog."""
    files = _files_in_window(session, spacecraft_id, spec.name, start_tai_ns, end_tai_ns)
    return sum(f.rows for f in files if sensor is None or sensor in f.sensors.split(","))


def _chunk_bounds(files: list[TelemetryFile], lo: int, hi: int, chunk_rows: int) -> list[tuple[int, int]]:
    """Consecutive inclusive time ranges [a, b] covering [lo, hi], cut at file starts so that each range's
    files hold about chunk_rows rows (files sorted by start)."""
    cuts: list[int] = []
    acc = 0
    for f, nxt in zip(files, files[1:], strict=False):
        acc += f.rows
        if acc >= chunk_rows and lo < nxt.t_min_tai_ns <= hi and (not cuts or nxt.t_min_tai_ns > cuts[-1]):
            cuts.append(int(nxt.t_min_tai_ns))
            acc = 0
    edges = [lo, *cuts, hi + 1]
    return [(a, b - 1) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def iter_window(session: Session, store: ParquetStore, spacecraft_id: int, spec: StreamSpec,
                start_tai_ns: int | None = None, end_tai_ns: int | None = None, sensor: str | None = None,
                chunk_rows: int = 1_000_000) -> Iterator[pa.Table]:
    """The rows of :func:`read_window`, in the same order (identity: sensor, key, time), as consecutive
    tables of a few files each (about ``chunk_rows`` stored rows): memory stays that of one chunk for any
    window. Quarantined files are refused before the first chunk; a file found damaged while streaming
    raises DamagedFileError then (the caller has already sent part of the answer)."""
    files = _files_in_window(session, spacecraft_id, spec.name, start_tai_ns, end_tai_ns)
    for f in files:
        if f.quarantined:
            raise DamagedFileError(f.path, f.quarantined, ingest_id=f.ingest_id, stream=f.stream)
    sensors = sorted({s for f in files for s in f.sensors.split(",")} if sensor is None else {sensor})
    names = list(empty_table(spec).schema.names)
    for s in sensors:
        mine = sorted((f for f in files if s in f.sensors.split(",")), key=lambda f: f.t_min_tai_ns)
        if not mine:
            continue
        lo = int(min(f.t_min_tai_ns for f in mine)) if start_tai_ns is None else max(int(start_tai_ns), int(
            min(f.t_min_tai_ns for f in mine)))
        hi = int(max(f.t_max_tai_ns for f in mine)) if end_tai_ns is None else min(int(end_tai_ns), int(
            max(f.t_max_tai_ns for f in mine)))
        for a, b in _chunk_bounds(mine, lo, hi, chunk_rows):
            group = [f for f in mine if f.t_max_tai_ns >= a and f.t_min_tai_ns <= b]
            tables = _read_files(session, store, group, a, b)
            if not tables:
                continue
            table = pa.concat_tables(tables, promote_options="permissive")
            if any(f.sensors != s for f in group):  # files of this sensor alone need no filtering
                table = table.filter(pa.compute.equal(table.column("sensor"), s))
            if table.num_rows:
                yield (table if _in_identity_order(table, spec) else _sort_unique(table, spec)).select(names)


def _in_identity_order(table: pa.Table, spec: StreamSpec) -> bool:
    """True when one sensor's rows of a stream keyed by time alone are already strictly increasing in time
    (files that follow each other, the usual case): sorted and unique, so no sort copy is needed."""
    if spec.key:
        return False
    t = table.column(TIME_COLUMN).to_numpy()
    return bool(np.all(t[1:] > t[:-1]))


def read_series(session: Session, store: ParquetStore, spacecraft_id: int, spec: StreamSpec, sensor: str,
                start_tai_ns: int | None = None, end_tai_ns: int | None = None) -> pa.Table:
    """One sensor's stored samples in [start, end] sorted by time, for plotting a long window fast.

    The same samples as :func:`read_window` with ``sensor``, ordered by time (then by the other key
    columns, e.g. panels, in stored order) instead of by identity: a table already in time order (one
    file, or files that follow each other, the usual case) is not sorted again."""
    files = [f for f in _files_in_window(session, spacecraft_id, spec.name, start_tai_ns, end_tai_ns)
             if sensor in f.sensors.split(",")]
    tables = _read_files(session, store, sorted(files, key=lambda f: f.t_min_tai_ns), start_tai_ns, end_tai_ns)
    if not tables:
        return empty_table(spec)
    table = pa.concat_tables(tables, promote_options="permissive")
    if any(f.sensors != sensor for f in files):  # files of this sensor alone need no filtering
        table = table.filter(pa.compute.equal(table.column("sensor"), sensor))
    table = table.select(list(empty_table(spec).schema.names))
    t = table.column(TIME_COLUMN).to_numpy()
    if t.size > 1 and not bool(np.all(t[1:] >= t[:-1])):
        table = table.take(pa.array(np.argsort(t, kind="stable")))
    return table


def arrow_schema(spec: StreamSpec) -> pa.Schema:
    types = {"float": pa.float64(), "int": pa.int64(), "str": pa.string(), "bool": pa.bool_()}
    return pa.schema([(TIME_COLUMN, pa.int64()), ("sensor", pa.string()),
                      *((c.name, types[c.kind]) for c in spec.columns)])


def empty_table(spec: StreamSpec) -> pa.Table:
    return arrow_schema(spec).empty_table()


def _split_new(existing: pa.Table, upload: pa.Table, spec: StreamSpec,
               row_index: np.ndarray) -> tuple[np.ndarray, list[dict[str, object]], int]:
    """Mask of upload rows not yet stored; conflicting rows (same identity, other values)."""
    keys = list(spec.key_columns)
    values = [c for c in spec.column_names if c not in keys]
    up = upload.select(keys + values).to_pandas()
    up["_pos"] = np.arange(len(up))
    old = existing.select(keys + values).to_pandas()
    merged = up.merge(old, on=keys, how="inner", suffixes=("", "_old"))
    is_dup = np.zeros(len(up), dtype=bool)
    is_dup[merged["_pos"].to_numpy()] = True
    differs = np.zeros(len(merged), dtype=bool)
    for c in values:
        differs |= (merged[c] != merged[f"{c}_old"]).to_numpy()
    conflicts = merged[differs]
    rows: list[dict[str, object]] = []
    for r in conflicts.head(100).to_dict("records"):
        changed = [c for c in values if r[c] != r[f"{c}_old"]]
        rows.append({
            "row": int(row_index[r["_pos"]]),
            "column": ",".join(changed),
            "message": "differs from the stored sample with the same sensor and time: "
                       + ", ".join(f"{c} stored {r[c + '_old']!r}, uploaded {r[c]!r}" for c in changed),
        })
    return ~is_dup, rows, int(differs.sum())


def ingest(session: Session, store: ParquetStore, spacecraft_id: int, spec: StreamSpec,
           table: pa.Table, row_index: np.ndarray, meta: IngestMeta) -> Ingest:
    """Store a validated upload (canonical columns, sorted by identity, unique identities).

    ``row_index`` maps each table row to its row in the original upload (for error reports).
    Commits nothing itself: the caller's transaction commits the ingest and file rows; files written
    here are removed again if that transaction fails (see :func:`commit_ingest`).
    Raises :class:`ConflictError` when stored samples disagree.
    """
    times = table.column(TIME_COLUMN).to_numpy()
    t0, t1 = int(times.min()), int(times.max())
    new_mask, conflicts, n_conflicts = new_rows(session, store, spacecraft_id, spec, table, row_index, t0, t1)
    if n_conflicts:
        raise ConflictError(conflicts, n_conflicts)
    n_new = int(new_mask.sum())
    sensors = set(table.column("sensor").unique().to_pylist())
    record = ingest_record(spacecraft_id, spec, meta, sensors=sensors, rows=table.num_rows, inserted=n_new,
                           t0=t0, t1=t1)
    session.add(record)
    session.flush()
    if n_new:
        rows = table if n_new == table.num_rows else table.filter(pa.array(new_mask))
        register_files(session, record, store.write(spacecraft_id, spec.name, record.id, rows))
    session.flush()
    return record


def new_rows(session: Session, store: ParquetStore, spacecraft_id: int, spec: StreamSpec, table: pa.Table,
             row_index: np.ndarray, t0: int, t1: int) -> tuple[np.ndarray, list[dict[str, object]], int]:
    """Mask of the rows of ``table`` (times in [t0, t1]) not yet stored, and the rows that conflict with stored
    samples (reported with their upload row from ``row_index``) with their count; only the stored files
    overlapping [t0, t1] are read."""
    files = _files_in_window(session, spacecraft_id, spec.name, t0, t1)
    stored = _read_files(session, store, files, t0, t1) if files else []
    if not stored:
        return np.ones(table.num_rows, dtype=bool), [], 0
    return _split_new(pa.concat_tables(stored, promote_options="permissive"), table, spec, row_index)


def ingest_record(spacecraft_id: int, spec: StreamSpec, meta: IngestMeta, *, sensors: Iterable[str], rows: int,
                  inserted: int, t0: int, t1: int, ingest_id: str | None = None) -> Ingest:
    """The catalog row of an upload of ``rows`` rows, ``inserted`` of them new, spanning [t0, t1]."""
    return Ingest(
        **({"id": ingest_id} if ingest_id is not None else {}),
        spacecraft_id=spacecraft_id, stream=spec.name, sensor=",".join(sorted(sensors)), rows=rows,
        inserted=inserted, duplicates=rows - inserted, start_tai_ns=t0, end_tai_ns=t1,
        filename=meta.filename, content_type=meta.content_type, size_bytes=meta.size_bytes,
        checksum_sha256=meta.checksum_sha256, time_scale=meta.time_scale,
        status="stored" if inserted else "duplicate", api_key_id=meta.api_key_id,
    )


def register_files(session: Session, record: Ingest, written: Iterable[WrittenFile]) -> None:
    """Catalog the files written for ``record`` (and note them, so that a failed commit removes them)."""
    written = list(written)
    session.info.setdefault("written_files", []).extend(w.path for w in written)
    for w in written:
        session.add(TelemetryFile(
            ingest_id=record.id, spacecraft_id=record.spacecraft_id, stream=record.stream, day=w.day,
            path=w.path, rows=w.rows, t_min_tai_ns=w.t_min_tai_ns, t_max_tai_ns=w.t_max_tai_ns,
            sensors=",".join(w.sensors),
        ))


def commit_ingest(session: Session, store: ParquetStore, spacecraft_id: int, spec: StreamSpec,
                  table: pa.Table, row_index: np.ndarray, meta: IngestMeta) -> Ingest:
    """Run :func:`ingest` and commit; on any failure roll back and delete the files it wrote.

    Ingests of one stream are serialised across threads, processes and instances
    (:func:`storage.locks.stream_lock`) so that de-duplication sees every committed sample.
    """
    with stream_lock(session, spacecraft_id, spec.name):
        try:
            record = ingest(session, store, spacecraft_id, spec, table, row_index, meta)
            session.commit()
        except BaseException:
            session.rollback()
            store.remove(session.info.pop("written_files", []))
            raise
        session.info.pop("written_files", None)
        return record


_STREAM_DIR = re.compile(r"^sc=(\d+)/stream=([a-z_]+)/")


def sweep_orphans(sessions: sessionmaker[Session], store: ParquetStore) -> list[str]:
    """Remove every stored file the catalog does not list (left by a crash before its commit).

    Each stream is swept holding its ingest lock (:func:`storage.locks.stream_lock`), so no ingest of it
    is in flight in any process or instance: a file not listed then is an orphan, whatever its age.
    Returns the removed paths."""
    groups: dict[tuple[int, str], list[str]] = {}
    for rel in store.parquet_files():
        m = _STREAM_DIR.match(rel)
        if m:
            groups.setdefault((int(m.group(1)), m.group(2)), []).append(rel)
    removed: list[str] = []
    for (spacecraft_id, stream), paths in sorted(groups.items()):
        with sessions() as session:
            with stream_lock(session, spacecraft_id, stream):
                listed = set(session.scalars(select(TelemetryFile.path).where(
                    TelemetryFile.spacecraft_id == spacecraft_id, TelemetryFile.stream == stream)))
                orphans = [p for p in paths if p not in listed]
                store.remove(orphans)
            session.commit()  # ends the transaction (and with it a PostgreSQL advisory lock)
        removed += orphans
    return removed


def referenced_paths(session: Session) -> set[str]:
    return set(session.scalars(select(TelemetryFile.path)))


def coverage(session: Session, spacecraft_id: int) -> pd.DataFrame:
    """Per stream: number of stored rows and the time range (from the catalog only)."""
    rows = session.execute(
        select(TelemetryFile.stream, TelemetryFile.rows, TelemetryFile.t_min_tai_ns,
               TelemetryFile.t_max_tai_ns).where(TelemetryFile.spacecraft_id == spacecraft_id)
    ).all()
    df = pd.DataFrame(rows, columns=["stream", "rows", "t_min_tai_ns", "t_max_tai_ns"])
    return df.groupby("stream").agg(rows=("rows", "sum"), start_tai_ns=("t_min_tai_ns", "min"),
                                    end_tai_ns=("t_max_tai_ns", "max")).reset_index()
