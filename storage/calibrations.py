"""Calibration versions of spacecraft sensors."""

from __future__ import annotations

from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from storage.models import Calibration


def add_version(session: Session, spacecraft_id: int, kind: str, values: dict[str, Any],
                job_id: str | None) -> Calibration:
    """Store ``values`` as the next version of the spacecraft's ``kind`` calibration."""
    version = (session.scalar(select(func.max(Calibration.version)).where(
        Calibration.spacecraft_id == spacecraft_id, Calibration.kind == kind)) or 0) + 1
    row = Calibration(spacecraft_id=spacecraft_id, kind=kind, version=version, values=values, job_id=job_id)
    session.add(row)
    session.flush()
    return row


def latest(session: Session, spacecraft_id: int, kind: str) -> Calibration | None:
    return session.scalar(select(Calibration).where(Calibration.spacecraft_id == spacecraft_id,
                                                    Calibration.kind == kind)
                          .order_by(Calibration.version.desc()).limit(1))


def versions(session: Session, spacecraft_id: int, kind: str | None = None) -> list[Calibration]:
    q = select(Calibration).where(Calibration.spacecraft_id == spacecraft_id)
    if kind is not None:
        q = q.where(Calibration.kind == kind)
    return list(session.scalars(q.order_by(Calibration.kind, Calibration.version.desc())))
