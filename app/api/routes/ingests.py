"""Retraction of uploads (operators) and the quarantine of damaged telemetry files (administrators)
(app/services/ingests.py)."""

from __future__ import annotations

import datetime as dt
from typing import Annotated

from fastapi import APIRouter, Query
from pydantic import BaseModel

from app.api.deps import Admin, Operator, SessionDep, StoreDep, Viewer
from app.reports.inputs import describe_retraction
from app.services import ingests as service
from app.services.times import iso
from storage.models import IngestRetraction, TelemetryFile

router = APIRouter(prefix="/api/v1/spacecraft/{name}", tags=["telemetry"])


class RetractionOut(BaseModel):
    retraction_id: str
    ingest_id: str
    stream: str
    sensor: str
    rows: int
    samples_removed: int
    start: str
    end: str
    filename: str | None
    checksum_sha256: str
    files_removed: int
    reason: str
    retracted_by: str | None
    retracted_at: dt.datetime
    uploaded_at: dt.datetime
    jobs_marked: list[str]


class QuarantinedFileOut(BaseModel):
    file_id: int
    ingest_id: str
    stream: str
    path: str
    rows: int
    start: str
    end: str
    reason: str | None
    quarantined_at: dt.datetime | None


def _retraction_out(session: SessionDep, r: IngestRetraction) -> RetractionOut:
    d = describe_retraction(r)
    return RetractionOut(**{k: v for k, v in d.items() if k in RetractionOut.model_fields},
                         jobs_marked=service.marked_jobs(session, r))


def _file_out(f: TelemetryFile) -> QuarantinedFileOut:
    return QuarantinedFileOut(file_id=f.id, ingest_id=f.ingest_id, stream=f.stream, path=f.path, rows=f.rows,
                              start=iso(f.t_min_tai_ns), end=iso(f.t_max_tai_ns), reason=f.quarantined,
                              quarantined_at=f.quarantined_at)


@router.delete("/ingests/{ingest_id}", response_model=RetractionOut,
               responses={409: {"description": "already retracted"}})
def retract_ingest(name: str, ingest_id: str, session: SessionDep, store: StoreDep, who: Operator,
                   reason: Annotated[str, Query(min_length=3, max_length=4000,
                                                description="why the upload is retracted (kept in the log)")]
                   ) -> RetractionOut:
    """Retract an upload: its samples stop being visible to reads and new jobs; the retraction is logged
    (who, when, why) and jobs that had used the samples are marked as based on retracted data."""
    return _retraction_out(session, service.retract(session, store, name, ingest_id, reason, who))


@router.get("/retractions", response_model=list[RetractionOut])
def list_retractions(name: str, session: SessionDep, who: Viewer,
                     limit: Annotated[int, Query(ge=1, le=1000)] = 100) -> list[RetractionOut]:
    """The retraction log of the spacecraft, newest first."""
    return [_retraction_out(session, r) for r in service.retractions(session, name, who, limit)]


@router.get("/quarantine", response_model=list[QuarantinedFileOut])
def list_quarantined(name: str, session: SessionDep, who: Admin) -> list[QuarantinedFileOut]:
    """Telemetry files found damaged (their reads fail with 503 until restored or retracted)."""
    return [_file_out(f) for f in service.quarantined(session, name, who)]


@router.post("/quarantine/{file_id}/restore", response_model=QuarantinedFileOut,
             responses={409: {"description": "the file is still damaged"}})
def restore_quarantined(name: str, file_id: int, session: SessionDep, store: StoreDep,
                        who: Admin) -> QuarantinedFileOut:
    """Lift the quarantine of a file that reads again (e.g. restored from a backup). To give up on it,
    retract its ingest (``DELETE /ingests/{ingest_id}``)."""
    return _file_out(service.restore(session, store, name, file_id, who))
