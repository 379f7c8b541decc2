"""Web UI pages of jobs: list with live status, run form, job page, reports (HTML, PDF, JSON), artifacts.

Submitting and cancelling go through the API's own route functions, so the UI applies exactly the
API's checks (parameters, window, reference data, roles, spacecraft grants).
"""

from __future__ import annotations

import json
import urllib.parse
from typing import Annotated, Any

from fastapi import APIRouter, Form, HTTPException, Query, Request, status
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, RedirectResponse, Response
from pydantic import ValidationError
from sqlalchemy import select

from app.api.deps import SessionDep
from app.api.routes import jobs as jobs_api
from app.api.routes.spacecraft import get_spacecraft
from app.jobs.registry import registry
from app.reports.job_report import render_html, render_pdf, report_json
from app.reports.summary import layout
from app.web.auth import WebOperator, WebViewer, check_form, current_principal
from app.web.render import NO_STORE, HtmlRoute, page
from app.web.routes import TIME_SCALES, visible_spacecraft
from storage.jobs import FINAL, ArtifactStore
from storage.models import Artifact, Job, Spacecraft

router = APIRouter(prefix="/ui/jobs", route_class=HtmlRoute, include_in_schema=False)

STATUSES = ("queued", "running", "succeeded", "failed", "cancelled")
MAX_LISTED = 100


def artifact_store(request: Request) -> ArtifactStore:
    settings = request.app.state.settings
    return ArtifactStore(getattr(settings, "artifacts_url", None) or settings.artifacts_dir)


@router.get("")
def job_list(request: Request, session: SessionDep, who: WebViewer, spacecraft: str | None = None,
             type: str | None = None, status_: Annotated[str | None, Query(alias="status")] = None) -> HTMLResponse:
    wanted_status = status_ or None
    if wanted_status is not None and wanted_status not in STATUSES:
        raise HTTPException(422, f"status must be one of {', '.join(STATUSES)}")
    q = select(Job, Spacecraft).join(Spacecraft, Spacecraft.id == Job.spacecraft_id)
    if spacecraft:
        q = q.where(Spacecraft.id == get_spacecraft(session, spacecraft, who).id)
    if who.spacecraft_ids is not None:
        q = q.where(Spacecraft.id.in_(who.spacecraft_ids))
    if type:
        q = q.where(Job.type == type)
    if wanted_status:
        q = q.where(Job.status == wanted_status)
    rows = session.execute(q.order_by(Job.created_at.desc()).limit(MAX_LISTED + 1)).all()
    return page(request, "jobs.html", jobs=[(j, s.name) for j, s in rows[:MAX_LISTED]], more=len(rows) > MAX_LISTED,
                spacecraft_names=[s.name for s in visible_spacecraft(session, who)], types=sorted(registry()),
                statuses=STATUSES, selected={"spacecraft": spacecraft or "", "type": type or "",
                                             "status": wanted_status or ""})


@router.get("/status")
def job_status(request: Request, session: SessionDep, ids: str = "") -> JSONResponse:
    """Status, progress and stage of up to 100 jobs (for the pages' live updates)."""
    who = current_principal(request)
    if who is None:
        return JSONResponse({"detail": "sign in again"}, status_code=401, headers=NO_STORE)
    wanted = [i for i in ids.split(",") if i][:100]
    rows = session.execute(select(Job.id, Job.status, Job.progress, Job.stage, Job.error, Job.spacecraft_id)
                           .where(Job.id.in_(wanted))).all() if wanted else []
    out = {r.id: {"status": r.status, "progress": r.progress, "stage": r.stage, "error": r.error,
                  "final": r.status in FINAL} for r in rows if who.may_use(r.spacecraft_id)}
    return JSONResponse(out, headers=NO_STORE)


def _form_defaults(request: Request) -> dict[str, str]:
    q = request.query_params
    return {"type": q.get("type", ""), "spacecraft": q.get("spacecraft", ""), "start": q.get("start", ""),
            "end": q.get("end", ""), "time_scale": q.get("time_scale", "utc"), "params": q.get("params", "{}"),
            "reference": q.get("reference", "")}


def _new_form(request: Request, session: Any, who: Any, values: dict[str, str], status_code: int = 200,
              error: str | None = None, errors: list[Any] | None = None) -> HTMLResponse:
    types = sorted(registry().values(), key=lambda j: j.name)
    schemas = {j.name: j.params.model_json_schema().get("properties", {}) for j in types}
    return page(request, "job_new.html", status_code=status_code, values=values, types=types, schemas=schemas,
                spacecraft_names=[s.name for s in visible_spacecraft(session, who)], time_scales=TIME_SCALES,
                error=error, errors=errors or [])


@router.get("/new")
def new_job(request: Request, session: SessionDep, who: WebOperator) -> HTMLResponse:
    return _new_form(request, session, who, _form_defaults(request))


