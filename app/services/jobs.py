"""Jobs: submit (window, reference data and calibration pinned for reproducibility), read, list,
cancel; their artifacts, reports and live status."""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import BaseModel, Field, ValidationError
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.jobs.registry import JobType, registry
from app.jobs.runner import CALIBRATION_PREFIX, SCREENING_KEY, stream_names
from app.reports.inputs import retracted_by_job
from app.reports.job_report import brief, report_json
from app.reports.specs import parse as parse_specs
from app.services import figures
from app.services.access import Principal
from app.services.bounds import check_json_shape
from app.services.downloads import StoredFile
from app.services.errors import Busy, Conflict, Gone, Invalid, NotFound
from app.services.pages import Page, page_of, paginate
from app.services.spacecraft import get_spacecraft, latest_config
from app.services.suggest import did_you_mean, field_errors
from app.services.times import check_bound, iso
from app.settings import Settings
from app.version import __version__
from processing.time import timescales
from storage import calibrations
from storage import jobs as jobstore
from storage.jobs import ArtifactStore
from storage.models import Artifact, Calibration, Job, ReferenceDataset, Spacecraft, TelemetryFile
from storage.models import SpacecraftConfig as ConfigRow
from storage.parquet_store import ParquetStore
from storage.reference import latest_covering, usable_by


class JobCreate(BaseModel):
    """A job request (the body of ``POST /api/v1/jobs``, the fields of the UI's run form)."""

    type: str
    spacecraft: str
    start: str | float | None = Field(None, description="ISO 8601 or seconds since 1970 on time_scale; "
                                                        "default: the first stored sample the job needs")
    end: str | float | None = Field(None, description="inclusive; default: the last stored sample")
    time_scale: str = Field("utc", pattern="^(utc|tai|gps|tt)$")
    params: dict[str, Any] = Field(default_factory=dict)
    reference: dict[str, str] = Field(default_factory=dict, description=(
        "reference kind -> data set id, or 'none'; kinds the job uses and that are not given get the "
        "newest data set of that kind covering the window"))
    calibration: str = Field(default="latest", description=(
        "for jobs that apply a calibration (gyro data; magnetometer data for gyroless_ekf and vector_attitude): "
        "'latest' (the newest version of that kind for the spacecraft, if any), 'none' (raw data), or a "
        "calibration id"))
    screened: bool = Field(default=False, description=(
        "use only samples accepted by the newest succeeded data_screening job of the spacecraft whose "
        "window covers this job's (002)"))


@dataclass(frozen=True)
class JobReport:
    """A job, its spacecraft and type, and the report document (app/reports/job_report.py)."""

    job: Job
    spacecraft: Spacecraft
    job_type: JobType | None
    data: dict[str, Any]


@dataclass(frozen=True)
class JobProgress:
    status: str
    progress: float
    stage: str
    error: str | None
    final: bool


def job_types() -> list[JobType]:
    return list(registry().values())


def get_job_type(name: str) -> JobType:
    jobs = registry()
    jt = jobs.get(name)
    if jt is None:
        raise Invalid(f"unknown job type {name!r}{did_you_mean(name, jobs)}; types: {', '.join(sorted(jobs))}")
    return jt


def validated_params(jt: JobType, params: dict[str, Any]) -> BaseModel:
    """The job type's parameter model; Invalid with one error per bad field, or when the value's shape
    exceeds :data:`app.services.bounds.PARAM_BOUNDS` (depth, items per list, string length)."""
    check_json_shape(params, "params")
    try:
        return jt.params.model_validate(params)
    except ValidationError as exc:
        errors = field_errors(exc, jt.params, prefix="params.")
        raise Invalid({"message": f"invalid params for {jt.name}", "errors": errors}) from None


def _time(value: str | float | None, scale: str, field: str) -> int | None:
    if value is None:
        return None
    try:
        if isinstance(value, (int, float)):
            return check_bound(int(timescales.seconds_to_tai_ns(np.array([float(value)]), scale)[0]), field)
        return check_bound(int(timescales.iso_to_tai_ns(np.array([value], dtype=object), scale)[0]), field)
    except (timescales.TimeValueError, OverflowError) as exc:
        raise Invalid(f"{field}: {exc}") from None


