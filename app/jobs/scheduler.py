"""Cron schedules: a small loop driven by the catalog that submits one job per tick.

Why not a scheduling library's job store (APScheduler and the like)? The guarantee we need — one run
per tick however many service instances share the catalog — is a database property: the unique
``(schedule_id, fire_at)`` of ``schedule_run`` (storage/schedules.py). Everything else is small:
cron arithmetic comes from ``croniter`` (UTC; five fields, or six with seconds last, or ``@daily``
and friends), and each instance polls the due schedules once per ``scheduler_poll_s``.

Firing a tick, in one transaction: lock the schedule row (``FOR UPDATE SKIP LOCKED`` on PostgreSQL,
so a second instance skips it instead of waiting), take the newest tick not after now (missed ticks
are coalesced into it and counted in ``missed``), insert the run row (the unique constraint makes a
racing instance fail here and roll back), insert the job from the template and the relative window,
and move ``next_fire_at`` to the following tick. When the window cannot make a valid job (no data,
unknown type, invalid parameters) the run is stored as ``skipped`` with the reason and no job.
"""

from __future__ import annotations

import datetime as dt
import logging
import os
import re
import socket
import threading
import uuid
from collections.abc import Callable
from typing import Any

import numpy as np
from croniter import CroniterError, croniter
from pydantic import ValidationError
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError, OperationalError
from sqlalchemy.orm import Session, sessionmaker

from app.jobs.registry import registry
from app.jobs.runner import stream_names
from app.settings import Settings
from app.version import __version__
from processing.time import timescales
from storage import schedules as schedstore
from storage.models import Job, ReferenceDataset, Schedule, ScheduleRun, SpacecraftConfig, TelemetryFile, utcnow
from storage.reference import latest_covering, usable_by

log = logging.getLogger("attitude.scheduler")

MAX_COUNTED_MISSES = 10_000  # beyond this, missed ticks are reported as this number


class CronError(ValueError):
    """A cron expression croniter does not accept."""


class SkipTick(Exception):
    """The tick cannot submit a job; the message is stored with the run."""


MIN_PERIOD_S = 60.0  # default floor between ticks (ATTITUDE_MIN_SCHEDULE_PERIOD_S)
_PERIOD_PROBE_TICKS = 130  # a six-field expression repeats its seconds pattern at least every minute

CRON_FIELDS = (("minute", 0, 59), ("hour", 0, 23), ("day of month", 1, 31), ("month", 1, 12),
               ("day of week", 0, 7), ("second", 0, 59))


def cron_field_problem(expr: str) -> str | None:
    """Which field of a 5- or 6-field cron expression croniter refuses, and why (e.g. "hour 25 out of range
    0-23"); None when the field count is wrong or no single field is to blame."""
    fields = expr.split()
    if len(fields) not in (5, 6):
        return None
    for i, (value, (name, low, high)) in enumerate(zip(fields, CRON_FIELDS, strict=False)):
        probe = ["*"] * len(fields)
        probe[i] = value
        if croniter.is_valid(" ".join(probe)):
            continue
        numbers = [int(n) for n in re.findall(r"\d+", value.split("/")[0])]
        outside = [n for n in numbers if not low <= n <= high]
        if outside:
            return f"{name} {outside[0]} out of range {low}-{high} (field {i + 1}, {value!r})"
        return (f"{name} field {value!r} (field {i + 1}) is not valid: numbers {low}-{high}, *, ranges a-b, "
                f"lists a,b, steps */n")
    return None


def check_cron(expr: str, min_period_s: float = MIN_PERIOD_S) -> str:
    """Normalise and validate a cron expression (UTC); raises CronError, also when two ticks come closer
    than ``min_period_s`` (a six-field ``* * * * * *`` fires every second)."""
    expr = " ".join(expr.split())
    if len(expr) > 200:
        raise CronError(f"cron expression of {len(expr)} characters; at most 200")
    if not expr or not croniter.is_valid(expr):
        problem = cron_field_problem(expr)
        if problem:
            raise CronError(f"invalid cron expression {expr!r}: {problem}")
        raise CronError(f"invalid cron expression {expr!r}: expected 5 fields (minute hour day month weekday), "
                        f"6 with seconds last, or @hourly/@daily/@weekly/@monthly/@yearly; got "
                        f"{len(expr.split())} field(s)")
    try:
        next_tick(expr, utcnow())
    except (CroniterError, ValueError, OverflowError):
        raise CronError(f"cron expression {expr!r} never fires (e.g. a day that no month has)") from None
    if len(expr.split()) == 6:  # seconds: five fields and @-names never fire more than once a minute
        it = croniter(expr, utcnow())
        ticks = [it.get_next(float) for _ in range(_PERIOD_PROBE_TICKS)]
        gap = min(b - a for a, b in zip(ticks, ticks[1:], strict=False))
        if gap < min_period_s:
            raise CronError(f"cron expression {expr!r} fires every {gap:g} s; schedules may fire at most once "
                            f"every {min_period_s:g} s (ATTITUDE_MIN_SCHEDULE_PERIOD_S)")
    return expr