@router.post("")
def submit_job(request: Request, session: SessionDep, who: WebOperator, type: Annotated[str, Form()],
               spacecraft: Annotated[str, Form()], csrf: Annotated[str | None, Form()] = None,
               start: Annotated[str, Form()] = "", end: Annotated[str, Form()] = "",
               time_scale: Annotated[str, Form()] = "utc", params: Annotated[str, Form()] = "{}",
               reference: Annotated[str, Form()] = "") -> Response:
    check_form(request, csrf)
    values = {"type": type, "spacecraft": spacecraft, "start": start, "end": end, "time_scale": time_scale,
              "params": params, "reference": reference}
    try:
        parsed_params = json.loads(params or "{}")
        parsed_reference = json.loads(reference) if reference.strip() else {}
        if not isinstance(parsed_params, dict) or not isinstance(parsed_reference, dict):
            raise ValueError("must be a JSON object")
    except ValueError as exc:
        return _new_form(request, session, who, values, 422, f"parameters and reference must be JSON objects: {exc}")
    try:
        body = jobs_api.JobCreate(type=type, spacecraft=spacecraft, start=start.strip() or None,
                                  end=end.strip() or None, time_scale=time_scale, params=parsed_params,
                                  reference=parsed_reference)
        accepted = jobs_api.submit(body, request, session, who)
    except ValidationError as exc:
        return _new_form(request, session, who, values, 422, "invalid job request",
                         [{"column": ".".join(str(p) for p in e["loc"]), "message": e["msg"]} for e in exc.errors()])
    except HTTPException as exc:
        detail = exc.detail
        if isinstance(detail, dict):
            return _new_form(request, session, who, values, exc.status_code, str(detail.get("message")),
                             detail.get("errors"))
        return _new_form(request, session, who, values, exc.status_code, str(detail))
    return RedirectResponse(f"/ui/jobs/{accepted.id}", status_code=303)


@router.get("/{job_id}")
def job_page(request: Request, job_id: str, session: SessionDep, who: WebViewer) -> HTMLResponse:
    job, sc = jobs_api.get_job(session, job_id, who)
    jt = registry().get(job.type)
    data = report_json(job, sc, jt)
    return page(request, "job.html", job=job, sc=sc, jt=jt, d=data, summary=layout(data["summary"]),
                final=job.status in FINAL)


@router.post("/{job_id}/cancel")
def cancel_job(request: Request, job_id: str, session: SessionDep, who: WebOperator,
               csrf: Annotated[str | None, Form()] = None) -> RedirectResponse:
    check_form(request, csrf)
    jobs_api.cancel(job_id, session, who)
    return RedirectResponse(f"/ui/jobs/{urllib.parse.quote(job_id, safe='')}", status_code=303)


@router.get("/{job_id}/report")
def report_html(request: Request, job_id: str, session: SessionDep, who: WebViewer) -> HTMLResponse:
    job, sc = jobs_api.get_job(session, job_id, who)
    data = report_json(job, sc, registry().get(job.type), telemetry=request.app.state.store)
    html = render_html(data, job, artifact_store(request), ui=True)
    return HTMLResponse(html, headers={**NO_STORE,
                                       "Content-Disposition": f'inline; filename="{job.type}_{job.id}.html"'})


@router.get("/{job_id}/report.pdf")
def report_pdf(request: Request, job_id: str, session: SessionDep, who: WebViewer) -> Response:
    job, sc = jobs_api.get_job(session, job_id, who)
    data = report_json(job, sc, registry().get(job.type), telemetry=request.app.state.store)
    return Response(render_pdf(data, job, artifact_store(request)), media_type="application/pdf",
                    headers={**NO_STORE, "Content-Disposition": f'inline; filename="{job.type}_{job.id}.pdf"'})


@router.get("/{job_id}/report.json")
def report_json_download(request: Request, job_id: str, session: SessionDep, who: WebViewer) -> JSONResponse:
    job, sc = jobs_api.get_job(session, job_id, who)
    data = report_json(job, sc, registry().get(job.type), telemetry=request.app.state.store)
    return JSONResponse(data, headers={**NO_STORE,
                                       "Content-Disposition": f'inline; filename="{job.type}_{job.id}.json"'})


@router.get("/{job_id}/artifacts/{name}")
def artifact(request: Request, job_id: str, name: str, session: SessionDep, who: WebViewer) -> FileResponse:
    jobs_api.get_job(session, job_id, who)
    art = session.scalar(select(Artifact).where(Artifact.job_id == job_id, Artifact.name == name))
    if art is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"job {job_id} has no artifact {name!r}")
    path = artifact_store(request).path(art)
    if not path.is_file():
        raise HTTPException(status.HTTP_410_GONE, f"artifact {name!r} of job {job_id} is missing on disk")
    inline = art.media_type.startswith("image/")
    return FileResponse(path, media_type=art.media_type, filename=art.name, headers=NO_STORE,
                        content_disposition_type="inline" if inline else "attachment")
