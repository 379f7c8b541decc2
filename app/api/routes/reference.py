"""Reference data sets: upload (parsed at once; bad files are 422 and nothing is stored), list, read
(app/services/reference.py)."""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request, Response, status
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse
from pydantic import BaseModel

from app.api.deps import Admin, Operator, SessionDep, SettingsDep, Viewer
from app.api.files import download_response, read_limited
from app.api.pagination import MAX_LIMIT, announce_next
from app.services import reference as service
from app.services.downloads import StoredFile
from processing.time import timescales
from storage.models import ReferenceDataset

router = APIRouter(prefix="/api/v1/reference", tags=["reference data"])


class ReferenceOut(BaseModel):
    id: str
    kind: str
    name: str
    filename: str | None
    size_bytes: int
    checksum_sha256: str
    rows: int
    start: str | None
    end: str | None
    details: dict[str, Any]
    created_at: dt.datetime
    spacecraft: str | None = None  # the spacecraft whose jobs may use it; None: shared by all


def _iso(t: int | None) -> str | None:
    return None if t is None else str(timescales.tai_ns_to_iso([t])[0])


def _out(d: ReferenceDataset) -> ReferenceOut:
    return ReferenceOut(spacecraft=d.spacecraft.name if d.spacecraft is not None else None, id=d.id,
                        kind=d.kind, name=d.name, filename=d.filename, size_bytes=d.size_bytes,
                        checksum_sha256=d.checksum_sha256, rows=d.rows, start=_iso(d.start_tai_ns),
                        end=_iso(d.end_tai_ns), details=d.details, created_at=d.created_at)


@router.get("/kinds")
def list_kinds(_: Viewer) -> list[dict[str, str]]:
    return [{"kind": k.name, "description": k.description} for k in service.list_kinds()]


@router.post("/{kind}", status_code=status.HTTP_201_CREATED, response_model=ReferenceOut,
             openapi_extra={"requestBody": {"required": True, "content": {
                 "application/octet-stream": {"schema": {"type": "string", "format": "binary"}}}}})
async def upload_reference(kind: str, request: Request, session: SessionDep, settings: SettingsDep, who: Operator,
                           name: str | None = None, filename: str | None = None,
                           spacecraft: str | None = None) -> ReferenceOut:
    """``spacecraft``: the data set is that spacecraft's (its jobs pick it up); without it the data set is
    shared by every spacecraft, which only an admin may upload."""
    service.get_kind(kind)
    scope = service.upload_scope(session, spacecraft, who)
    raw = await read_limited(request, settings.max_upload_bytes)
    row = await run_in_threadpool(service.upload, session, settings, kind, raw, name, filename, who, scope)
    return _out(row)


@router.get("", response_model=list[ReferenceOut])
def list_reference(request: Request, response: Response, session: SessionDep, who: Viewer,
                   kind: str | None = None, limit: Annotated[int, Query(ge=1, le=MAX_LIMIT)] = 100,
                   cursor: str | None = None) -> list[ReferenceOut]:
    """Reference data sets, newest first; more pages are announced in ``X-Next-Cursor``/``Link``."""
    page = service.list_datasets(session, kind, cursor, limit, who)
    return [_out(d) for d in announce_next(request, response, page, limit)]


@router.get("/{kind}/{dataset_id}", response_model=ReferenceOut)
def read_reference(kind: str, dataset_id: str, session: SessionDep, who: Viewer) -> ReferenceOut:
    return _out(service.read(session, kind, dataset_id, who))


@router.get("/{kind}/{dataset_id}/data")
def reference_data(kind: str, dataset_id: str, session: SessionDep, settings: SettingsDep, who: Viewer,
                   format: Annotated[str, Query(pattern="^(csv|parquet|json|raw)$")] = "csv") -> Response:
    """The parsed columns (csv, parquet, json; times as UTC) or the file as uploaded (raw)."""
    data = service.data(session, settings, kind, dataset_id, format, who)
    if isinstance(data, StoredFile):
        return FileResponse(data.path, media_type=data.media_type, filename=data.filename)
    return download_response(data)


@router.delete("/{kind}/{dataset_id}", response_model=ReferenceOut)
def delete_reference(kind: str, dataset_id: str, session: SessionDep, settings: SettingsDep,
                     who: Admin) -> ReferenceOut:
    return _out(service.delete(session, settings, kind, dataset_id, who))