def _data_extent(session: Session, sc: Spacecraft, streams: tuple[str, ...],
                 start: int | None, end: int | None) -> dict[str, tuple[int, int]]:
    """Per stream, the stored time extent intersecting [start, end] (from the catalog)."""
    q = (select(TelemetryFile.stream, func.min(TelemetryFile.t_min_tai_ns), func.max(TelemetryFile.t_max_tai_ns))
         .where(TelemetryFile.spacecraft_id == sc.id, TelemetryFile.stream.in_(streams)))
    if start is not None:
        q = q.where(TelemetryFile.t_max_tai_ns >= start)
    if end is not None:
        q = q.where(TelemetryFile.t_min_tai_ns <= end)
    return {s: (int(a), int(b)) for s, a, b in session.execute(q.group_by(TelemetryFile.stream)).all()}


def _window(session: Session, sc: Spacecraft, jt: JobType, body: JobCreate) -> tuple[int, int]:
    start = _time(body.start, body.time_scale, "start")
    end = _time(body.end, body.time_scale, "end")
    if start is not None and end is not None and end <= start:
        raise Invalid("end must be after start")
    needed = stream_names(jt)
    if not needed:  # jobs without telemetry (diagnostics)
        now = int(timescales.seconds_to_tai_ns(np.array([dt.datetime.now(dt.UTC).timestamp()]), "utc")[0])
        return (start if start is not None else now), (end if end is not None else now)
    extent = _data_extent(session, sc, needed, start, end)
    where = f"between {iso(start) if start else 'the beginning'} and {iso(end) if end else 'the end'}"
    missing = [s for s in jt.streams if s not in extent]
    if missing:
        raise Invalid(f"no {', '.join(missing)} samples for {sc.name} {where}; "
                      f"job {jt.name} needs {', '.join(jt.streams)}")
    if jt.any_stream and not extent:
        raise Invalid(f"no telemetry for {sc.name} {where}")
    used = [extent[s] for s in (jt.streams or tuple(extent))]
    if not used:  # only optional streams, none of them present
        raise Invalid(f"no {' or '.join(needed)} samples for {sc.name} {where}; job {jt.name} needs one of them")
    lo = start if start is not None else min(a for a, _ in used)
    hi = end if end is not None else max(b for _, b in used)
    return lo, hi


def _pick_reference(session: Session, jt: JobType, sc: Spacecraft, given: dict[str, str], start: int,
                    end: int) -> dict[str, str]:
    """Pin the reference data sets a job will use, so that reruns and reports are reproducible: shared
    ones or the spacecraft's own, never another spacecraft's."""
    unknown = sorted(set(given) - set(jt.reference))
    if unknown:
        raise Invalid(f"job {jt.name} uses no reference data of kind {', '.join(unknown)}"
                      + (f"; it uses {', '.join(jt.reference)}" if jt.reference else ""))
    chosen: dict[str, str] = {}
    for kind in jt.reference:
        wanted = given.get(kind)
        if wanted == "none":
            continue
        if wanted is not None:
            d = session.get(ReferenceDataset, wanted)
            if d is None or d.kind != kind or not usable_by(d, sc.id):
                raise Invalid(f"reference.{kind}: no {kind} data set with id {wanted!r} for {sc.name}")
            chosen[kind] = d.id
        elif (d := latest_covering(session, kind, start, end, spacecraft_id=sc.id)) is not None:
            chosen[kind] = d.id
    return chosen


def _pick_screening(session: Session, sc: Spacecraft, start: int, end: int) -> str:
    job_id = session.scalar(select(Job.id).where(
        Job.spacecraft_id == sc.id, Job.type == "data_screening", Job.status == "succeeded",
        Job.start_tai_ns <= start, Job.end_tai_ns >= end).order_by(Job.finished_at.desc()).limit(1))
    if job_id is None:
        raise Invalid(f"screened: no succeeded data_screening job of {sc.name} covers this window; run one first")
    return str(job_id)


def _pick_calibration(session: Session, jt: JobType, sc: Spacecraft, wanted: str) -> dict[str, str]:
    """Pin the calibration version a job will apply (recorded with the job and in its report)."""
    kind = jt.applies_calibration
    if kind is None or wanted == "none":
        return {}
    if wanted == "latest":
        cal = calibrations.latest(session, sc.id, kind)
    else:
        cal = session.get(Calibration, wanted)
        if cal is None or cal.spacecraft_id != sc.id or cal.kind != kind:
            raise Invalid(f"calibration: no {kind} calibration {wanted!r} of {sc.name}")
    return {} if cal is None else {CALIBRATION_PREFIX + kind: cal.id}


