"""Partitioned Parquet files of telemetry, published atomically.

Layout: ``<root>/sc=<spacecraft id>/stream=<stream>/day=<YYYY-MM-DD>/<ingest id>.parquet``, one file
per ingest and TAI day. A file is written under a hidden temporary name in its final directory,
fsynced, renamed into place and the directory fsynced; only then does the caller commit the catalog
row that makes it visible. Readers open only files the catalog lists, so a crash at any point leaves
either an unreferenced file (removed at start-up by :func:`storage.telemetry.sweep_orphans`, under
each stream's ingest lock) or a complete, referenced one.

The root may also be a URL of any pyarrow/fsspec filesystem (``ATTITUDE_DATA_URL``, e.g.
``s3://bucket/prefix/telemetry``). Object stores have no atomic rename: each file is uploaded whole
under its final name (an object is visible complete or not at all) and published through the
catalog exactly as above — readers never list the store, they open the files the catalog names.
"""

from __future__ import annotations

import datetime as dt
import errno
import os
import queue
import tempfile
import threading
import time
import uuid
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from processing.streams import SENSOR_COLUMN, TIME_COLUMN
from processing.units import NS_PER_DAY
from storage.errors import DamagedFileError, StorageFullError
from storage.fs import Location, resolve

EPOCH_DATE = dt.date(1970, 1, 1)
TMP_PREFIX = ".tmp-"
NO_SPACE = (errno.ENOSPC, errno.EDQUOT)
WRITE_QUEUE = 2  # validated batches waiting for the writer thread of a staged upload
MAX_OPEN_DAYS = 16  # staged day files open at once; an older one is closed and a later row of its day opens a part


