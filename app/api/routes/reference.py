"""Reference data sets: upload (parsed at once; bad files are 422 and nothing is stored), list, read."""

from __future__ import annotations

import datetime as dt
import hashlib
from typing import Annotated, Any

import pyarrow as pa
from fastapi import APIRouter, HTTPException, Query, Request, Response, status
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse
from pydantic import BaseModel
from sqlalchemy import select

from app.api.deps import Admin, Operator, SessionDep, Viewer
from app.api.pagination import MAX_LIMIT, announce_next, paginate
from app.api.routes.telemetry import read_limited, table_response
from app.jobs.outputs import jsonable
from app.reference.registry import reference_kinds
from processing.time import timescales
from storage.models import ReferenceDataset
from storage.reference import ReferenceStore

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


def _iso(t: int | None) -> str | None:
    return None if t is None else str(timescales.tai_ns_to_iso([t])[0])


def _out(d: ReferenceDataset) -> ReferenceOut:
    return ReferenceOut(id=d.id, kind=d.kind, name=d.name, filename=d.filename, size_bytes=d.size_bytes,
                        checksum_sha256=d.checksum_sha256, rows=d.rows, start=_iso(d.start_tai_ns),
                        end=_iso(d.end_tai_ns), details=d.details, created_at=d.created_at)


def store_of(request: Request) -> ReferenceStore:
    return ReferenceStore(request.app.state.settings.reference_url)


@router.get("/kinds")
def list_kinds(_: Viewer) -> list[dict[str, str]]:
    return [{"kind": k.name, "description": k.description} for k in reference_kinds().values()]


@router.post("/{kind}", status_code=status.HTTP_201_CREATED, response_model=ReferenceOut,
             openapi_extra={"requestBody": {"required": True, "content": {
                 "application/octet-stream": {"schema": {"type": "string", "format": "binary"}}}}})
async def upload_reference(kind: str, request: Request, session: SessionDep, who: Operator,
                           name: str | None = None, filename: str | None = None) -> ReferenceOut:
    spec = reference_kinds().get(kind)
    if spec is None:
        raise HTTPException(404, f"unknown reference kind {kind!r}; kinds: {', '.join(sorted(reference_kinds()))}")
    raw = await read_limited(request, request.app.state.settings.max_upload_bytes)
    if not raw.strip():
        raise HTTPException(422, "the request body is empty")
    try:
        parsed = await run_in_threadpool(spec.parse, raw)
    except ValueError as exc:
        raise HTTPException(422, f"not a valid {kind} file: {exc}") from None
    row = await run_in_threadpool(
        store_of(request).save, session, kind=kind, name=(name or filename or kind)[:255], filename=filename,
        raw=raw, columns=parsed.columns, start_tai_ns=parsed.start_tai_ns, end_tai_ns=parsed.end_tai_ns,
        details=jsonable({**parsed.details, "sha256": hashlib.sha256(raw).hexdigest()}), api_key_id=who.key_id)
    session.commit()
    return _out(row)


@router.get("", response_model=list[ReferenceOut])
def list_reference(request: Request, response: Response, session: SessionDep, _: Viewer,
                   kind: str | None = None, limit: Annotated[int, Query(ge=1, le=MAX_LIMIT)] = 100,
                   cursor: str | None = None) -> list[ReferenceOut]:
    """Reference data sets, newest first; more pages are announced in ``X-Next-Cursor``/``Link``."""
    q = select(ReferenceDataset)
    if kind is not None:
        q = q.where(ReferenceDataset.kind == kind)
    rows = list(session.scalars(paginate(q, ReferenceDataset.created_at, ReferenceDataset.id, cursor, limit)))
    return [_out(d) for d in announce_next(request, response, rows, limit, lambda r: (r.created_at, r.id))]


def get_dataset(session: Any, dataset_id: str) -> ReferenceDataset:
    d = session.get(ReferenceDataset, dataset_id)
    if d is None:
        raise HTTPException(404, f"reference data set {dataset_id!r} not found")
    return d


@router.get("/{kind}/{dataset_id}", response_model=ReferenceOut)
def read_reference(kind: str, dataset_id: str, session: SessionDep, _: Viewer) -> ReferenceOut:
    d = get_dataset(session, dataset_id)
    if d.kind != kind:
        raise HTTPException(404, f"reference data set {dataset_id!r} is not of kind {kind!r}")
    return _out(d)


@router.get("/{kind}/{dataset_id}/data")
def reference_data(kind: str, dataset_id: str, request: Request, session: SessionDep, who: Viewer,
                   format: Annotated[str, Query(pattern="^(csv|parquet|json|raw)$")] = "csv") -> Response:
    """The parsed columns (csv, parquet, json; times as UTC) or the file as uploaded (raw)."""
    read_reference(kind, dataset_id, session, who)
    row = get_dataset(session, dataset_id)
    store = store_of(request)
    if format == "raw":
        return FileResponse(store.raw_path(row), media_type="application/octet-stream",
                            filename=row.filename or f"{kind}-{row.id}")
    return table_response(pa.table(store.columns(row)), format, "utc", "iso", f"{kind}-{row.id}")


@router.delete("/{kind}/{dataset_id}", response_model=ReferenceOut)
def delete_reference(kind: str, dataset_id: str, request: Request, session: SessionDep, _: Admin) -> ReferenceOut:
    d = get_dataset(session, dataset_id)
    if d.kind != kind:
        raise HTTPException(404, f"reference data set {dataset_id!r} is not of kind {kind!r}")
    out = _out(d)
    session.delete(d)
    session.commit()
    store_of(request).remove(dataset_id)
    return out
