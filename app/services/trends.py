"""Trends of one spacecraft's calibration and accuracy results across its succeeded jobs (app/reports/trends.py)."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import select
from sqlalchemy.orm import Session

from app.reports import specs as speclib
from app.reports import trends as trendlib
from app.services.access import Principal
from app.services.spacecraft import get_spacecraft, latest_config
from app.services.times import parse_bound
from storage.models import Job, Spacecraft


@dataclass(frozen=True)
class TrendSelection:
    """The trends asked for, and the job types with succeeded jobs that could be trended."""

    spacecraft: Spacecraft
    trends: list[trendlib.Trend]
    available: list[str]


def select_trends(session: Session, name: str, who: Principal, job_type: str | None, start: str | None,
                  end: str | None) -> TrendSelection:
    """Key metrics (no ``job_type``) or every metric of ``job_type``, of jobs whose windows lie in
    [start, end] (ISO 8601 UTC or seconds since 1970 UTC), with the specification limits."""
    sc = get_spacecraft(session, name, who)
    t0, t1 = parse_bound(start, "utc", "start"), parse_bound(end, "utc", "end")
    available = sorted(session.scalars(select(Job.type).where(Job.spacecraft_id == sc.id,
                                                              Job.status == "succeeded").distinct()))
    if job_type:
        jobs = trendlib.succeeded_jobs(session, sc.id, [job_type], start_tai_ns=t0, end_tai_ns=t1)
        metrics = trendlib.generic_metrics(job_type, jobs)
    else:
        metrics = list(trendlib.KEY_METRICS)
        jobs = trendlib.succeeded_jobs(session, sc.id, {m.job_type for m in metrics}, start_tai_ns=t0, end_tai_ns=t1)
    specs = speclib.parse(latest_config(session, sc).config)
    return TrendSelection(sc, trendlib.trends(jobs, metrics, specs), available)
