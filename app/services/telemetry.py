"""Telemetry: streams, upload formats, all-or-nothing ingest of uploads, read-back, the ingest log."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import replace
from typing import Any

import numpy as np
import pyarrow as pa
from sqlalchemy import select
from sqlalchemy.orm import Session

from app.ingest.batches import iter_tables, parse_body
from app.ingest.errors import MAX_REPORTED, RowError, UploadError
from app.ingest.formats import Decoder, decoders
from app.ingest.parse import DecodeLimits, LimitExceeded, UnsupportedMediaType
from app.ingest.spool import Body
from app.ingest.validate import ORDER_ERRORS, SensorPolicy, UploadOptions, validate
from app.services.access import Principal
from app.services.errors import NotFound, TooLarge, Unsupported
from app.services.pages import Page, page_of, paginate
from app.services.spacecraft import get_spacecraft
from app.services.times import parse_window
from processing.streams import STREAMS, StreamSpec
from processing.units import NS_PER_DAY
from storage.models import Ingest, Spacecraft
from storage.parquet_store import ParquetStore
from storage.streamed_ingest import OutOfOrder, StreamedIngest, TooManyDays
from storage.telemetry import (
    IngestMeta,
    TooManyRowsToRead,
    commit_ingest,
    empty_table,
    iter_window,
    read_window,
    window_rows,
)

log = logging.getLogger("attitude.ingest")
DEFAULT_BATCH_ROWS = 1_000_000  # rows per decoded batch of an upload (ATTITUDE_INGEST_BATCH_ROWS)
SINGLE_SENSOR_KINDS = {"gyro": "gyro", "magnetometer": "magnetometer", "sun_sensor": "sun_sensor"}


class TooManyRows(TooLarge):
    """An upload of more rows than ``max_upload_rows``."""


def get_stream(stream: str) -> StreamSpec:
    spec = STREAMS.get(stream)
    if spec is None:
        raise NotFound(f"unknown stream {stream!r}; streams: {', '.join(STREAMS)}")
    return spec


def list_formats() -> list[Decoder]:
    """Upload formats besides the generic tables (``format=`` of an upload)."""
    return list(decoders().values())


def sensor_policy(spec: StreamSpec, config: dict[str, Any]) -> SensorPolicy:
    """Which sensor names an upload of ``spec`` may use for this configuration (DESIGN.md)."""
    if spec.sensor_kind == "star_trackers":
        names = tuple(config.get("star_trackers", {}))
        if len(names) == 1:
            return SensorPolicy(names, names[0])
        why = ("several star trackers are configured (" + ", ".join(names) + "): give sensor="
               if names else "no star tracker is configured for this spacecraft: add one with "
                             "PUT /config or give sensor=")
        return SensorPolicy(names or None, None, why)
    return SensorPolicy(None, spec.name if spec.sensor_kind is None else SINGLE_SENSOR_KINDS[spec.sensor_kind])


def upload_options(config: dict[str, Any], time_scale: str, sensor: str | None, norm_tolerance: float,
                   quaternion_direction: str) -> UploadOptions:
    """The options of an upload to a spacecraft of configuration ``config``."""
    return UploadOptions(time_scale=time_scale, sensor=sensor, norm_tolerance=norm_tolerance,
                         quaternion_direction=quaternion_direction,
                         n_panels=len(config.get("solar_panels", [])) or None)


def _decode(body: bytes, spec: StreamSpec, fmt: str, opts: UploadOptions) -> tuple[pa.Table, UploadOptions]:
    """The upload in the file format ``fmt`` as a table of canonical upload columns."""
    decoder = decoders().get(fmt)
    if decoder is None:
        raise UploadError([RowError(None, "format", f"unknown format {fmt!r}; formats: "
                                                     f"{', '.join(['table', *sorted(decoders())])}")])
    if spec.name not in decoder.streams:
        raise UploadError([RowError(None, "format", f"format {fmt} feeds {', '.join(decoder.streams)}, "
                                                     f"not {spec.name}")])
    if not body.strip():
        raise UploadError([RowError(None, None, "the request body is empty")])
    try:
        decoded = decoder.decode(body, spec.name)
    except ValueError as exc:
        raise UploadError([RowError(None, None, f"not a valid {fmt} file: {exc}")]) from exc
    if opts.sensor is not None and decoded.sensor is not None and opts.sensor != decoded.sensor:
        raise UploadError([RowError(None, "sensor", f"the file names sensor {decoded.sensor!r}, the query "
                                                     f"{opts.sensor!r}")])
    return decoded.table, replace(opts, time_scale=decoded.time_scale,
                                  quaternion_direction=decoded.quaternion_direction,
                                  sensor=opts.sensor or decoded.sensor, notes=tuple(decoded.notes))


def ingest_upload(session: Session, store: ParquetStore, sc: Spacecraft, spec: StreamSpec, body: bytes | Body,
                  content_type: str, opts: UploadOptions, meta: IngestMeta, config: dict[str, Any],
                  fmt: str | None, max_rows: int, max_days: int = 1000,
                  batch_rows: int = DEFAULT_BATCH_ROWS) -> tuple[Ingest, tuple[str, ...]]:
    """Decode, validate and store one upload; all or nothing (blocking: run it off the event loop).

    Tables (CSV, Parquet, Arrow, JSON) are decoded, validated and written in batches of ``batch_rows``
    (:func:`_ingest_streamed`); a file format (``fmt``) is decoded whole. Returns the ingest record and the
    notes of a file-format decoder. Raises UploadError (invalid rows), Unsupported (media type),
    TooManyRows or storage.telemetry.ConflictError (rows differ from stored samples); nothing is stored then."""
    body = Body.from_bytes(body) if isinstance(body, bytes) else body
    limits = DecodeLimits(max_rows=max_rows)
    try:
        if fmt is None or fmt == "table":
            try:
                return _ingest_streamed(session, store, sc, spec, body, content_type, opts, meta, config, limits,
                                        max_days, batch_rows), opts.notes
            except OutOfOrder:
                # Times must increase per sensor/key group in upload order, so a valid upload always
                # streams; this one goes back or repeats a time (within a batch or across batches):
                # nothing was stored, and the upload is validated whole instead, so that its 422 lists
                # every such row exactly as for any upload. Still bounded by max_upload_rows.
                log.info("upload to %s/%s: times go back or repeat; validated whole", sc.name, spec.name)
                table = parse_body(body.read(), content_type, limits)
        else:
            table, opts = _decode(body.read(), spec, fmt, opts)
    except UnsupportedMediaType as exc:
        raise Unsupported(str(exc)) from None
    except LimitExceeded as exc:
        raise TooManyRows(str(exc)) from None
    if table.num_rows > max_rows:
        raise TooManyRows(f"{table.num_rows} rows exceed the limit of {max_rows} rows per upload; split the upload")
    checked = validate(table, spec, sensor_policy(spec, config), opts)
    del table
    times = checked.table.column("time_tai_ns").to_numpy()
    days = np.unique(np.floor_divide(times, NS_PER_DAY)).size
    if days > max_days:  # one Parquet file per TAI day: bound the files (and catalog rows) of one upload
        raise TooManyRows(f"the rows fall on {days} different days; at most {max_days} days per upload "
                          "(ATTITUDE_MAX_UPLOAD_DAYS): split the upload")
    record = commit_ingest(session, store, sc.id, spec, checked.table, checked.row_index, meta)
    return record, opts.notes  # notes: what a file-format decoder did (frames, units)


def _shifted(exc: UploadError, first: int) -> list[RowError]:
    return [e if e.row is None else RowError(e.row + first, e.column, e.message) for e in exc.errors]


def _ingest_streamed(session: Session, store: ParquetStore, sc: Spacecraft, spec: StreamSpec, body: Body,
                     content_type: str, opts: UploadOptions, meta: IngestMeta, config: dict[str, Any],
                     limits: DecodeLimits, max_days: int, batch_rows: int) -> Ingest:
    """Each batch is validated and handed to a :class:`StreamedIngest` (de-duplicated against the stored
    samples of its span, written into staged files); an invalid row in any batch, also the last, rejects the
    upload (422 with the rows of the original upload; the batches after it are still checked so that every
    error is reported, nothing more is written) and the staged files are removed. Times that go back or repeat
    (within a batch or across batches) raise OutOfOrder: see the caller."""
    policy = sensor_policy(spec, config)
    errors: list[RowError] = []
    n_errors = rows = 0
    try:
        with StreamedIngest(session, store, sc.id, spec, max_days) as sink:
            for first, batch in iter_tables(body, content_type, limits, batch_rows):
                rows += batch.num_rows
                try:
                    checked = validate(batch, spec, policy, opts)
                except UploadError as exc:
                    if any(e.message in ORDER_ERRORS for e in exc.errors):
                        raise OutOfOrder("times go back within a batch") from None
                    errors += _shifted(exc, first)[:MAX_REPORTED - len(errors)]
                    n_errors += exc.total
                    if any(e.row is None for e in exc.errors):
                        break  # a problem of the whole upload (columns, options): every batch has it
                    continue
                if n_errors:
                    sink.check_follows(checked.table)  # only checked: nothing more is written
                else:
                    sink.add(checked.table, checked.row_index + first)
            if n_errors:
                raise UploadError(errors, n_errors)
            if rows == 0:
                raise UploadError([RowError(None, None, "the upload has no rows")])
            return sink.commit(meta)
    except TooManyDays as exc:
        raise TooManyRows(str(exc)) from None


def read(session: Session, store: ParquetStore, name: str, stream: str, who: Principal, start: str | None,
         end: str | None, time_scale: str, sensor: str | None = None, max_rows: int | None = None) -> pa.Table:
    """Stored samples of one stream in [start, end] (ISO 8601 or seconds since 1970 on ``time_scale``),
    sorted by sensor and time, without duplicates; TooLarge when the window holds more than ``max_rows``."""
    spec = get_stream(stream)
    sc = get_spacecraft(session, name, who)
    t0, t1 = parse_window(start, end, time_scale)
    try:
        return read_window(session, store, sc.id, spec, t0, t1, sensor, max_rows=max_rows)
    except TooManyRowsToRead as exc:
        raise TooLarge(str(exc)) from None


def read_chunks(session: Session, store: ParquetStore, name: str, stream: str, who: Principal, start: str | None,
                end: str | None, time_scale: str, sensor: str | None = None,
                stream_above_rows: int = 1_000_000) -> Iterator[pa.Table] | None:
    """The read of :func:`read` as consecutive tables when the window holds more than ``stream_above_rows``
    stored rows (None below: read it whole). Access, the window and quarantined files are checked now."""
    spec = get_stream(stream)
    sc = get_spacecraft(session, name, who)
    t0, t1 = parse_window(start, end, time_scale)
    if window_rows(session, sc.id, spec, t0, t1, sensor) <= stream_above_rows:
        return None
    chunks = iter_window(session, store, sc.id, spec, t0, t1, sensor, chunk_rows=stream_above_rows)
    first = next(chunks, None)  # quarantined files refused here, before the answer starts

    def all_chunks() -> Iterator[pa.Table]:
        yield empty_table(spec) if first is None else first
        yield from chunks

    return all_chunks()


def list_ingests(session: Session, name: str, who: Principal, stream: str | None, cursor: str | None,
                 limit: int) -> Page[Ingest]:
    """Uploads of the spacecraft, newest first."""
    sc = get_spacecraft(session, name, who)
    q = select(Ingest).where(Ingest.spacecraft_id == sc.id)
    if stream is not None:
        q = q.where(Ingest.stream == get_stream(stream).name)
    rows = list(session.scalars(paginate(q, Ingest.created_at, Ingest.id, cursor, limit)))
    return page_of(rows, limit, lambda r: (r.created_at, r.id))


def recent_ingests(session: Session, sc: Spacecraft, limit: int) -> list[Ingest]:
    """The newest ``limit`` uploads of a spacecraft."""
    return list(session.scalars(select(Ingest).where(Ingest.spacecraft_id == sc.id)
                                .order_by(Ingest.created_at.desc()).limit(limit)))


def find_ingest(session: Session, sc: Spacecraft, ingest_id: str) -> Ingest | None:
    """The upload ``ingest_id`` if it is one of the spacecraft's."""
    rec = session.get(Ingest, ingest_id)
    return rec if rec is not None and rec.spacecraft_id == sc.id else None
