"""Telemetry upload and read-back, and the ingest log (app/services/telemetry.py)."""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, Request, Response, status
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse, StreamingResponse
from pydantic import BaseModel

from app.api.deps import Operator, SessionDep, SettingsDep, StoreDep, Viewer
from app.api.files import download_response, spool_limited, upload_filename
from app.api.pagination import MAX_LIMIT, announce_next
from app.ingest.errors import UploadError
from app.ingest.parse import SUPPORTED_TYPES
from app.services import telemetry as service
from app.services.downloads import FORMATS, STREAMED_FORMATS, stream_chunks, table_download
from app.services.spacecraft import get_spacecraft, latest_config
from app.services.times import iso
from storage.models import Ingest
from storage.telemetry import ConflictError, IngestMeta

router = APIRouter(prefix="/api/v1/spacecraft/{name}", tags=["telemetry"])


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


def _ingest_out(rec: Ingest) -> IngestOut:
    return IngestOut(ingest_id=rec.id, stream=rec.stream, sensor=rec.sensor, rows=rec.rows,
                     inserted=rec.inserted, duplicates=rec.duplicates, start=iso(rec.start_tai_ns),
                     end=iso(rec.end_tai_ns), status=rec.status, filename=rec.filename,
                     checksum_sha256=rec.checksum_sha256, created_at=rec.created_at)


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
    spec = service.get_stream(stream)
    sc = get_spacecraft(session, name, who)
    config = latest_config(session, sc).config
    settings = request.app.state.settings
    # spooled to a temporary file as it arrives (checksum on the way), then decoded in batches
    body = await spool_limited(request, settings.max_upload_bytes, settings.data_dir / "tmp")
    content_type = request.headers.get("content-type", "")
    meta = IngestMeta(filename=upload_filename(request, filename), content_type=content_type.split(";")[0][:100],
                      size_bytes=body.size, checksum_sha256=body.sha256, time_scale=time_scale, api_key_id=who.key_id)
    opts = service.upload_options(config, time_scale, sensor, norm_tolerance, quaternion_direction)
    try:
        rec, notes = await run_in_threadpool(service.ingest_upload, session, store, sc, spec, body, content_type,
                                             opts, meta, config, format, settings.max_upload_rows,
                                             settings.max_upload_days, settings.ingest_batch_rows)
    except UploadError as exc:
        return JSONResponse(status_code=422, content={
            "detail": f"upload rejected, nothing stored: {exc}", "error_count": exc.total,
            "errors": [e.as_dict() for e in exc.errors]})
    except ConflictError as exc:
        return JSONResponse(status_code=409, content={
            "detail": f"upload rejected, nothing stored: {exc.total} rows differ from stored samples "
                      "with the same identity (sensor, time)", "conflict_count": exc.total,
            "conflicts": exc.rows})
    finally:
        body.close()
    out = _ingest_out(rec)
    out.notes = list(notes)
    return out


@router.get("/telemetry/{stream}", responses={200: {"content": {t: {} for t in FORMATS.values()}}})
def read_telemetry(
    name: str, stream: str, session: SessionDep, store: StoreDep, settings: SettingsDep, who: Viewer,
    start: Annotated[str | None, Query(description="ISO 8601 or seconds since 1970 on time_scale")] = None,
    end: Annotated[str | None, Query(description="inclusive end of the window")] = None,
    format: Annotated[Literal["csv", "parquet", "arrow", "json"], Query(
        description="parquet/arrow: `time` a timestamp (ns; UTC, or naive readings of tai/gps/tt) beside the "
                    "exact `time_tai_ns`; csv/json: `time` as text or seconds (time_format)")] = "csv",
    time_scale: Annotated[str, Query(pattern="^(utc|tai|gps|tt)$")] = "utc",
    time_format: Annotated[Literal["iso", "seconds", "tai_ns"], Query(
        description="csv/json: `time` as ISO 8601 or seconds since 1970 on time_scale; tai_ns: ISO `time` "
                    "followed by the exact `time_tai_ns`")] = "iso",
    sensor: str | None = None,
) -> Response:
    """Stored samples in [start, end], sorted by sensor and time, without duplicates.

    CSV/JSON: ``time`` is ISO 8601 on ``time_scale`` (UTC with a ``Z``; 23:59:60 inside leap seconds) or, with
    ``time_format=seconds``, seconds since 1970-01-01 on that scale. Parquet/Arrow: ``time`` is a timestamp
    (ns; tz UTC on the UTC scale, where a leap second holds at the next midnight) and ``time_tai_ns`` the
    exact integer TAI nanoseconds; such a file uploads again unchanged.
    """
    if format in STREAMED_FORMATS:  # a large window is written as it is read: constant memory
        chunks = service.read_chunks(session, store, name, stream, who, start, end, time_scale, sensor,
                                     stream_above_rows=settings.stream_read_rows)
        if chunks is not None:
            return StreamingResponse(stream_chunks(chunks, format, time_scale, time_format),
                                     media_type=FORMATS[format], headers={
                                         "Content-Disposition": f'attachment; filename="{name}_{stream}.{format}"'})
    table = service.read(session, store, name, stream, who, start, end, time_scale, sensor,
                         max_rows=settings.max_read_rows)
    return download_response(table_download(table, format, time_scale, time_format, f"{name}_{stream}"))


formats_router = APIRouter(prefix="/api/v1/formats", tags=["telemetry"])


@formats_router.get("")
def list_formats(_: Viewer) -> list[dict[str, Any]]:
    """Upload formats besides the generic tables (query ``format=`` of the upload route)."""
    return [{"format": d.name, "streams": list(d.streams), "description": d.description}
            for d in service.list_formats()]


@router.get("/ingests", response_model=list[IngestOut])
def list_ingests(name: str, request: Request, response: Response, session: SessionDep, who: Viewer,
                 stream: str | None = None, limit: Annotated[int, Query(ge=1, le=MAX_LIMIT)] = 100,
                 cursor: str | None = None) -> list[IngestOut]:
    """Uploads, newest first; more pages are announced in ``X-Next-Cursor``/``Link``."""
    page = service.list_ingests(session, name, who, stream, cursor, limit)
    return [_ingest_out(r) for r in announce_next(request, response, page, limit)]