def submit(session: Session, body: JobCreate, who: Principal, on_submit: Callable[[], None],
           max_queued: int | None = None) -> Job:
    """Queue a job (``on_submit`` wakes the executor); its window, reference data and calibration are
    fixed now. Busy when the caller's key already has ``max_queued`` jobs waiting."""
    if max_queued is not None:
        waiting = session.scalar(select(func.count()).select_from(Job).where(
            Job.api_key_id == who.key_id, Job.status == "queued")) or 0
        if waiting >= max_queued:
            raise Busy(f"this key has {waiting} queued jobs, the most it may have waiting "
                       "(ATTITUDE_MAX_QUEUED_JOBS_PER_KEY); submit more when some have started")
    jt = get_job_type(body.type)
    params = validated_params(jt, body.params)
    sc = get_spacecraft(session, body.spacecraft, who)
    start, end = _window(session, sc, jt, body)
    reference = _pick_reference(session, jt, sc, body.reference, start, end)
    reference.update(_pick_calibration(session, jt, sc, body.calibration))
    if body.screened:
        reference[SCREENING_KEY] = _pick_screening(session, sc, start, end)
    job = Job(type=jt.name, spacecraft_id=sc.id, config_version=latest_config(session, sc).version,
              start_tai_ns=start, end_tai_ns=end, params=params.model_dump(mode="json"), status="queued",
              progress=0.0, stage="queued", software_version=__version__, api_key_id=who.key_id,
              cancel_requested=False, reference=reference)
    session.add(job)
    session.commit()
    on_submit()
    return job


def get_job(session: Session, job_id: str, who: Principal) -> tuple[Job, Spacecraft]:
    """The job if the caller may use its spacecraft; NotFound otherwise."""
    row = session.execute(select(Job, Spacecraft).join(Spacecraft, Spacecraft.id == Job.spacecraft_id)
                          .where(Job.id == job_id)).first()
    if row is None or not who.may_use(row[1].id):
        raise NotFound(f"job {job_id!r} not found")
    return row[0], row[1]


def list_jobs(session: Session, who: Principal, spacecraft: str | None, job_type: str | None, status: str | None,
              cursor: str | None, limit: int) -> Page[tuple[Job, Spacecraft]]:
    """Jobs of the caller's spacecraft, newest first, optionally of one spacecraft, type or status."""
    q = select(Job, Spacecraft).join(Spacecraft, Spacecraft.id == Job.spacecraft_id)
    if spacecraft is not None:
        q = q.where(Spacecraft.id == get_spacecraft(session, spacecraft, who).id)
    if who.spacecraft_ids is not None:
        q = q.where(Spacecraft.id.in_(who.spacecraft_ids))
    if job_type is not None:
        q = q.where(Job.type == job_type)
    if status is not None:
        q = q.where(Job.status == status)
    rows: list[Any] = [tuple(r) for r in session.execute(paginate(q, Job.created_at, Job.id, cursor, limit)).all()]
    return page_of(rows, limit, lambda r: (r[0].created_at, r[0].id))


def recent_jobs(session: Session, sc: Spacecraft, limit: int) -> list[Job]:
    """The newest ``limit`` jobs of a spacecraft."""
    return list(session.scalars(select(Job).where(Job.spacecraft_id == sc.id)
                                .order_by(Job.created_at.desc()).limit(limit)))


def cancel(session: Session, job_id: str, who: Principal) -> tuple[Job, Spacecraft]:
    """Queued jobs are cancelled at once; running ones stop at their next progress report or are
    stopped by the executor after a short grace period. Conflict for finished jobs."""
    job, sc = get_job(session, job_id, who)
    if job.status in jobstore.FINAL:
        raise Conflict(f"job {job_id} already {job.status}")
    jobstore.set_status(session, job_id, "cancelled", allowed_from=("queued",), stage="cancelled")
    job.cancel_requested = True
    session.commit()
    session.refresh(job)
    return job, sc


