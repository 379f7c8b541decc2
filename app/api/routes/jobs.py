"""Jobs: submit, poll, list, cancel; their artifacts and reports (app/services/jobs.py)."""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any, Literal, cast

from fastapi import APIRouter, Query, Request, Response, status
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, StreamingResponse
from pydantic import BaseModel, Field

from app.api.deps import Operator, SessionDep, SettingsDep, StoreDep, Viewer
from app.api.pagination import MAX_LIMIT, announce_next
from app.jobs.outputs import csv_chunks
from app.reports.job_report import render_html, render_pdf
from app.services import figures
from app.services import jobs as service
from app.services.downloads import StoredFile
from app.services.jobs import JobCreate
from app.services.times import iso
from storage.models import Job

router = APIRouter(prefix="/api/v1/jobs", tags=["jobs"])

JobStatus = Literal["queued", "running", "succeeded", "failed", "cancelled"]
ArtifactKind = Literal["summary", "table", "figure", "file"]


class JobAccepted(BaseModel):
    id: str
    status: JobStatus
    status_url: str


class JobOut(BaseModel):
    id: str
    type: str
    spacecraft: str
    status: JobStatus
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


def job_out(job: Job, spacecraft_name: str) -> JobOut:
    stored = job.result or {}
    return JobOut(
        id=job.id, type=job.type, spacecraft=spacecraft_name, status=cast(JobStatus, job.status),
        progress=job.progress,
        stage=job.stage, start=iso(job.start_tai_ns), end=iso(job.end_tai_ns), params=job.params,
        reference=job.reference or {},
        config_version=job.config_version, software_version=job.software_version,
        result=stored.get("summary"), inputs=stored.get("inputs"), notes=stored.get("notes", []),
        error=job.error, cancel_requested=job.cancel_requested, created_at=job.created_at,
        started_at=job.started_at, finished_at=job.finished_at, report_url=f"/api/v1/jobs/{job.id}/report",
        artifacts_url=f"/api/v1/jobs/{job.id}/artifacts",
    )


@router.post("", status_code=status.HTTP_202_ACCEPTED, response_model=JobAccepted)
def submit(body: JobCreate, request: Request, session: SessionDep, who: Operator) -> JobAccepted:
    job = service.submit(session, body, who, on_submit=request.app.state.executor.wake,
                         max_queued=request.app.state.settings.max_queued_jobs_per_key)
    return JobAccepted(id=job.id, status=cast(JobStatus, job.status), status_url=f"/api/v1/jobs/{job.id}")


@router.get("/types")
def job_types(_: Viewer) -> list[dict[str, Any]]:
    return [{"type": j.name, "title": j.title, "paper": j.paper, "streams": list(j.streams),
             "optional_streams": list(j.optional_streams), "description": j.description,
             "params_schema": j.params.model_json_schema()} for j in service.job_types()]


@router.get("/{job_id}", response_model=JobOut)
def read_job(job_id: str, session: SessionDep, who: Viewer) -> JobOut:
    job, sc = service.get_job(session, job_id, who)
    return job_out(job, sc.name)


@router.get("", response_model=list[JobOut])
def list_jobs(request: Request, response: Response, session: SessionDep, who: Viewer,
              spacecraft: str | None = None, type: str | None = None,
              status_: Annotated[str | None, Query(alias="status",
                                                   pattern="^(queued|running|succeeded|failed|cancelled)$")] = None,
              limit: Annotated[int, Query(ge=1, le=MAX_LIMIT)] = 100, cursor: str | None = None) -> list[JobOut]:
    """Jobs, newest first; more pages are announced in ``X-Next-Cursor``/``Link``."""
    page = service.list_jobs(session, who, spacecraft, type, status_, cursor, limit)
    return [job_out(j, s.name) for j, s in announce_next(request, response, page, limit)]


@router.post("/{job_id}/cancel", response_model=JobOut)
def cancel(job_id: str, session: SessionDep, who: Operator) -> JobOut:
    """Queued jobs are cancelled at once; running ones stop at their next progress report or are
    stopped by the executor after a short grace period."""
    job, sc = service.cancel(session, job_id, who)
    return job_out(job, sc.name)


class ArtifactOut(BaseModel):
    name: str
    kind: ArtifactKind
    media_type: str
    size_bytes: int | None = Field(description="null for a figure made on request that is not drawn yet")
    checksum_sha256: str | None = Field(description="null for a figure made on request that is not drawn yet")
    description: str
    url: str
    on_request: bool = Field(False, description=(
        "a figure the job did not draw (ATTITUDE_FIGURES=lazy): GET its url draws it from the stored results, "
        "stores it and serves it; later requests serve the stored PNG"))


@router.get("/{job_id}/artifacts", response_model=list[ArtifactOut])
def list_artifacts(job_id: str, session: SessionDep, who: Viewer) -> list[ArtifactOut]:
    """The job's stored artifacts, then the figures it makes on request (``on_request``)."""
    job, _sc = service.get_job(session, job_id, who)
    return [ArtifactOut(**{**a, "kind": cast(ArtifactKind, a["kind"])},
                        url=f"/api/v1/jobs/{job_id}/artifacts/{a['name']}") for a in figures.listing(job)]


def artifact_response(f: StoredFile, headers: dict[str, str] | None = None) -> Response:
    """A stored artifact as a download: the file as it is (images inline), or the CSV of a table stored as
    Parquet only, converted and streamed in row batches (app.jobs.outputs.csv_chunks)."""
    if f.csv_from_parquet:
        disposition = {"Content-Disposition": f'attachment; filename="{f.filename}"'}
        return StreamingResponse(csv_chunks(f.path), media_type="text/csv; charset=utf-8",
                                 headers={**(headers or {}), **disposition})
    inline = f.media_type.startswith("image/")
    return FileResponse(f.path, media_type=f.media_type, filename=f.filename, headers=headers,
                        content_disposition_type="inline" if inline else "attachment")


@router.get("/{job_id}/artifacts/{name}", response_class=Response)
def download_artifact(job_id: str, name: str, session: SessionDep, settings: SettingsDep, who: Viewer) -> Response:
    return artifact_response(service.artifact_file(session, settings, job_id, name, who))


@router.get("/{job_id}/report", responses={200: {"content": {"text/html": {}, "application/json": {},
                                                             "application/pdf": {}}}})
def report(job_id: str, session: SessionDep, store: StoreDep, settings: SettingsDep, who: Viewer,
           format: Annotated[str, Query(pattern="^(html|json|pdf)$")] = "html") -> Response:
    r = service.report(session, job_id, who, telemetry=store)
    job, data, artifacts = r.job, r.data, service.artifact_store(settings)
    if format == "pdf":
        return Response(render_pdf(data, job, artifacts), media_type="application/pdf",
                        headers={"Content-Disposition": f'attachment; filename="{job.type}_{job.id}.pdf"'})
    if format == "json":
        return JSONResponse(data, headers={"Content-Disposition": f'inline; filename="{job.type}_{job.id}.json"'})
    html = render_html(data, job, artifacts)
    return HTMLResponse(html, headers={"Content-Disposition": f'inline; filename="{job.type}_{job.id}.html"'})
