"""Jobs: submit, poll, list, cancel; their artifacts and reports."""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, HTTPException, Query, Request, Response, status
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse
from pydantic import BaseModel, Field, ValidationError
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.api.deps import Operator, Principal, SessionDep, Viewer
from app.api.pagination import MAX_LIMIT, announce_next, paginate
from app.api.routes.spacecraft import get_spacecraft, latest_config
from app.jobs.registry import JobType, registry
from app.jobs.runner import CALIBRATION_PREFIX, SCREENING_KEY, stream_names
from app.reports.job_report import render_html, render_pdf, report_json
from app.version import __version__
from processing.time import timescales
from storage import calibrations
from storage import jobs as jobstore
from storage.jobs import ArtifactStore
from storage.models import Artifact, Calibration, Job, ReferenceDataset, Spacecraft, TelemetryFile
from storage.reference import latest_covering

router = APIRouter(prefix="/api/v1/jobs", tags=["jobs"])


class JobCreate(BaseModel):
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
        "for jobs that use gyro data: 'latest' (the newest gyro calibration version of the spacecraft, "
        "if any), 'none' (raw data), or a calibration id"))
    screened: bool = Field(default=False, description=(
        "use only samples accepted by the newest succeeded data_screening job of the spacecraft whose "
        "window covers this job's (002)"))


class JobAccepted(BaseModel):
    id: str
    status: str
    status_url: str


class JobOut(BaseModel):
    id: str
    type: str
    spacecraft: str
    status: str
    progress: float
    stage: str
    start: str
    end: str
    params: dict[str, Any]
    reference: dict[str, Any]
    config_version: int
    software_version: str
    result: dict[str, Any] | None
    inputs: dict[str, Any] | None
    notes: list[str]
    error: str | None
    cancel_requested: bool
    created_at: dt.datetime
    started_at: dt.datetime | None
    finished_at: dt.datetime | None
    report_url: str
    artifacts_url: str


def iso(tai_ns: int) -> str:
    return str(timescales.tai_ns_to_iso(np.array([tai_ns], dtype=np.int64))[0])


def job_out(job: Job, spacecraft_name: str) -> JobOut:
    stored = job.result or {}
    return JobOut(
        id=job.id, type=job.type, spacecraft=spacecraft_name, status=job.status, progress=job.progress,
        stage=job.stage, start=iso(job.start_tai_ns), end=iso(job.end_tai_ns), params=job.params,
        reference=job.reference or {},
        config_version=job.config_version, software_version=job.software_version,
        result=stored.get("summary"), inputs=stored.get("inputs"), notes=stored.get("notes", []),
        error=job.error, cancel_requested=job.cancel_requested, created_at=job.created_at,
        started_at=job.started_at, finished_at=job.finished_at, report_url=f"/api/v1/jobs/{job.id}/report",
        artifacts_url=f"/api/v1/jobs/{job.id}/artifacts",
    )


def _time(value: str | float | None, scale: str, field: str) -> int | None:
    if value is None:
        return None
    try:
        if isinstance(value, (int, float)):
            return int(timescales.seconds_to_tai_ns(np.array([float(value)]), scale)[0])
        return int(timescales.iso_to_tai_ns(np.array([value], dtype=object), scale)[0])
    except timescales.TimeValueError as exc:
        raise HTTPException(422, f"{field}: {exc}") from None


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
        raise HTTPException(422, "end must be after start")
    needed = stream_names(jt)
    if not needed:  # jobs without telemetry (diagnostics)
        now = int(timescales.seconds_to_tai_ns(np.array([dt.datetime.now(dt.UTC).timestamp()]), "utc")[0])
        return (start if start is not None else now), (end if end is not None else now)
    extent = _data_extent(session, sc, needed, start, end)
    where = f"between {iso(start) if start else 'the beginning'} and {iso(end) if end else 'the end'}"
    missing = [s for s in jt.streams if s not in extent]
    if missing:
        raise HTTPException(422, f"no {', '.join(missing)} samples for {sc.name} {where}; "
                                 f"job {jt.name} needs {', '.join(jt.streams)}")
    if jt.any_stream and not extent:
        raise HTTPException(422, f"no telemetry for {sc.name} {where}")
    used = [extent[s] for s in (jt.streams or tuple(extent))]
    lo = start if start is not None else min(a for a, _ in used)
    hi = end if end is not None else max(b for _, b in used)
    return lo, hi


