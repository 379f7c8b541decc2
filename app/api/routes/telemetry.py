"""Telemetry upload and read-back, and the ingest log."""

from __future__ import annotations

import datetime as dt
import hashlib
import io
import re
from dataclasses import replace
from typing import Annotated, Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
from fastapi import APIRouter, HTTPException, Query, Request, Response, status
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse
from pydantic import BaseModel
from sqlalchemy import select
from sqlalchemy.orm import Session

from app.api.deps import Operator, SessionDep, StoreDep, Viewer
from app.api.pagination import MAX_LIMIT, announce_next, paginate
from app.api.routes.spacecraft import get_spacecraft, latest_config
from app.ingest.errors import RowError, UploadError
from app.ingest.formats import decoders
from app.ingest.inflate import GzipBodyError, GzipInflater, InflatedTooLarge
from app.ingest.parse import SUPPORTED_TYPES, UnsupportedMediaType, parse_body
from app.ingest.validate import SensorPolicy, UploadOptions, validate
from app.jobs.outputs import jsonable
from processing.streams import STREAMS, TIME_COLUMN, StreamSpec
from processing.time import timescales
from storage.models import Ingest, Spacecraft
from storage.parquet_store import ParquetStore
from storage.telemetry import ConflictError, IngestMeta, commit_ingest, read_window

router = APIRouter(prefix="/api/v1/spacecraft/{name}", tags=["telemetry"])

SINGLE_SENSOR_KINDS = {"gyro": "gyro", "magnetometer": "magnetometer", "sun_sensor": "sun_sensor"}


class IngestOut(BaseModel):
    ingest_id: str
    stream: str
    sensor: str
    rows: int
    inserted: int
    duplicates: int
    start: str
    end: str
    status: str
    filename: str | None = None
    checksum_sha256: str | None = None
    created_at: dt.datetime | None = None
    notes: list[str] = []


def get_stream(stream: str) -> StreamSpec:
    spec = STREAMS.get(stream)
    if spec is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            f"unknown stream {stream!r}; streams: {', '.join(STREAMS)}")
    return spec


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


def _iso(tai_ns: int) -> str:
    return str(timescales.tai_ns_to_iso(np.array([tai_ns], dtype=np.int64))[0])


def _ingest_out(rec: Ingest) -> IngestOut:
    return IngestOut(ingest_id=rec.id, stream=rec.stream, sensor=rec.sensor, rows=rec.rows,
                     inserted=rec.inserted, duplicates=rec.duplicates, start=_iso(rec.start_tai_ns),
                     end=_iso(rec.end_tai_ns), status=rec.status, filename=rec.filename,
                     checksum_sha256=rec.checksum_sha256, created_at=rec.created_at)


async def read_limited(request: Request, limit: int) -> bytes:
    """The request body, refusing (413) more than ``limit`` bytes without reading it all.

    ``Content-Encoding: gzip`` bodies are inflated as they arrive (every member; trailing bytes are a 422,
    :mod:`app.ingest.inflate`), and the inflated size is held to the same limit, so a small "gzip bomb"
    is refused early; other encodings are 415.
    """
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise HTTPException(413,
                            f"body of {declared} bytes exceeds the limit of {limit} bytes")
    encoding = request.headers.get("content-encoding", "identity").strip().lower()
    if encoding not in ("identity", "gzip"):
        raise HTTPException(status.HTTP_415_UNSUPPORTED_MEDIA_TYPE,
                            f"Content-Encoding {encoding!r} is not supported; use gzip or none")
    inflater = GzipInflater(limit) if encoding == "gzip" else None
    chunks: list[bytes] = []
    size = 0
    try:
        async for chunk in request.stream():
            if inflater is not None:
                chunk = inflater.feed(chunk)
            size += len(chunk)
            if size > limit:
                raise HTTPException(413, f"body exceeds the limit of {limit} bytes")
            chunks.append(chunk)
        if inflater is not None:
            inflater.close()
    except InflatedTooLarge as exc:
        raise HTTPException(413, str(exc)) from None
    except GzipBodyError as exc:
        raise HTTPException(422, str(exc)) from None
    return b"".join(chunks)


def _filename(request: Request, explicit: str | None) -> str | None:
    if explicit:
        return explicit[:255]
    disposition = request.headers.get("content-disposition", "")
    m = re.search(r'filename="?([^";]+)"?', disposition)
    return m.group(1)[:255] if m else None


