"""Schedules in the catalog: CRUD and the one-run-per-tick guarantee.

A tick of a schedule fires when a row ``schedule_run(schedule_id, fire_at)`` is inserted; the unique
constraint on that pair makes the insert succeed in exactly one transaction, whatever the number of
service instances. The job the tick submits is inserted in the same transaction, so a losing
instance rolls its job back with its run row. Cron arithmetic lives in ``app.jobs.scheduler``.
"""

from __future__ import annotations

import datetime as dt
from typing import Any

from sqlalchemy import func, or_, select, update
from sqlalchemy.orm import Session

from storage.models import Job, Schedule, ScheduleRun

WINDOWS = ("previous", "since_last_success")


def create_schedule(session: Session, *, name: str, cron: str, job_type: str, spacecraft_id: int,
                    params: dict[str, Any], reference: dict[str, str], window: str, window_s: int | None,
                    next_fire_at: dt.datetime, api_key_id: str | None, enabled: bool = True) -> Schedule:
    if window not in WINDOWS:
        raise ValueError(f"window must be one of {', '.join(WINDOWS)}, got {window!r}")
    schedule = Schedule(name=name, cron=cron, job_type=job_type, spacecraft_id=spacecraft_id, params=params,
                        reference=reference, window=window, window_s=window_s, enabled=enabled,
                        next_fire_at=next_fire_at, api_key_id=api_key_id)
    session.add(schedule)
    session.flush()
    return schedule


def find_schedule(session: Session, id_or_name: str) -> Schedule | None:
    return session.scalar(select(Schedule).where(or_(Schedule.id == id_or_name, Schedule.name == id_or_name)))


def list_schedules(session: Session, spacecraft_ids: frozenset[int] | None = None) -> list[Schedule]:
    q = select(Schedule).order_by(Schedule.created_at, Schedule.id)
    if spacecraft_ids is not None:
        q = q.where(Schedule.spacecraft_id.in_(spacecraft_ids))
    return list(session.scalars(q))


def due_ids(session: Session, now: dt.datetime) -> list[str]:
    return list(session.scalars(select(Schedule.id).where(Schedule.enabled.is_(True), Schedule.next_fire_at <= now)
                                .order_by(Schedule.next_fire_at)))


def add_run(session: Session, *, schedule_id: str, fire_at: dt.datetime, status: str, missed: int,
            fired_by: str, message: str | None = None) -> ScheduleRun:
    """Insert the run row of a tick and flush: raises IntegrityError when the tick already fired."""
    run = ScheduleRun(schedule_id=schedule_id, fire_at=fire_at, status=status, missed=missed, fired_by=fired_by,
                      message=message)
    session.add(run)
    session.flush()
    return run


def advance(session: Session, schedule_id: str, next_fire_at: dt.datetime) -> None:
    """Move the schedule's next tick forward (never backward: instances may race)."""
    session.execute(update(Schedule).where(Schedule.id == schedule_id,
                                           or_(Schedule.next_fire_at.is_(None), Schedule.next_fire_at < next_fire_at))
                    .values(next_fire_at=next_fire_at))


def last_success_end_tai_ns(session: Session, schedule_id: str) -> int | None:
    """End of the window of the schedule's newest succeeded job (for "since the last successful run")."""
    value = session.scalar(select(func.max(Job.end_tai_ns)).join(ScheduleRun, ScheduleRun.job_id == Job.id)
                           .where(ScheduleRun.schedule_id == schedule_id, Job.status == "succeeded"))
    return int(value) if value is not None else None


def runs(session: Session, schedule_id: str, limit: int = 100) -> list[ScheduleRun]:
    return list(session.scalars(select(ScheduleRun).where(ScheduleRun.schedule_id == schedule_id)
                                .order_by(ScheduleRun.fire_at.desc()).limit(limit)))