@dataclass(frozen=True)
class WrittenFile:
    path: str  # relative to the store root
    day: dt.date
    rows: int
    t_min_tai_ns: int
    t_max_tai_ns: int
    sensors: tuple[str, ...]


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class ParquetStore:
    """Telemetry files in a local directory (the embedded default) or on a pyarrow/fsspec filesystem."""

    def __init__(self, root: Path | str) -> None:
        self.location: Location = resolve(root)
        self.root = Path(self.location.root)  # meaningful for local stores only
        if self.location.local:
            self.root.mkdir(parents=True, exist_ok=True)

    def _dir(self, spacecraft_id: int, stream: str, day: dt.date) -> Path:
        return self.root / self._rel_dir(spacecraft_id, stream, day)

    @staticmethod
    def _rel_dir(spacecraft_id: int, stream: str, day: dt.date) -> str:
        return f"sc={spacecraft_id}/stream={stream}/day={day.isoformat()}"

    def write(self, spacecraft_id: int, stream: str, ingest_id: str, table: pa.Table) -> list[WrittenFile]:
        """Write ``table`` (sorted by key, containing ``time_tai_ns``) as one file per TAI day."""
        times = table.column(TIME_COLUMN).to_numpy()
        day_index = np.floor_divide(times, NS_PER_DAY)
        # Sorted by (sensor, ..., time): days are contiguous only for a single sensor/key group.
        monotonic = bool(np.all(day_index[1:] >= day_index[:-1]))
        order = None if monotonic else np.argsort(day_index, kind="stable")
        sorted_days = day_index if order is None else day_index[order]
        days, starts = np.unique(sorted_days, return_index=True)
        bounds = [*starts[1:], len(sorted_days)]
        written: list[WrittenFile] = []
        try:
            for day_i, lo, hi in zip(days, starts, bounds, strict=True):
                if order is None:
                    part = table.slice(lo, hi - lo)
                else:
                    part = table.take(pa.array(order[lo:hi]))
                day = EPOCH_DATE + dt.timedelta(days=int(day_i))
                written.append(self._publish(spacecraft_id, stream, ingest_id, day, part))
        except BaseException as exc:
            self.remove(w.path for w in written)
            if isinstance(exc, OSError) and exc.errno in NO_SPACE:
                raise StorageFullError(f"the telemetry store is full ({exc.strerror}); nothing was stored") from exc
            raise
        return written

    def _publish(self, spacecraft_id: int, stream: str, ingest_id: str, day: dt.date,
                 part: pa.Table) -> WrittenFile:
        # Dictionary encoding only for the string columns: floats rarely repeat and trying wastes time.
        dict_cols = [f.name for f in part.schema if pa.types.is_string(f.type)]
        rel = f"{self._rel_dir(spacecraft_id, stream, day)}/{ingest_id}.parquet"
        if not self.location.local:
            self._upload(rel, part, dict_cols)
            return self._written(rel, day, part)
        directory = self._dir(spacecraft_id, stream, day)
        directory.mkdir(parents=True, exist_ok=True)
        final = directory / f"{ingest_id}.parquet"
        tmp = directory / f"{TMP_PREFIX}{uuid.uuid4().hex}.parquet"
        try:
            with open(tmp, "wb") as fh:
                pq.write_table(part, fh, compression="snappy", use_dictionary=dict_cols,
                               write_statistics=[TIME_COLUMN])
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, final)
            _fsync_dir(directory)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        return self._written(str(final.relative_to(self.root)), day, part)

    def staged(self, spacecraft_id: int, stream: str, schema: pa.Schema) -> StagedFiles:
        """A writer of batches into staged per-day files, published by :meth:`StagedFiles.publish`."""
        return StagedFiles(self, spacecraft_id, stream, schema)

    def _upload(self, rel: str, part: pa.Table, dict_cols: list[str]) -> None:
        """Object store: serialise completely in memory, then one upload under the final name."""
        sink = pa.BufferOutputStream()
        pq.write_table(part, sink, compression="snappy", use_dictionary=dict_cols,
                       write_statistics=[TIME_COLUMN])
        try:
            self.location.write_bytes(rel, sink.getvalue())
        except BaseException:
            self.location.delete(rel)  # a failed upload must leave no object under the final name
            raise

    @staticmethod
    def _written(rel: str, day: dt.date, part: pa.Table) -> WrittenFile:
        times = part.column(TIME_COLUMN).to_numpy()
        sensors = tuple(sorted(set(part.column(SENSOR_COLUMN).unique().to_pylist())))
        return WrittenFile(path=rel, day=day, rows=part.num_rows, t_min_tai_ns=int(times.min()),
                           t_max_tai_ns=int(times.max()), sensors=sensors)

    def read(self, paths: Iterable[str], start_tai_ns: int | None = None,
             end_tai_ns: int | None = None) -> list[pa.Table]:
        """Read the listed files, keeping rows with start <= time <= end."""
        filters = []
        if start_tai_ns is not None:
            filters.append((TIME_COLUMN, ">=", start_tai_ns))
        if end_tai_ns is not None:
            filters.append((TIME_COLUMN, "<=", end_tai_ns))
        return [self._read_one(p, filters) for p in paths]

    def _read_one(self, path: str, filters: list[tuple[str, str, int]]) -> pa.Table:
        """One file; DamagedFileError naming it when it cannot be read (corrupt, truncated, missing)."""
        try:
            if self.location.local:
                return pq.read_table(self.root / path, filters=filters or None)
            return pq.read_table(self.location.path(path), filesystem=self.location.fs, filters=filters or None)
        except (OSError, pa.ArrowException) as exc:
            raise DamagedFileError(path, f"{type(exc).__name__}: {exc}") from exc

    def remove(self, paths: Iterable[str]) -> None:
        for p in paths:
            if self.location.local:
                (self.root / p).unlink(missing_ok=True)
            else:
                self.location.delete(p)

    def parquet_files(self) -> list[str]:
        """Every Parquet file in the store (published or temporary), relative to the root."""
        if not self.location.local:
            return [rel for rel, _ in self.location.list_files(".parquet")]
        return [str(p.relative_to(self.root)) for p in self.root.rglob("*.parquet")]

    def remove_orphans(self, referenced: set[str], older_than_s: float = 600.0) -> list[str]:
        """Delete files the catalog does not reference (left by a crash before commit).

        Only files older than ``older_than_s`` go: a younger one may belong to an ingest that another
        process is about to commit.
        """
        removed: list[str] = []
        now = time.time()
        if not self.location.local:
            for rel, mtime in self.location.list_files(".parquet"):
                if rel in referenced or mtime is None or now - mtime.timestamp() < older_than_s:
                    continue
                self.location.delete(rel)
                removed.append(rel)
            return removed
        for path in self.root.rglob("*.parquet"):
            rel = str(path.relative_to(self.root))
            if rel in referenced:
                continue
            try:
                if now - path.stat().st_mtime < older_than_s:
                    continue
            except FileNotFoundError:
                continue
            path.unlink(missing_ok=True)
            removed.append(rel)
        return removed


