"""Ingest of an upload that arrives in validated batches, written as it arrives (issue 24).

:class:`StreamedIngest` holds the stream's ingest lock (:func:`storage.locks.stream_lock`) from the first
batch to the commit, like :func:`storage.telemetry.commit_ingest`: each batch is de-duplicated against the
stored samples of its own time span (only the files overlapping the batch are read) and its new rows are
written into staged per-day files (:class:`storage.parquet_store.StagedFiles`). All or nothing: the files
are published and the catalog rows committed by :meth:`StreamedIngest.commit`; any failure before (a
conflict, an invalid row found in a later batch, an exception) removes every staged file.

Batches must follow each other per identity group (sensor + extra key columns): a group's first time in
a batch after its last time in every earlier batch. Then no identity repeats across batches, and each
batch's de-duplication against the store is complete. A batch that breaks this raises :class:`OutOfOrder`
(nothing stored; the caller falls back to ingesting the upload whole).
"""

from __future__ import annotations

from contextlib import ExitStack
from types import TracebackType

import numpy as np
import pyarrow as pa
from sqlalchemy.orm import Session

from processing.streams import TIME_COLUMN, StreamSpec
from processing.units import NS_PER_DAY
from storage.locks import stream_lock
from storage.models import Ingest, new_id
from storage.parquet_store import ParquetStore, StagedFiles
from storage.telemetry import ConflictError, IngestMeta, arrow_schema, ingest_record, new_rows, register_files

MAX_CONFLICTS_REPORTED = 100


class OutOfOrder(Exception):
    """A batch does not follow the earlier batches of its identity group (see the module docstring)."""


class TooManyDays(Exception):
    """The upload's rows fall on more TAI days than allowed (one file per day)."""


class StreamedIngest:
    """``with StreamedIngest(...) as sink: sink.add(batch, rows) ...; record = sink.commit(meta)``."""

    def __init__(self, session: Session, store: ParquetStore, spacecraft_id: int, spec: StreamSpec,
                 max_days: int = 1000) -> None:
        self.session, self.store, self.spacecraft_id, self.spec = session, store, spacecraft_id, spec
        self.max_days = max_days
        self.rows = self.inserted = 0
        self.t0: int | None = None
        self.t1: int | None = None
        self.sensors: set[str] = set()
        self.days: set[int] = set()
        self.conflicts: list[dict[str, object]] = []
        self.n_conflicts = 0
        self._last: dict[tuple[object, ...], int] = {}  # identity group -> its latest time so far
        self._staged: StagedFiles = store.staged(spacecraft_id, spec.name, arrow_schema(spec))
        self._stack = ExitStack()

    def __enter__(self) -> StreamedIngest:
        self._stack.enter_context(stream_lock(self.session, self.spacecraft_id, self.spec.name))
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        try:
            if kind is not None:
                self.session.rollback()
                self._staged.abort()
                self.session.info.pop("written_files", None)
        finally:
            self._stack.close()

    def check_follows(self, table: pa.Table) -> None:
        """OutOfOrder unless every identity group of ``table`` starts after its end in earlier batches."""
        groups = [k for k in self.spec.key_columns if k != TIME_COLUMN]
        times = table.column(TIME_COLUMN)
        if len(groups) == 1 and len(sensors := table.column("sensor").unique()) == 1:
            # the usual case: one sensor, its times increasing (validated)
            self._follow([((sensors[0].as_py(),), int(times[0].as_py()), int(times[-1].as_py()))])
            return
        agg = table.group_by(groups).aggregate([(TIME_COLUMN, "min"), (TIME_COLUMN, "max")])
        keys = list(zip(*(agg.column(g).to_pylist() for g in groups), strict=True))
        self._follow(list(zip(keys, agg.column(f"{TIME_COLUMN}_min").to_pylist(),
                              agg.column(f"{TIME_COLUMN}_max").to_pylist(), strict=True)))

    def _follow(self, spans: list[tuple[tuple[object, ...], int, int]]) -> None:
        for key, lo, _ in spans:
            if key in self._last and lo <= self._last[key]:
                raise OutOfOrder(f"group {key}: batch starts at {lo}, at or before {self._last[key]}")
        for key, _, hi in spans:
            self._last[key] = hi

    def add(self, table: pa.Table, row_index: np.ndarray) -> None:
        """One validated batch (canonical, sorted by identity); ``row_index``: upload row of each row."""
        if table.num_rows == 0:
            return
        self.check_follows(table)
        times = table.column(TIME_COLUMN).to_numpy()
        lo, hi = int(times.min()), int(times.max())
        day = np.floor_divide(times, NS_PER_DAY)
        steps = day[1:] != day[:-1]
        monotonic = bool(np.all(day[1:] >= day[:-1]))  # one group: no sort needed to find its days
        self.days.update((day[np.concatenate([[True], steps])] if monotonic else np.unique(day)).tolist())
        if len(self.days) > self.max_days:  # refused at the commit (after every batch was validated, as a
            self._staged.abort()             # whole upload would be, and with the count); nothing more written
        self.rows += table.num_rows
        self.t0 = lo if self.t0 is None else min(self.t0, lo)
        self.t1 = hi if self.t1 is None else max(self.t1, hi)
        self.sensors.update(table.column("sensor").unique().to_pylist())
        if len(self.days) > self.max_days:
            return
        new_mask, conflicts, n_conflicts = new_rows(self.session, self.store, self.spacecraft_id, self.spec, table,
                                                    row_index, lo, hi)
        if n_conflicts:
            self.conflicts += conflicts[:MAX_CONFLICTS_REPORTED - len(self.conflicts)]
            self.n_conflicts += n_conflicts
        n_new = int(new_mask.sum())
        self.inserted += n_new
        if n_new and not self.n_conflicts:  # after a conflict nothing more is written (it will be refused)
            self._staged.append(table if n_new == table.num_rows else table.filter(pa.array(new_mask)))

    def commit(self, meta: IngestMeta) -> Ingest:
        """Publish the staged files and commit the ingest with its file rows; ConflictError (nothing
        stored) when any batch differed from stored samples."""
        if len(self.days) > self.max_days:
            raise TooManyDays(f"the rows fall on {len(self.days)} different days; at most {self.max_days} days per "
                              "upload (ATTITUDE_MAX_UPLOAD_DAYS): split the upload")
        if self.n_conflicts:
            raise ConflictError(self.conflicts, self.n_conflicts)
        if self.t0 is None or self.t1 is None:
            raise ValueError("no rows were added")
        record = ingest_record(self.spacecraft_id, self.spec, meta, sensors=self.sensors, rows=self.rows,
                               inserted=self.inserted, t0=self.t0, t1=self.t1, ingest_id=new_id())
        self.session.add(record)
        self.session.flush()
        register_files(self.session, record, self._staged.publish(record.id))  # removed by __exit__ on failure
        self.session.commit()
        self.session.info.pop("written_files", None)
        return record