def _decode(body: bytes, content_type: str, spec: StreamSpec, fmt: str | None,
            opts: UploadOptions) -> tuple[pa.Table, UploadOptions]:
    """The upload as a table of canonical upload columns, by ``format`` or by Content-Type."""
    if fmt is None or fmt == "table":
        return parse_body(body, content_type), opts
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


class TooManyRows(ValueError):
    pass


def ingest_upload(session: Session, store: ParquetStore, sc: Spacecraft, spec: StreamSpec, body: bytes,
               content_type: str, opts: UploadOptions, meta: IngestMeta, config: dict[str, Any],
               fmt: str | None, max_rows: int) -> tuple[Ingest, tuple[str, ...]]:
    """Decode, validate and store one upload (used by the API and the web UI); all or nothing.

    Returns the ingest record and the notes of a file-format decoder. Raises UploadError (422),
    UnsupportedMediaType (415), TooManyRows (413) or ConflictError (409); nothing is stored then."""
    table, opts = _decode(body, content_type, spec, fmt, opts)
    if table.num_rows > max_rows:
        raise TooManyRows(f"{table.num_rows} rows exceed the limit of {max_rows} rows per upload; split the upload")
    checked = validate(table, spec, sensor_policy(spec, config), opts)
    record = commit_ingest(session, store, sc.id, spec, checked.table, checked.row_index, meta)
    return record, opts.notes  # notes: what a file-format decoder did (frames, units)


@router.post("/telemetry/{stream}", status_code=status.HTTP_201_CREATED, response_model=IngestOut,
             responses={409: {"description": "rows conflict with stored samples"},
                        413: {"description": "body too large"}, 415: {"description": "unsupported type"},
                        422: {"description": "invalid rows: nothing stored"}},
             openapi_extra={"requestBody": {"required": True, "content": {
                 t: {"schema": {"type": "string", "format": "binary"}} for t in SUPPORTED_TYPES}}})
async def upload_telemetry(
    name: str, stream: str, request: Request, session: SessionDep, store: StoreDep, who: Operator,
    time_scale: Annotated[str, Query(description="scale of the times: utc, tai, gps, tt")] = "utc",
    sensor: Annotated[str | None, Query(description="sensor name (default: see README)")] = None,
    norm_tolerance: Annotated[float, Query(gt=0, lt=0.5)] = 1e-3,
    quaternion_direction: Annotated[str, Query(
        description="star_tracker only: sensor_to_inertial (q_IS, default) or inertial_to_sensor")]
    = "sensor_to_inertial",
    filename: str | None = None,
    format: Annotated[str | None, Query(
        description="table (default: CSV/Parquet/Arrow/JSON by Content-Type) or a file format; "
                    "see GET /api/v1/formats")] = None,
) -> Any:
    """Upload one batch (CSV, Parquet, Arrow IPC stream, JSON records, or a named file format).

    All or nothing."""
    spec = get_stream(stream)
    sc = get_spacecraft(session, name, who)
    config = latest_config(session, sc).config
    body = await read_limited(request, request.app.state.settings.max_upload_bytes)
    content_type = request.headers.get("content-type", "")
    meta = IngestMeta(filename=_filename(request, filename), content_type=content_type.split(";")[0][:100],
                      size_bytes=len(body), checksum_sha256=hashlib.sha256(body).hexdigest(),
                      time_scale=time_scale, api_key_id=who.key_id)
    opts = UploadOptions(time_scale=time_scale, sensor=sensor, norm_tolerance=norm_tolerance,
                         quaternion_direction=quaternion_direction,
                         n_panels=len(config.get("solar_panels", [])) or None)
    try:
        rec, notes = await run_in_threadpool(ingest_upload, session, store, sc, spec, body, content_type, opts, meta,
                                      config, format, request.app.state.settings.max_upload_rows)
    except TooManyRows as exc:
        raise HTTPException(413, str(exc)) from None
    except UnsupportedMediaType as exc:
        raise HTTPException(status.HTTP_415_UNSUPPORTED_MEDIA_TYPE, str(exc)) from None
    except UploadError as exc:
        return JSONResponse(status_code=422, content={
            "detail": f"upload rejected, nothing stored: {exc}", "error_count": exc.total,
            "errors": [e.as_dict() for e in exc.errors]})
    except ConflictError as exc:
        return JSONResponse(status_code=409, content={
            "detail": f"upload rejected, nothing stored: {exc.total} rows differ from stored samples "
                      "with the same identity (sensor, time)", "conflict_count": exc.total,
            "conflicts": exc.rows})
    out = _ingest_out(rec)
    out.notes = list(notes)
    return out