def _pick_reference(session: Session, jt: JobType, given: dict[str, str], start: int,
                    end: int) -> dict[str, str]:
    """Pin the reference data sets a job will use, so that reruns and reports are reproducible."""
    unknown = sorted(set(given) - set(jt.reference))
    if unknown:
        raise HTTPException(422, f"job {jt.name} uses no reference data of kind {', '.join(unknown)}"
                                 + (f"; it uses {', '.join(jt.reference)}" if jt.reference else ""))
    chosen: dict[str, str] = {}
    for kind in jt.reference:
        wanted = given.get(kind)
        if wanted == "none":
            continue
        if wanted is not None:
            d = session.get(ReferenceDataset, wanted)
            if d is None or d.kind != kind:
                raise HTTPException(422, f"reference.{kind}: no {kind} data set with id {wanted!r}")
            chosen[kind] = d.id
        elif (d := latest_covering(session, kind, start, end)) is not None:
            chosen[kind] = d.id
    return chosen


def _pick_screening(session: Session, sc: Spacecraft, start: int, end: int) -> str:
    job_id = session.scalar(select(Job.id).where(
        Job.spacecraft_id == sc.id, Job.type == "data_screening", Job.status == "succeeded",
        Job.start_tai_ns <= start, Job.end_tai_ns >= end).order_by(Job.finished_at.desc()).limit(1))
    if job_id is None:
        raise HTTPException(422, f"screened: no succeeded data_screening job of {sc.name} covers this window; "
                                 "run one first")
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
            raise HTTPException(422, f"calibration: no {kind} calibration {wanted!r} of {sc.name}")
    return {} if cal is None else {CALIBRATION_PREFIX + kind: cal.id}


@router.post("", status_code=status.HTTP_202_ACCEPTED, response_model=JobAccepted)
def submit(body: JobCreate, request: Request, session: SessionDep, who: Operator) -> JobAccepted:
    jobs = registry()
    jt = jobs.get(body.type)
    if jt is None:
        raise HTTPException(422, f"unknown job type {body.type!r}; types: {', '.join(sorted(jobs))}")
    try:
        params = jt.params.model_validate(body.params)
    except ValidationError as exc:
        errors = [{"row": None, "column": "params." + ".".join(str(p) for p in e["loc"]), "message": e["msg"]}
                  for e in exc.errors()]
        raise HTTPException(422, {"message": f"invalid params for {jt.name}", "errors": errors}) from None
    sc = get_spacecraft(session, body.spacecraft, who)
    start, end = _window(session, sc, jt, body)
    reference = _pick_reference(session, jt, body.reference, start, end)
    reference.update(_pick_calibration(session, jt, sc, body.calibration))
    if body.screened:
        reference[SCREENING_KEY] = _pick_screening(session, sc, start, end)
    job = Job(type=jt.name, spacecraft_id=sc.id, config_version=latest_config(session, sc).version,
              start_tai_ns=start, end_tai_ns=end, params=params.model_dump(mode="json"), status="queued",
              progress=0.0, stage="queued", software_version=__version__, api_key_id=who.key_id,
              cancel_requested=False, reference=reference)
    session.add(job)
    session.commit()
    request.app.state.executor.wake()
    return JobAccepted(id=job.id, status=job.status, status_url=f"/api/v1/jobs/{job.id}")


def get_job(session: Session, job_id: str, who: Principal) -> tuple[Job, Spacecraft]:
    """The job if the caller may use its spacecraft; 404 otherwise."""
    row = session.execute(select(Job, Spacecraft).join(Spacecraft, Spacecraft.id == Job.spacecraft_id)
                          .where(Job.id == job_id)).first()
    if row is None or not who.may_use(row[1].id):
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"job {job_id!r} not found")
    return row[0], row[1]


@router.get("/types")
def job_types(_: Viewer) -> list[dict[str, Any]]:
    return [{"type": j.name, "title": j.title, "paper": j.paper, "streams": list(j.streams),
             "optional_streams": list(j.optional_streams), "description": j.description,
             "params_schema": j.params.model_json_schema()} for j in registry().values()]


@router.get("/{job_id}", response_model=JobOut)
def read_job(job_id: str, session: SessionDep, who: Viewer) -> JobOut:
    job, sc = get_job(session, job_id, who)
    return job_out(job, sc.name)