def next_tick(expr: str, after: dt.datetime) -> dt.datetime:
    """The first tick strictly after ``after`` (UTC)."""
    value: dt.datetime = croniter(expr, after.astimezone(dt.UTC)).get_next(dt.datetime)
    return value.astimezone(dt.UTC)


def due_tick(expr: str, first_due: dt.datetime, now: dt.datetime) -> tuple[dt.datetime, int]:
    """The newest tick in [first_due, now] and how many earlier ones it coalesces."""
    fire, missed = first_due, 0
    while missed < MAX_COUNTED_MISSES:
        following = next_tick(expr, fire)
        if following > now:
            return fire, missed
        fire, missed = following, missed + 1
    latest: dt.datetime = croniter(expr, now + dt.timedelta(microseconds=1)).get_prev(dt.datetime)
    return latest.astimezone(dt.UTC), missed


def to_tai_ns(t: dt.datetime) -> int:
    return int(timescales.seconds_to_tai_ns(np.array([t.timestamp()]), "utc")[0])


def _extent(session: Session, spacecraft_id: int, streams: tuple[str, ...], start: int | None,
            end: int) -> dict[str, tuple[int, int]]:
    q = (select(TelemetryFile.stream, func.min(TelemetryFile.t_min_tai_ns), func.max(TelemetryFile.t_max_tai_ns))
         .where(TelemetryFile.spacecraft_id == spacecraft_id, TelemetryFile.stream.in_(streams),
                TelemetryFile.t_min_tai_ns <= end))
    if start is not None:
        q = q.where(TelemetryFile.t_max_tai_ns >= start)
    return {s: (int(a), int(b)) for s, a, b in session.execute(q.group_by(TelemetryFile.stream)).all()}


def window_for(session: Session, schedule: Schedule, fire_at: dt.datetime) -> tuple[int | None, int]:
    """The relative window of a tick as TAI ns: it ends at the fire time."""
    end = to_tai_ns(fire_at)
    if schedule.window == "since_last_success":
        last = schedstore.last_success_end_tai_ns(session, schedule.id)
        if last is not None:
            if last >= end:
                raise SkipTick("no new time since the last successful run")
            return last + 1, end
    if schedule.window_s is not None:
        return end - schedule.window_s * 1_000_000_000, end
    if schedule.window == "previous":  # default: since the previous tick
        previous: dt.datetime = croniter(schedule.cron, fire_at).get_prev(dt.datetime)
        return to_tai_ns(previous.astimezone(dt.UTC)), end
    return None, end  # since the last success, first run: everything stored up to now


