"""Schedules: cron (UTC) + job template + relative window; one job per tick (app/services/schedules.py,
app/jobs/scheduler.py)."""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, Response, status
from pydantic import BaseModel, Field

from app.api.deps import Operator, SessionDep, SettingsDep, Viewer
from app.services import schedules as service
from app.services.schedules import ScheduleSpec
from storage.models import Schedule

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


@router.post("", status_code=status.HTTP_201_CREATED, response_model=ScheduleOut)
def create(body: ScheduleCreate, session: SessionDep, settings: SettingsDep, who: Operator) -> ScheduleOut:
    s, sc = service.create(session, ScheduleSpec(
        name=body.name, cron=body.cron, job_type=body.type, spacecraft=body.spacecraft, params=body.params,
        reference=body.reference, window=body.window, window_s=body.window_s, enabled=body.enabled), who,
        min_period_s=settings.min_schedule_period_s)
    return _out(s, sc.name)


@router.get("", response_model=list[ScheduleOut])
def list_all(session: SessionDep, who: Viewer) -> list[ScheduleOut]:
    return [_out(s, name) for s, name in service.list_schedules(session, who)]


@router.get("/{schedule}", response_model=ScheduleOut)
def read(schedule: str, session: SessionDep, who: Viewer) -> ScheduleOut:
    s, sc = service.get_schedule(session, schedule, who)
    return _out(s, sc.name)


@router.get("/{schedule}/runs", response_model=list[RunOut])
def list_runs(schedule: str, session: SessionDep, who: Viewer,
              limit: Annotated[int, Query(ge=1, le=1000)] = 100) -> list[RunOut]:
    """The schedule's ticks, newest first: submitted (with the job) or skipped (with the reason)."""
    return [RunOut(fire_at=r.fire_at, status=r.status, job_id=r.job_id, missed=r.missed, message=r.message,
                   fired_by=r.fired_by, created_at=r.created_at,
                   job_url=f"/api/v1/jobs/{r.job_id}" if r.job_id else None)
            for r in service.runs(session, schedule, who, limit)]


@router.delete("/{schedule}", status_code=status.HTTP_204_NO_CONTENT)
def delete(schedule: str, session: SessionDep, who: Operator) -> Response:
    """Delete the schedule and its run log; jobs it submitted stay."""
    service.delete(session, schedule, who)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
