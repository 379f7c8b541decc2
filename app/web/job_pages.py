"""Web UI pages of jobs: list with live status, run form, job page, reports (HTML, PDF, JSON), artifacts.

Submitting and cancelling go through the services the API uses (app/services/jobs.py), so the UI
applies exactly the API's checks (parameters, window, reference data, roles, spacecraft grants).
"""

from __future__ import annotations

import dataclasses
import json
import urllib.parse
from collections.abc import Mapping
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Form, HTTPException, Query, Request
from fastapi.responses import HTMLResponse, JSONResponse, RedirectResponse, Response
from pydantic import ValidationError

from app.api.deps import SessionDep, SettingsDep, StoreDep
from app.api.errors import http_status
from app.api.routes.jobs import artifact_response
from app.reports.job_report import render_html, render_pdf
from app.reports.summary import layout
from app.services import jobs
from app.services.errors import ServiceError
from app.services.jobs import JobCreate
from app.services.spacecraft import visible_spacecraft
from app.web import params_form
from app.web.auth import WebOperator, WebViewer, check_form, current_principal
from app.web.render import NO_STORE, HtmlRoute, page
from app.web.routes import TIME_SCALES
from storage.jobs import FINAL

router = APIRouter(prefix="/ui/jobs", route_class=HtmlRoute, include_in_schema=False)

STATUSES = ("queued", "running", "succeeded", "failed", "cancelled")
MAX_LISTED = 100


@router.get("")
def job_list(request: Request, session: SessionDep, who: WebViewer, spacecraft: str | None = None,
             type: str | None = None, status_: Annotated[str | None, Query(alias="status")] = None) -> HTMLResponse:
    wanted_status = status_ or None
    if wanted_status is not None and wanted_status not in STATUSES:
        raise HTTPException(422, f"status must be one of {', '.join(STATUSES)}")
    listed = jobs.list_jobs(session, who, spacecraft or None, type or None, wanted_status, None, MAX_LISTED)
    shown = [(j, s.name) for j, s in listed.items]
    return page(request, "jobs.html", jobs=shown, briefs=jobs.briefs(session, shown),
                more=listed.next_cursor is not None,
                spacecraft_names=[s.name for s in visible_spacecraft(session, who)],
                types=sorted(j.name for j in jobs.job_types()), statuses=STATUSES,
                selected={"spacecraft": spacecraft or "", "type": type or "", "status": wanted_status or ""})


@router.get("/status")
def job_status(request: Request, session: SessionDep, ids: str = "") -> JSONResponse:
    """Status, progress and stage of up to 100 jobs (for the pages' live updates)."""
    who = current_principal(request)
    if who is None:
        return JSONResponse({"detail": "sign in again"}, status_code=401, headers=NO_STORE)
    wanted = [i for i in ids.split(",") if i][:100]
    out = {job_id: dataclasses.asdict(p) for job_id, p in jobs.progress(session, who, wanted).items()}
    return JSONResponse(out, headers=NO_STORE)


def _form_defaults(request: Request) -> dict[str, str]:
    q = request.query_params
    return {"type": q.get("type", ""), "spacecraft": q.get("spacecraft", ""), "start": q.get("start", ""),
            "end": q.get("end", ""), "time_scale": q.get("time_scale", "utc"), "params": q.get("params", "{}"),
            "reference": q.get("reference", "")}


def _new_form(request: Request, session: Any, who: Any, values: dict[str, str], status_code: int = 200,
              error: str | None = None, errors: list[Any] | None = None,
              typed: Mapping[str, Any] | None = None) -> HTMLResponse:
    types = sorted(jobs.job_types(), key=lambda j: j.name)
    form_fields = {j.name: params_form.fields(j.params) for j in types}
    by_field = {str(e.get("column") or ""): str(e.get("message")) for e in errors or []}
    return page(request, "job_new.html", status_code=status_code, values=values, types=types,
                form_fields=form_fields, typed=typed or {}, field_errors=by_field,
                spacecraft_names=[s.name for s in visible_spacecraft(session, who)], time_scales=TIME_SCALES,
                error=error, errors=errors or [])


@router.get("/new")
def new_job(request: Request, session: SessionDep, who: WebOperator) -> HTMLResponse:
    return _new_form(request, session, who, _form_defaults(request))


async def _form(request: Request) -> Mapping[str, Any]:
    """Every field of the submitted form (the typed parameter fields have names of their job type)."""
    return await request.form()