def progress(session: Session, who: Principal, ids: list[str]) -> dict[str, JobProgress]:
    """Status, progress and stage of the listed jobs the caller may see (unknown ids are left out)."""
    rows = session.execute(select(Job.id, Job.status, Job.progress, Job.stage, Job.error, Job.spacecraft_id)
                           .where(Job.id.in_(ids))).all() if ids else []
    return {r.id: JobProgress(r.status, r.progress, r.stage, r.error, r.status in jobstore.FINAL)
            for r in rows if who.may_use(r.spacecraft_id)}


def artifact_store(settings: Settings) -> ArtifactStore:
    return ArtifactStore(settings.artifacts_url)


def artifacts(session: Session, job_id: str, who: Principal) -> list[Artifact]:
    job, _sc = get_job(session, job_id, who)
    return list(job.artifacts)


def artifact_file(session: Session, settings: Settings, job_id: str, name: str, who: Principal) -> StoredFile:
    """The stored file of artifact ``name`` of the job; NotFound, or Gone when it is missing from the store.
    ``<table>.csv`` of a table stored as Parquet only (app.jobs.outputs) gives that Parquet file with
    ``csv_from_parquet`` set: the caller converts it (app.jobs.outputs.csv_chunks). ``<figure>.png`` of a figure
    made on request is drawn and stored first (app.services.figures.figure_artifact)."""
    job, _sc = get_job(session, job_id, who)
    art = session.scalar(select(Artifact).where(Artifact.job_id == job_id, Artifact.name == name))
    if art is None and name.endswith(".png"):  # a figure made on request (app.services.figures)
        art = figures.figure_artifact(session, artifact_store(settings), job, name[: -len(".png")])
    on_request = False
    if art is None and name.endswith(".csv"):  # a long table is stored as Parquet only: its CSV on request
        art = session.scalar(select(Artifact).where(Artifact.job_id == job_id, Artifact.kind == "table",
                                                    Artifact.name == name[: -len(".csv")] + ".parquet"))
        on_request = art is not None
    if art is None:
        raise NotFound(f"job {job_id} has no artifact {name!r}")
    path = artifact_store(settings).path(art)
    if not path.is_file():
        raise Gone(f"artifact {art.name!r} of job {job_id} is missing on disk")
    if on_request:
        return StoredFile(path, "text/csv", name, csv_from_parquet=True)
    return StoredFile(path, art.media_type, art.name)


@dataclass(frozen=True)
class Brief:
    """A job in a list: its headline in one line, the verdict, how long it ran, retracted inputs."""

    text: str
    verdict: str
    duration: str
    retracted: bool


def _duration(job: Job) -> str:
    if job.started_at is None:
        return ""
    end = job.finished_at or dt.datetime.now(dt.UTC)
    s = max(0.0, (end - job.started_at).total_seconds())
    if s < 60:
        return f"{s:.1f} s"
    if s < 3600:
        return f"{int(s // 60)} min {int(s % 60)} s"
    return f"{int(s // 3600)} h {int(s % 3600 // 60)} min"


def briefs(session: Session, listed: list[tuple[Job, str]]) -> dict[str, Brief]:
    """job id -> Brief for jobs listed with their spacecraft names (specifications read once per spacecraft)."""
    types = registry()
    specs: dict[int, Any] = {}
    retracted = retracted_by_job(session, [j.id for j, _ in listed])
    out = {}
    for job, _name in listed:
        if job.spacecraft_id not in specs:
            row = session.scalar(select(ConfigRow.config).where(ConfigRow.spacecraft_id == job.spacecraft_id)
                                 .order_by(ConfigRow.version.desc()).limit(1))
            specs[job.spacecraft_id] = parse_specs(row)
        b = brief(job, types.get(job.type), specs[job.spacecraft_id])
        out[job.id] = Brief(b["text"], b["verdict"], _duration(job), job.id in retracted)
    return out


def report(session: Session, job_id: str, who: Principal, telemetry: ParquetStore | None = None) -> JobReport:
    """The job's report document; ``telemetry`` describes the input window of jobs that did not record it."""
    job, sc = get_job(session, job_id, who)
    jt = registry().get(job.type)
    return JobReport(job, sc, jt, report_json(job, sc, jt, telemetry=telemetry))
