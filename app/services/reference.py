"""Reference data sets (Earth orientation, GNSS navigation, ...): upload (parsed at once; bad files
are refused and nothing is stored), list, read, download, delete."""

from __future__ import annotations

import hashlib
from typing import Any

import pyarrow as pa
from sqlalchemy import or_, select, true
from sqlalchemy.orm import Session

from app.jobs.outputs import jsonable
from app.reference.registry import ReferenceKind, reference_kinds
from app.services.access import Principal
from app.services.downloads import Download, StoredFile, table_download
from app.services.errors import Forbidden, Invalid, NotFound
from app.services.pages import Page, page_of, paginate
from app.services.spacecraft import get_spacecraft
from app.settings import Settings
from storage.models import ReferenceDataset
from storage.reference import ReferenceStore


def list_kinds() -> list[ReferenceKind]:
    return list(reference_kinds().values())


def get_kind(kind: str) -> ReferenceKind:
    spec = reference_kinds().get(kind)
    if spec is None:
        raise NotFound(f"unknown reference kind {kind!r}; kinds: {', '.join(sorted(reference_kinds()))}")
    return spec


def store(settings: Settings) -> ReferenceStore:
    return ReferenceStore(settings.reference_url)


def upload_scope(session: Session, spacecraft: str | None, who: Principal) -> int | None:
    """The spacecraft id an upload is scoped to (None: shared). Shared data sets are an admin's: every
    spacecraft's jobs pick them up; others name a spacecraft the key is granted (NotFound otherwise)."""
    if spacecraft is None:
        if who.role != "admin":
            raise Forbidden("reference data shared by every spacecraft are uploaded by an admin; operators name "
                            "their spacecraft (query parameter spacecraft=)")
        return None
    return get_spacecraft(session, spacecraft, who).id


def upload(session: Session, settings: Settings, kind: str, raw: bytes, name: str | None, filename: str | None,
           who: Principal, spacecraft_id: int | None = None) -> ReferenceDataset:
    """Parse and store one file of ``kind`` (blocking: run it off the event loop); Invalid for an empty or
    unparsable file, and nothing is stored then. ``spacecraft_id`` from :func:`upload_scope`."""
    spec = get_kind(kind)
    if not raw.strip():
        raise Invalid("the request body is empty")
    try:
        parsed = spec.parse(raw)
    except ValueError as exc:
        raise Invalid(f"not a valid {kind} file: {exc}") from None
    row = store(settings).save(
        session, kind=kind, name=(name or filename or kind)[:255], filename=filename, raw=raw,
        columns=parsed.columns, start_tai_ns=parsed.start_tai_ns, end_tai_ns=parsed.end_tai_ns,
        details=jsonable({**parsed.details, "sha256": hashlib.sha256(raw).hexdigest()}), api_key_id=who.key_id,
        spacecraft_id=spacecraft_id)
    session.commit()
    return row


def _visible(who: Principal) -> Any:
    if who.spacecraft_ids is None:
        return true()
    return or_(ReferenceDataset.spacecraft_id.is_(None), ReferenceDataset.spacecraft_id.in_(who.spacecraft_ids))


def list_datasets(session: Session, kind: str | None, cursor: str | None, limit: int,
                  who: Principal) -> Page[ReferenceDataset]:
    """Reference data sets the caller may see (shared ones and its spacecraft's), newest first."""
    q = select(ReferenceDataset).where(_visible(who))
    if kind is not None:
        q = q.where(ReferenceDataset.kind == kind)
    rows = list(session.scalars(paginate(q, ReferenceDataset.created_at, ReferenceDataset.id, cursor, limit)))
    return page_of(rows, limit, lambda r: (r.created_at, r.id))


def get_dataset(session: Session, dataset_id: str, who: Principal) -> ReferenceDataset:
    d = session.get(ReferenceDataset, dataset_id)
    if d is None or (d.spacecraft_id is not None and not who.may_use(d.spacecraft_id)):
        raise NotFound(f"reference data set {dataset_id!r} not found")
    return d


def read(session: Session, kind: str, dataset_id: str, who: Principal) -> ReferenceDataset:
    """The data set ``dataset_id``, which must be of ``kind`` and visible to the caller."""
    d = get_dataset(session, dataset_id, who)
    if d.kind != kind:
        raise NotFound(f"reference data set {dataset_id!r} is not of kind {kind!r}")
    return d


def data(session: Session, settings: Settings, kind: str, dataset_id: str, fmt: str,
         who: Principal) -> Download | StoredFile:
    """The parsed columns (csv, parquet, json; times as UTC) or the file as uploaded (raw)."""
    row = read(session, kind, dataset_id, who)
    files = store(settings)
    if fmt == "raw":
        return StoredFile(files.raw_path(row), "application/octet-stream", row.filename or f"{kind}-{row.id}")
    return table_download(pa.table(files.columns(row)), fmt, "utc", "iso", f"{kind}-{row.id}")


def delete(session: Session, settings: Settings, kind: str, dataset_id: str, who: Principal) -> ReferenceDataset:
    """Delete the data set (catalog row, then its files); returns it as it was."""
    d = read(session, kind, dataset_id, who)
    session.delete(d)
    session.commit()
    store(settings).remove(dataset_id)
    return d