@router.post("")
def submit_job(request: Request, session: SessionDep, who: WebOperator, type: Annotated[str, Form()],
               spacecraft: Annotated[str, Form()], form: Annotated[Mapping[str, Any], Depends(_form)],
               csrf: Annotated[str | None, Form()] = None,
               start: Annotated[str, Form()] = "", end: Annotated[str, Form()] = "",
               time_scale: Annotated[str, Form()] = "utc", params: Annotated[str, Form()] = "{}",
               reference: Annotated[str, Form()] = "") -> Response:
    check_form(request, csrf)
    values = {"type": type, "spacecraft": spacecraft, "start": start, "end": end, "time_scale": time_scale,
              "params": params, "reference": reference}
    jt = next((j for j in jobs.job_types() if j.name == type), None)
    typed = {k: str(v) for k, v in form.items() if k.startswith(params_form.PREFIX)}
    from_fields, field_problems = params_form.read(jt.params, jt.name, form) if jt is not None else ({}, [])
    if field_problems:
        return _new_form(request, session, who, values, 422, "some parameters could not be read", field_problems,
                         typed)
    try:
        parsed_params = json.loads(params or "{}")
        parsed_reference = json.loads(reference) if reference.strip() else {}
        if not isinstance(parsed_params, dict) or not isinstance(parsed_reference, dict):
            raise ValueError("must be a JSON object")
    except ValueError as exc:
        return _new_form(request, session, who, values, 422, f"parameters and reference must be JSON objects: {exc}",
                         typed=typed)
    parsed_params = {**from_fields, **parsed_params}  # the JSON area overrides the typed fields
    try:
        body = JobCreate(type=type, spacecraft=spacecraft, start=start.strip() or None, end=end.strip() or None,
                         time_scale=time_scale, params=parsed_params, reference=parsed_reference)
        job = jobs.submit(session, body, who, on_submit=request.app.state.executor.wake,
                          max_queued=request.app.state.settings.max_queued_jobs_per_key)
    except ValidationError as exc:
        return _new_form(request, session, who, values, 422, "invalid job request",
                         [{"column": ".".join(str(p) for p in e["loc"]), "message": e["msg"]} for e in exc.errors()],
                         typed)
    except ServiceError as exc:
        detail = exc.detail
        if isinstance(detail, dict):
            return _new_form(request, session, who, values, http_status(exc), str(detail.get("message")),
                             detail.get("errors"), typed)
        return _new_form(request, session, who, values, http_status(exc), str(detail), typed=typed)
    return RedirectResponse(f"/ui/jobs/{job.id}", status_code=303)


@router.get("/{job_id}")
def job_page(request: Request, job_id: str, session: SessionDep, who: WebViewer) -> HTMLResponse:
    r = jobs.report(session, job_id, who)
    return page(request, "job.html", job=r.job, sc=r.spacecraft, jt=r.job_type, d=r.data,
                summary=layout(r.data["summary"]), final=r.job.status in FINAL)


@router.post("/{job_id}/cancel")
def cancel_job(request: Request, job_id: str, session: SessionDep, who: WebOperator,
               csrf: Annotated[str | None, Form()] = None) -> RedirectResponse:
    check_form(request, csrf)
    jobs.cancel(session, job_id, who)
    return RedirectResponse(f"/ui/jobs/{urllib.parse.quote(job_id, safe='')}", status_code=303)


def _inline(r: jobs.JobReport, ext: str) -> dict[str, str]:
    return {**NO_STORE, "Content-Disposition": f'inline; filename="{r.job.type}_{r.job.id}.{ext}"'}


@router.get("/{job_id}/report")
def report_html(job_id: str, session: SessionDep, store: StoreDep, settings: SettingsDep,
                who: WebViewer) -> HTMLResponse:
    r = jobs.report(session, job_id, who, telemetry=store)
    html = render_html(r.data, r.job, jobs.artifact_store(settings), ui=True)
    return HTMLResponse(html, headers=_inline(r, "html"))


@router.get("/{job_id}/report.pdf")
def report_pdf(job_id: str, session: SessionDep, store: StoreDep, settings: SettingsDep, who: WebViewer) -> Response:
    r = jobs.report(session, job_id, who, telemetry=store)
    return Response(render_pdf(r.data, r.job, jobs.artifact_store(settings)), media_type="application/pdf",
                    headers=_inline(r, "pdf"))


@router.get("/{job_id}/report.json")
def report_json_download(job_id: str, session: SessionDep, store: StoreDep, who: WebViewer) -> JSONResponse:
    r = jobs.report(session, job_id, who, telemetry=store)
    return JSONResponse(r.data, headers=_inline(r, "json"))


@router.get("/{job_id}/artifacts/{name}")
def artifact(job_id: str, name: str, session: SessionDep, settings: SettingsDep, who: WebViewer) -> Response:
    return artifact_response(jobs.artifact_file(session, settings, job_id, name, who), dict(NO_STORE))
