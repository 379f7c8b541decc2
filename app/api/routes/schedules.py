"""Schedules: cron (UTC) + job template + relative window; one job per tick (app/jobs/scheduler.py)."""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any, Literal

from fastapi import APIRouter, HTTPException, Query, Response, status
from pydantic import BaseModel, Field, ValidationError
from sqlalchemy import delete as sa_delete
from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from app.api.deps import Operator, Principal, SessionDep, Viewer
from app.api.routes.spacecraft import get_spacecraft
from app.jobs.registry import registry
from app.jobs.scheduler import CronError, check_cron, next_tick
from storage import schedules as schedstore
from storage.models import Schedule, ScheduleRun, Spacecraft, utcnow

router = APIRouter(prefix="/api/v1/schedules", tags=["schedules"])


class ScheduleCreate(BaseModel):
    name: str = Field(min_length=1, max_length=100, pattern=r"^[A-Za-z0-9_.:-]+$")
    cron: str = Field(max_length=120, description="cron expression in UTC: 5 fields, 6 with seconds last, "
                                                  "or @hourly/@daily/...; e.g. '0 2 * * *' = 02:00 UTC daily")
    type: str = Field(description="job type (GET /api/v1/jobs/types)")
    spacecraft: str
    params: dict[str, Any] = Field(default_factory=dict)
    reference: dict[str, str] = Field(default_factory=dict, description="reference kind -> data set id or 'none'; "
                                                                        "others: the newest covering the window")
    window: Literal["previous", "since_last_success"] = Field(
        "previous", description="previous: the window_s before the tick (default: since the previous tick); "
                                "since_last_success: from the end of the last succeeded run (first run: window_s "
                                "before the tick, or all stored data)")
    window_s: int | None = Field(None, gt=0, le=366 * 86_400, description="window length in seconds")
    enabled: bool = True


class ScheduleOut(BaseModel):
    id: str
    name: str
    cron: str
    type: str
    spacecraft: str
    params: dict[str, Any]
    reference: dict[str, Any]
    window: str
    window_s: int | None
    enabled: bool
    next_fire_at: dt.datetime | None
    created_at: dt.datetime
    runs_url: str


class RunOut(BaseModel):
    fire_at: dt.datetime
    status: str
    job_id: str | None
    missed: int
    message: str | None
    fired_by: str
    created_at: dt.datetime
    job_url: str | None


def _out(s: Schedule, spacecraft: str) -> ScheduleOut:
    return ScheduleOut(id=s.id, name=s.name, cron=s.cron, type=s.job_type, spacecraft=spacecraft, params=s.params,
                       reference=s.reference or {}, window=s.window, window_s=s.window_s, enabled=s.enabled,
                       next_fire_at=s.next_fire_at, created_at=s.created_at, runs_url=f"/api/v1/schedules/{s.id}/runs")


def _get(session: Session, id_or_name: str, who: Principal) -> tuple[Schedule, Spacecraft]:
    s = schedstore.find_schedule(session, id_or_name)
    sc = session.get(Spacecraft, s.spacecraft_id) if s is not None else None
    if s is None or sc is None or not who.may_use(sc.id):
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"schedule {id_or_name!r} not found")
    return s, sc


@router.post("", status_code=status.HTTP_201_CREATED, response_model=ScheduleOut)
def create(body: ScheduleCreate, session: SessionDep, who: Operator) -> ScheduleOut:
    try:
        cron = check_cron(body.cron)
    except CronError as exc:
        raise HTTPException(422, f"cron: {exc}") from None
    jobs = registry()
    jt = jobs.get(body.type)
    if jt is None:
        raise HTTPException(422, f"unknown job type {body.type!r}; types: {', '.join(sorted(jobs))}")
    try:
        params = jt.params.model_validate(body.params).model_dump(mode="json")
    except ValidationError as exc:
        errors = [{"row": None, "column": "params." + ".".join(str(p) for p in e["loc"]), "message": e["msg"]}
                  for e in exc.errors()]
        raise HTTPException(422, {"message": f"invalid params for {jt.name}", "errors": errors}) from None
    unknown = sorted(set(body.reference) - set(jt.reference))
    if unknown:
        raise HTTPException(422, f"job {jt.name} uses no reference data of kind {', '.join(unknown)}")
    sc = get_spacecraft(session, body.spacecraft, who)
    if schedstore.find_schedule(session, body.name) is not None:
        raise HTTPException(status.HTTP_409_CONFLICT, f"a schedule named {body.name!r} exists")
    schedule = schedstore.create_schedule(
        session, name=body.name, cron=cron, job_type=jt.name, spacecraft_id=sc.id, params=params,
        reference=dict(body.reference), window=body.window, window_s=body.window_s,
        next_fire_at=next_tick(cron, utcnow()), api_key_id=who.key_id, enabled=body.enabled)
    try:
        session.commit()
    except IntegrityError:
        session.rollback()
        raise HTTPException(status.HTTP_409_CONFLICT, f"a schedule named {body.name!r} exists") from None
    return _out(schedule, sc.name)


@router.get("", response_model=list[ScheduleOut])
def list_all(session: SessionDep, who: Viewer) -> list[ScheduleOut]:
    names: dict[int, str] = dict(session.execute(select(Spacecraft.id, Spacecraft.name)).all())
    return [_out(s, names[s.spacecraft_id]) for s in schedstore.list_schedules(session, who.spacecraft_ids)]


@router.get("/{schedule}", response_model=ScheduleOut)
def read(schedule: str, session: SessionDep, who: Viewer) -> ScheduleOut:
    s, sc = _get(session, schedule, who)
    return _out(s, sc.name)


@router.get("/{schedule}/runs", response_model=list[RunOut])
def list_runs(schedule: str, session: SessionDep, who: Viewer,
              limit: Annotated[int, Query(ge=1, le=1000)] = 100) -> list[RunOut]:
    """The schedule's ticks, newest first: submitted (with the job) or skipped (with the reason)."""
    s, _ = _get(session, schedule, who)
    return [RunOut(fire_at=r.fire_at, status=r.status, job_id=r.job_id, missed=r.missed, message=r.message,
                   fired_by=r.fired_by, created_at=r.created_at,
                   job_url=f"/api/v1/jobs/{r.job_id}" if r.job_id else None)
            for r in schedstore.runs(session, s.id, limit)]


@router.delete("/{schedule}", status_code=status.HTTP_204_NO_CONTENT)
def delete(schedule: str, session: SessionDep, who: Operator) -> Response:
    """Delete the schedule and its run log; jobs it submitted stay."""
    s, _ = _get(session, schedule, who)
    session.execute(sa_delete(ScheduleRun).where(ScheduleRun.schedule_id == s.id))
    session.delete(s)
    session.commit()
    return Response(status_code=status.HTTP_204_NO_CONTENT)