@dataclass
class _Part:
    """One staged file of one day: a temporary file (local stores: in the day's directory under a hidden
    name, so a crash leaves it to the orphan sweep; object stores: a local anonymous temporary file)."""

    day_index: int
    number: int  # 0: <ingest>.parquet, k > 0: <ingest>-<k>.parquet
    tmp: Path | None
    handle: IO[bytes]
    writer: pq.ParquetWriter | None
    rows: int = 0
    t_min: int = 0
    t_max: int = 0
    sensors: set[str] = field(default_factory=set)


class StagedFiles:
    """Batches written as they arrive into one staged Parquet file per TAI day (a row group per batch and
    day); nothing is visible until :meth:`publish`, :meth:`abort` removes everything staged.

    Memory is that of the batch being written: a file's earlier row groups are on disk. At most
    :data:`MAX_OPEN_DAYS` day files are open; when a batch opens another, the least recently written one is
    finished, and a later row of that day goes into a further part file of the same day.
    """

    def __init__(self, store: ParquetStore, spacecraft_id: int, stream: str, schema: pa.Schema) -> None:
        self.store, self.spacecraft_id, self.stream, self.schema = store, spacecraft_id, stream, schema
        self._dict_cols = [f.name for f in schema if pa.types.is_string(f.type)]
        self._open: dict[int, _Part] = {}  # insertion order = least recently written first
        self._closed: list[_Part] = []
        self._parts_per_day: dict[int, int] = {}
        self._published: list[str] = []
        self._queue: queue.Queue[pa.Table | None] = queue.Queue(maxsize=WRITE_QUEUE)
        self._thread: threading.Thread | None = None
        self._failure: BaseException | None = None

    def append(self, table: pa.Table) -> None:
        """Write ``table`` (rows of :func:`arrow_schema`, any order of days) in the background: a writer
        thread encodes it while the caller decodes and validates the next batch (at most
        :data:`WRITE_QUEUE` batches wait). A failure of the writer is raised by the next call."""
        if table.num_rows == 0:
            return
        self._raise_failure()
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="staged-parquet-writer", daemon=True)
            self._thread.start()
        self._queue.put(table)

    def _run(self) -> None:
        while (table := self._queue.get()) is not None:
            if self._failure is None:
                try:
                    self._append_now(table)
                except BaseException as exc:  # noqa: BLE001 (handed to the caller's thread)
                    self._failure = exc

    def _raise_failure(self) -> None:
        if self._failure is not None:
            raise self._failure

    def _drain(self) -> None:
        """Wait until every queued batch is written."""
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join()
            self._thread = None

    def _append_now(self, table: pa.Table) -> None:
        try:
            day_index = np.floor_divide(table.column(TIME_COLUMN).to_numpy(), NS_PER_DAY)
            if bool(np.all(day_index[1:] >= day_index[:-1])):
                cuts = np.flatnonzero(day_index[1:] != day_index[:-1]) + 1
                for lo, hi in zip([0, *cuts], [*cuts, len(day_index)], strict=True):
                    self._write(int(day_index[lo]), table.slice(lo, hi - lo))
            else:  # several sensors/key groups: each spans the days
                order = np.argsort(day_index, kind="stable")
                days, starts = np.unique(day_index[order], return_index=True)
                for d, lo, hi in zip(days, starts, [*starts[1:], len(order)], strict=True):
                    self._write(int(d), table.take(pa.array(order[lo:hi])))
        except OSError as exc:
            if exc.errno in NO_SPACE:
                raise StorageFullError(f"the telemetry store is full ({exc.strerror}); nothing was stored") from exc
            raise

    def _write(self, day_index: int, part_table: pa.Table) -> None:
        part = self._open.pop(day_index, None)
        if part is None:
            part = self._new_part(day_index)
        self._open[day_index] = part  # now the most recently written
        assert part.writer is not None
        part.writer.write_table(part_table, row_group_size=max(1, part_table.num_rows))
        times = part_table.column(TIME_COLUMN).to_numpy()
        lo, hi = int(times.min()), int(times.max())
        part.t_min, part.t_max = (lo, hi) if part.rows == 0 else (min(part.t_min, lo), max(part.t_max, hi))
        part.rows += part_table.num_rows
        part.sensors.update(part_table.column(SENSOR_COLUMN).unique().to_pylist())
        while len(self._open) > MAX_OPEN_DAYS:
            oldest = next(iter(self._open))
            self._finish(self._open.pop(oldest))

    def _new_part(self, day_index: int) -> _Part:
        number = self._parts_per_day.get(day_index, 0)
        self._parts_per_day[day_index] = number + 1
        tmp: Path | None = None
        if self.store.location.local:
            directory = self.store._dir(self.spacecraft_id, self.stream, EPOCH_DATE + dt.timedelta(days=day_index))
            directory.mkdir(parents=True, exist_ok=True)
            tmp = directory / f"{TMP_PREFIX}{uuid.uuid4().hex}.parquet"
            handle: IO[bytes] = open(tmp, "wb")  # noqa: SIM115 (closed by _finish or abort)
        else:
            handle = tempfile.TemporaryFile()  # noqa: SIM115
        writer = pq.ParquetWriter(handle, self.schema, compression="snappy", use_dictionary=self._dict_cols,
                                  write_statistics=[TIME_COLUMN])
        return _Part(day_index, number, tmp, handle, writer)

    def _finish(self, part: _Part) -> None:
        """Close a part's writer (it stays staged; a local file is closed too, so an upload of many days holds
        no more than MAX_OPEN_DAYS descriptors; made durable by :meth:`publish`, so a refused upload costs
        no fsync)."""
        if part.writer is not None:
            part.writer.close()
            part.writer = None
            part.handle.flush()
            if part.tmp is not None:
                part.handle.close()
        self._closed.append(part)

    def publish(self, ingest_id: str) -> list[WrittenFile]:
        """Finish every part and move it to its final name; the caller commits the catalog rows (or removes
        the returned files again with :meth:`abort`)."""
        self._drain()
        self._raise_failure()
        try:
            return self._publish_parts(ingest_id)
        except OSError as exc:
            if exc.errno in NO_SPACE:
                raise StorageFullError(f"the telemetry store is full ({exc.strerror}); nothing was stored") from exc
            raise

    def _publish_parts(self, ingest_id: str) -> list[WrittenFile]:
        while self._open:
            self._finish(self._open.pop(next(iter(self._open))))
        written = []
        directories: set[Path] = set()
        for part in sorted(self._closed, key=lambda p: (p.day_index, p.number)):
            day = EPOCH_DATE + dt.timedelta(days=part.day_index)
            name = f"{ingest_id}.parquet" if part.number == 0 else f"{ingest_id}-{part.number}.parquet"
            rel = f"{self.store._rel_dir(self.spacecraft_id, self.stream, day)}/{name}"
            if part.tmp is not None:
                fd = os.open(part.tmp, os.O_RDONLY)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
                os.replace(part.tmp, self.store.root / rel)
                part.tmp = None
                directories.add((self.store.root / rel).parent)
            else:
                part.handle.seek(0)
                try:
                    self.store.location.write_bytes(rel, part.handle.read())  # one upload: whole or absent
                except BaseException:
                    self.store.location.delete(rel)
                    raise
                part.handle.close()
            self._published.append(rel)
            written.append(WrittenFile(path=rel, day=day, rows=part.rows, t_min_tai_ns=part.t_min,
                                       t_max_tai_ns=part.t_max, sensors=tuple(sorted(part.sensors))))
        for directory in directories:
            _fsync_dir(directory)
        return written

    def abort(self) -> None:
        """Remove every staged and published file of this writer."""
        self._drain()
        for part in [*self._open.values(), *self._closed]:
            try:
                if part.writer is not None:
                    part.writer.close()
            except (OSError, pa.ArrowException):
                pass
            part.handle.close()
            if part.tmp is not None:
                part.tmp.unlink(missing_ok=True)
        self._open.clear()
        self._closed.clear()
        self.store.remove(self._published)
        self._published.clear()