FORMATS = {"csv": "text/csv", "parquet": "application/vnd.apache.parquet", "json": "application/json"}


def _parse_bound(value: str | None, scale: str, field: str) -> int | None:
    if value is None or value == "":
        return None
    try:
        seconds = float(value)
    except ValueError:
        seconds = None
    try:
        if seconds is not None:
            return int(timescales.seconds_to_tai_ns(np.array([seconds]), scale)[0])
        return int(timescales.iso_to_tai_ns(np.array([value], dtype=object), scale)[0])
    except timescales.TimeValueError as exc:
        raise HTTPException(422, f"{field}: {exc}") from None


@router.get("/telemetry/{stream}", responses={200: {"content": {t: {} for t in FORMATS.values()}}})
def read_telemetry(
    name: str, stream: str, session: SessionDep, store: StoreDep, who: Viewer,
    start: Annotated[str | None, Query(description="ISO 8601 or seconds since 1970 on time_scale")] = None,
    end: Annotated[str | None, Query(description="inclusive end of the window")] = None,
    format: Annotated[str, Query(pattern="^(csv|parquet|json)$")] = "csv",
    time_scale: Annotated[str, Query(pattern="^(utc|tai|gps|tt)$")] = "utc",
    time_format: Annotated[str, Query(pattern="^(iso|seconds)$")] = "iso",
    sensor: str | None = None,
) -> Response:
    """Stored samples in [start, end], sorted by sensor and time, without duplicates.

    ``time`` is ISO 8601 on ``time_scale`` (UTC with a ``Z``; 23:59:60 inside leap seconds) or, with
    ``time_format=seconds``, seconds since 1970-01-01 on that scale.
    """
    spec = get_stream(stream)
    sc = get_spacecraft(session, name, who)
    t0 = _parse_bound(start, time_scale, "start")
    t1 = _parse_bound(end, time_scale, "end")
    if t0 is not None and t1 is not None and t1 < t0:
        raise HTTPException(422, "end is before start")
    table = read_window(session, store, sc.id, spec, t0, t1, sensor)
    return table_response(table, format, time_scale, time_format, f"{name}_{stream}")


def table_response(table: pa.Table, fmt: str, time_scale: str, time_format: str, stem: str) -> Response:
    """A table as a CSV/Parquet/JSON download; ``time_tai_ns`` becomes ``time`` on the requested scale."""
    out = table
    if TIME_COLUMN in table.column_names:
        tai = table.column(TIME_COLUMN).to_numpy()
        if time_format == "iso":
            times = pa.array(timescales.tai_ns_to_iso(tai, time_scale), pa.string())
        else:
            times = pa.array(timescales.tai_ns_to_seconds(tai, time_scale), pa.float64())
        out = table.drop_columns([TIME_COLUMN]).add_column(0, "time", times)
    headers = {"Content-Disposition": f'attachment; filename="{stem}.{fmt}"'}
    if fmt == "json":
        return JSONResponse(jsonable(out.to_pylist()), headers=headers)
    buf = io.BytesIO()
    if fmt == "csv":
        pacsv.write_csv(out, buf)
    else:
        pq.write_table(out, buf)
    return Response(buf.getvalue(), media_type=FORMATS[fmt], headers=headers)


formats_router = APIRouter(prefix="/api/v1/formats", tags=["telemetry"])


@formats_router.get("")
def list_formats(_: Viewer) -> list[dict[str, Any]]:
    """Upload formats besides the generic tables (query ``format=`` of the upload route)."""
    return [{"format": d.name, "streams": list(d.streams), "description": d.description}
            for d in decoders().values()]


@router.get("/ingests", response_model=list[IngestOut])
def list_ingests(name: str, request: Request, response: Response, session: SessionDep, who: Viewer,
                 stream: str | None = None, limit: Annotated[int, Query(ge=1, le=MAX_LIMIT)] = 100,
                 cursor: str | None = None) -> list[IngestOut]:
    """Uploads, newest first; more pages are announced in ``X-Next-Cursor``/``Link``."""
    sc = get_spacecraft(session, name, who)
    q = select(Ingest).where(Ingest.spacecraft_id == sc.id)
    if stream is not None:
        q = q.where(Ingest.stream == get_stream(stream).name)
    rows = list(session.scalars(paginate(q, Ingest.created_at, Ingest.id, cursor, limit)))
    rows = announce_next(request, response, rows, limit, lambda r: (r.created_at, r.id))
    return [_ingest_out(r) for r in rows]