@router.get("", response_model=list[JobOut])
def list_jobs(request: Request, response: Response, session: SessionDep, who: Viewer,
              spacecraft: str | None = None, type: str | None = None,
              status_: Annotated[str | None, Query(alias="status",
                                                   pattern="^(queued|running|succeeded|failed|cancelled)$")] = None,
              limit: Annotated[int, Query(ge=1, le=MAX_LIMIT)] = 100, cursor: str | None = None) -> list[JobOut]:
    """Jobs, newest first; more pages are announced in ``X-Next-Cursor``/``Link``."""
    q = select(Job, Spacecraft).join(Spacecraft, Spacecraft.id == Job.spacecraft_id)
    if spacecraft is not None:
        q = q.where(Spacecraft.id == get_spacecraft(session, spacecraft, who).id)
    if who.spacecraft_ids is not None:
        q = q.where(Spacecraft.id.in_(who.spacecraft_ids))
    if type is not None:
        q = q.where(Job.type == type)
    if status_ is not None:
        q = q.where(Job.status == status_)
    rows: list[Any] = list(session.execute(paginate(q, Job.created_at, Job.id, cursor, limit)).all())
    rows = announce_next(request, response, rows, limit, lambda r: (r[0].created_at, r[0].id))
    return [job_out(j, s.name) for j, s in rows]


@router.post("/{job_id}/cancel", response_model=JobOut)
def cancel(job_id: str, session: SessionDep, who: Operator) -> JobOut:
    """Queued jobs are cancelled at once; running ones stop at their next progress report or are
    stopped by the executor after a short grace period."""
    job, sc = get_job(session, job_id, who)
    if job.status in jobstore.FINAL:
        raise HTTPException(status.HTTP_409_CONFLICT, f"job {job_id} already {job.status}")
    jobstore.set_status(session, job_id, "cancelled", allowed_from=("queued",), stage="cancelled")
    job.cancel_requested = True
    session.commit()
    session.refresh(job)
    return job_out(job, sc.name)


class ArtifactOut(BaseModel):
    name: str
    kind: str
    media_type: str
    size_bytes: int
    checksum_sha256: str
    description: str
    url: str


@router.get("/{job_id}/artifacts", response_model=list[ArtifactOut])
def list_artifacts(job_id: str, session: SessionDep, who: Viewer) -> list[ArtifactOut]:
    job, _sc = get_job(session, job_id, who)
    return [ArtifactOut(name=a.name, kind=a.kind, media_type=a.media_type, size_bytes=a.size_bytes,
                        checksum_sha256=a.checksum_sha256, description=a.description,
                        url=f"/api/v1/jobs/{job_id}/artifacts/{a.name}") for a in job.artifacts]


@router.get("/{job_id}/artifacts/{name}")
def download_artifact(job_id: str, name: str, request: Request, session: SessionDep, who: Viewer) -> FileResponse:
    get_job(session, job_id, who)
    art = session.scalar(select(Artifact).where(Artifact.job_id == job_id, Artifact.name == name))
    if art is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"job {job_id} has no artifact {name!r}")
    store = ArtifactStore(request.app.state.settings.artifacts_url)
    path = store.path(art)
    if not path.is_file():
        raise HTTPException(status.HTTP_410_GONE, f"artifact {name!r} of job {job_id} is missing on disk")
    inline = art.media_type.startswith("image/")
    return FileResponse(path, media_type=art.media_type, filename=art.name,
                        content_disposition_type="inline" if inline else "attachment")


@router.get("/{job_id}/report", responses={200: {"content": {"text/html": {}, "application/json": {},
                                                             "application/pdf": {}}}})
def report(job_id: str, request: Request, session: SessionDep, who: Viewer,
           format: Annotated[str, Query(pattern="^(html|json|pdf)$")] = "html") -> Response:
    job, sc = get_job(session, job_id, who)
    jt = registry().get(job.type)
    store = ArtifactStore(request.app.state.settings.artifacts_url)
    data = report_json(job, sc, jt, telemetry=request.app.state.store)
    if format == "pdf":
        return Response(render_pdf(data, job, store), media_type="application/pdf",
                        headers={"Content-Disposition": f'attachment; filename="{job.type}_{job.id}.pdf"'})
    if format == "json":
        return JSONResponse(data, headers={"Content-Disposition": f'inline; filename="{job.type}_{job.id}.json"'})
    html = render_html(data, job, store)
    return HTMLResponse(html, headers={"Content-Disposition": f'inline; filename="{job.type}_{job.id}.html"'})
