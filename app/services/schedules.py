"""Schedules: cron (UTC) + job template + relative window; one job per tick (app/jobs/scheduler.py)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sqlalchemy import delete as sa_delete
from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from app.jobs.scheduler import MIN_PERIOD_S, CronError, check_cron, next_tick
from app.names import has_control_characters
from app.services.access import Principal
from app.services.errors import Conflict, Invalid, NotFound
from app.services.jobs import get_job_type, validated_params
from app.services.spacecraft import get_spacecraft
from storage import schedules as schedstore
from storage.models import ReferenceDataset, Schedule, ScheduleRun, Spacecraft, utcnow
from storage.reference import usable_by


@dataclass(frozen=True)
class ScheduleSpec:
    """A new schedule: ``window`` previous (the window_s before the tick, default since the previous
    tick) or since_last_success (from the end of the last succeeded run)."""

    name: str
    cron: str
    job_type: str
    spacecraft: str
    params: dict[str, Any]
    reference: dict[str, str]
    window: str
    window_s: int | None
    enabled: bool


def get_schedule(session: Session, id_or_name: str, who: Principal) -> tuple[Schedule, Spacecraft]:
    """The schedule (by id or name) if the caller may use its spacecraft; NotFound otherwise."""
    s = schedstore.find_schedule(session, id_or_name)
    sc = session.get(Spacecraft, s.spacecraft_id) if s is not None else None
    if s is None or sc is None or not who.may_use(sc.id):
        raise NotFound(f"schedule {id_or_name!r} not found")
    return s, sc


def create(session: Session, spec: ScheduleSpec, who: Principal,
           min_period_s: float = MIN_PERIOD_S) -> tuple[Schedule, Spacecraft]:
    """Store a schedule; its cron (ticks at least ``min_period_s`` apart), job type, parameters and
    reference kinds are checked now."""
    if spec.name.strip(".") == "" or has_control_characters(spec.name):
        raise Invalid(f"name: {spec.name!r} is not a schedule name (not only dots, no control characters)")
    try:
        cron = check_cron(spec.cron, min_period_s)
    except CronError as exc:
        raise Invalid(f"cron: {exc}") from None
    jt = get_job_type(spec.job_type)
    params = validated_params(jt, spec.params).model_dump(mode="json")
    unknown = sorted(set(spec.reference) - set(jt.reference))
    if unknown:
        raise Invalid(f"job {jt.name} uses no reference data of kind {', '.join(unknown)}")
    sc = get_spacecraft(session, spec.spacecraft, who)
    for kind, wanted in spec.reference.items():
        pinned = session.get(ReferenceDataset, wanted) if wanted != "none" else None
        if wanted != "none" and (pinned is None or pinned.kind != kind or not usable_by(pinned, sc.id)):
            raise Invalid(f"reference.{kind}: no {kind} data set with id {wanted!r} for {sc.name}")
    if schedstore.find_schedule(session, spec.name) is not None:
        raise Conflict(f"a schedule named {spec.name!r} exists")
    schedule = schedstore.create_schedule(
        session, name=spec.name, cron=cron, job_type=jt.name, spacecraft_id=sc.id, params=params,
        reference=dict(spec.reference), window=spec.window, window_s=spec.window_s,
        next_fire_at=next_tick(cron, utcnow()), api_key_id=who.key_id, enabled=spec.enabled)
    try:
        session.commit()
    except IntegrityError:
        session.rollback()
        raise Conflict(f"a schedule named {spec.name!r} exists") from None
    return schedule, sc


def list_schedules(session: Session, who: Principal) -> list[tuple[Schedule, str]]:
    """The schedules of the caller's spacecraft, with the spacecraft's name."""
    names: dict[int, str] = dict(session.execute(select(Spacecraft.id, Spacecraft.name)).all())
    return [(s, names[s.spacecraft_id]) for s in schedstore.list_schedules(session, who.spacecraft_ids)]


def runs(session: Session, id_or_name: str, who: Principal, limit: int) -> list[ScheduleRun]:
    """The schedule's ticks, newest first: submitted (with the job) or skipped (with the reason)."""
    s, _ = get_schedule(session, id_or_name, who)
    return list(schedstore.runs(session, s.id, limit))


def delete(session: Session, id_or_name: str, who: Principal) -> None:
    """Delete the schedule and its run log; jobs it submitted stay."""
    s, _ = get_schedule(session, id_or_name, who)
    session.execute(sa_delete(ScheduleRun).where(ScheduleRun.schedule_id == s.id))
    session.delete(s)
    session.commit()
