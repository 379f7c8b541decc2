"""Retraction of mistaken uploads and the quarantine of damaged telemetry files.

A retraction removes an ingest's samples from every later read and job (storage.telemetry.retract_ingest),
logs who retracted it, when and why, and marks the jobs that had read those samples as based on
retracted data; nothing else changes. Damaged files (found unreadable and quarantined by a read) are
listed for administrators, who restore them (once the file reads again, e.g. from a backup) or retract
their ingest.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from app.jobs.registry import registry
from app.jobs.runner import stream_names
from app.reports.inputs import retracted_by_job
from app.services.access import Principal
from app.services.errors import Conflict, Invalid, NotFound
from app.services.spacecraft import get_spacecraft
from storage import telemetry as store_telemetry
from storage.errors import DamagedFileError
from storage.models import Ingest, IngestRetraction, JobRetraction, TelemetryFile
from storage.parquet_store import ParquetStore

MIN_REASON = 3


def _reads(job_type: str) -> tuple[str, ...]:
    jt = registry().get(job_type)
    return stream_names(jt) if jt is not None else ()


def retract(session: Session, store: ParquetStore, name: str, ingest_id: str, reason: str,
            who: Principal) -> IngestRetraction:
    """Retract one upload of the spacecraft; ``reason`` is required (kept in the log)."""
    sc = get_spacecraft(session, name, who)
    reason = (reason or "").strip()
    if len(reason) < MIN_REASON:
        raise Invalid(f"reason: say why the upload is retracted (at least {MIN_REASON} characters), got {reason!r}")
    record = session.get(Ingest, ingest_id)
    if record is None or record.spacecraft_id != sc.id:
        done = store_telemetry.retraction_of(session, ingest_id)
        if done is not None and done.spacecraft_id == sc.id:
            raise Conflict(f"ingest {ingest_id} was already retracted at {done.retracted_at.isoformat()}")
        raise NotFound(f"spacecraft {name!r} has no ingest {ingest_id!r}")
    store_telemetry.retract_ingest(session, store, ingest_id, reason=reason, retracted_by=who.key_id,
                                   retracted_by_name=who.name, reads=_reads)
    retraction = store_telemetry.retraction_of(session, ingest_id)
    assert retraction is not None
    return retraction


def retractions(session: Session, name: str, who: Principal, limit: int = 100) -> list[IngestRetraction]:
    """The spacecraft's retractions, newest first."""
    sc = get_spacecraft(session, name, who)
    return list(session.scalars(select(IngestRetraction).where(IngestRetraction.spacecraft_id == sc.id)
                                .order_by(IngestRetraction.retracted_at.desc()).limit(limit)))


def marked_jobs(session: Session, retraction: IngestRetraction) -> list[str]:
    """Ids of the jobs marked as based on the retracted samples."""
    return list(session.scalars(select(JobRetraction.job_id).where(JobRetraction.retraction_id == retraction.id)))


def retracted_inputs(session: Session, job_ids: Iterable[str]) -> dict[str, list[dict[str, Any]]]:
    """job id -> its retracted inputs (described), for jobs that have any."""
    return retracted_by_job(session, job_ids)


def quarantined(session: Session, name: str, who: Principal) -> list[TelemetryFile]:
    """The spacecraft's damaged (quarantined) telemetry files, oldest first."""
    sc = get_spacecraft(session, name, who)
    return store_telemetry.quarantined_files(session, sc.id)


def restore(session: Session, store: ParquetStore, name: str, file_id: int, who: Principal) -> TelemetryFile:
    """Lift the quarantine of a file that reads again; Conflict (nothing changed) while it is still damaged."""
    sc = get_spacecraft(session, name, who)
    f = session.get(TelemetryFile, file_id)
    if f is None or f.spacecraft_id != sc.id or not f.quarantined:
        raise NotFound(f"spacecraft {name!r} has no quarantined telemetry file {file_id}")
    try:
        restored = store_telemetry.restore_file(session, store, file_id)
    except DamagedFileError as exc:
        session.rollback()
        raise Conflict(f"file {f.path} is still damaged ({exc.reason}); replace it from a backup, or retract "
                       f"its ingest {f.ingest_id}") from None
    session.commit()
    return restored