def new_job(session: Session, schedule: Schedule, fire_at: dt.datetime) -> Job:
    """The job of one tick, checked like a submission through the API; SkipTick says why not."""
    jt = registry().get(schedule.job_type)
    if jt is None:
        raise SkipTick(f"job type {schedule.job_type!r} is no longer available")
    try:
        params = jt.params.model_validate(schedule.params).model_dump(mode="json")
    except ValidationError as exc:
        raise SkipTick(f"the job template's params are no longer valid for {jt.name}: {exc}") from None
    version = session.scalar(select(func.max(SpacecraftConfig.version))
                             .where(SpacecraftConfig.spacecraft_id == schedule.spacecraft_id))
    if version is None:
        raise SkipTick("the spacecraft has no configuration")
    start, end = window_for(session, schedule, fire_at)
    needed = stream_names(jt)
    if needed:
        extent = _extent(session, schedule.spacecraft_id, needed, start, end)
        missing = [s for s in jt.streams if s not in extent]
        if missing:
            raise SkipTick(f"no {', '.join(missing)} samples in the window; {jt.name} needs {', '.join(jt.streams)}")
        if jt.any_stream and not extent:
            raise SkipTick("no telemetry in the window")
        if start is None:
            start = min(a for a, _ in (extent[s] for s in (jt.streams or tuple(extent))))
    if start is None:
        start = end
    reference: dict[str, str] = {}
    for kind in jt.reference:
        wanted = schedule.reference.get(kind)
        if wanted == "none":
            continue
        if wanted is not None:
            pinned = session.get(ReferenceDataset, wanted)
            if pinned is None or not usable_by(pinned, schedule.spacecraft_id):
                raise SkipTick(f"reference.{kind}: data set {wanted!r} does not exist or is not usable by this "
                               "spacecraft")
            reference[kind] = wanted
        elif (d := latest_covering(session, kind, start, end, spacecraft_id=schedule.spacecraft_id)) is not None:
            reference[kind] = d.id
    return Job(type=jt.name, spacecraft_id=schedule.spacecraft_id, config_version=int(version), start_tai_ns=start,
               end_tai_ns=end, params=params, status="queued", progress=0.0, stage="queued",
               software_version=__version__, api_key_id=schedule.api_key_id, cancel_requested=False,
               reference=reference)


def fire_due(session: Session, schedule_id: str, now: dt.datetime, fired_by: str) -> ScheduleRun | None:
    """Fire the schedule's newest due tick in the caller's transaction (None: nothing to do).

    Raises IntegrityError when another instance fired that tick first: roll the transaction back.
    """
    schedule = session.scalar(select(Schedule).where(Schedule.id == schedule_id)
                              .with_for_update(skip_locked=True))
    if schedule is None or not schedule.enabled or schedule.next_fire_at is None or schedule.next_fire_at > now:
        return None
    fire_at, missed = due_tick(schedule.cron, schedule.next_fire_at, now)
    run = schedstore.add_run(session, schedule_id=schedule.id, fire_at=fire_at, status="submitted", missed=missed,
                             fired_by=fired_by)
    try:
        job = new_job(session, schedule, fire_at)
    except SkipTick as exc:
        run.status, run.message = "skipped", str(exc)
    else:
        session.add(job)
        session.flush()
        run.job_id = job.id
    schedstore.advance(session, schedule.id, next_tick(schedule.cron, fire_at))
    return run


class Scheduler:
    """Background thread of one service instance; ``clock`` may be replaced (tests)."""

    def __init__(self, settings: Settings, sessions: sessionmaker[Session],
                 on_submit: Callable[[], None] | None = None, poll_s: float | None = None) -> None:
        self.settings = settings
        self.sessions = sessions
        self.on_submit = on_submit or (lambda: None)
        self.poll_s = settings.scheduler_poll_s if poll_s is None else poll_s
        self.clock: Callable[[], dt.datetime] = utcnow
        self.instance = f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:6]}"
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        self._thread = threading.Thread(target=self._loop, name="scheduler", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=30)

    def _loop(self) -> None:
        while not self._stop.is_set():
            try:
                self.tick()
            except Exception:  # noqa: BLE001 - the scheduler must survive a database hiccup
                log.exception("scheduler iteration failed")
            self._stop.wait(self.poll_s)

    def tick(self, now: dt.datetime | None = None) -> list[dict[str, Any]]:
        """Fire every due schedule once; returns what this instance fired."""
        now = now or self.clock()
        with self.sessions() as session:
            due = schedstore.due_ids(session, now)
        fired: list[dict[str, Any]] = []
        for schedule_id in due:
            try:
                with self.sessions.begin() as session:
                    run = fire_due(session, schedule_id, now, self.instance)
                    info = None if run is None else {"schedule_id": schedule_id, "fire_at": run.fire_at,
                                                     "status": run.status, "job_id": run.job_id}
            except IntegrityError:  # another instance fired this tick first
                continue
            except OperationalError as exc:  # SQLite busy under a concurrent writer: next poll
                log.info("schedule %s not fired this poll: %s", schedule_id, exc)
                continue
            if info is not None:
                fired.append(info)
                log.info("schedule %s fired at %s: %s %s", schedule_id, info["fire_at"], info["status"],
                         info["job_id"] or "")
        if any(f["job_id"] for f in fired):
            self.on_submit()
        return fired
