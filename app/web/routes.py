"""Web UI pages: sign-in, spacecraft list, per spacecraft coverage timeline, uploads and trends.

Server-rendered (Jinja2), a little JavaScript for live job status (static/app.js), no build step.
Every page checks the caller exactly as the API does: the same roles (viewer reads, operator uploads
and runs jobs) and the same spacecraft grants, through the services the API uses (app/services).
"""

from __future__ import annotations

import csv
import hashlib
import io
import math
import urllib.parse
from typing import Annotated, Any

from fastapi import APIRouter, File, Form, HTTPException, Request, UploadFile, status
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response

from app.api.deps import SessionDep, StoreDep
from app.api.errors import http_status
from app.api.files import download_response
from app.api.gate import client_address
from app.ingest.errors import UploadError
from app.jobs.outputs import csv_cell
from app.reports import specs as speclib
from app.reports import trends as trendlib
from app.services import coverage, ingests, jobs, telemetry, trends
from app.services.downloads import table_download
from app.services.errors import Unsupported
from app.services.spacecraft import get_spacecraft, latest_config, overview
from app.services.times import parse_bound
from app.web import timeline
from app.web.auth import (
    COOKIE,
    COOKIE_PATH,
    WebOperator,
    WebViewer,
    check_form,
    check_same_site,
    end_ui_session,
    start_ui_session,
)
from app.web.render import STATIC, HtmlRoute, page
from processing.streams import STREAMS
from storage.telemetry import ConflictError, IngestMeta

router = APIRouter(prefix="/ui", route_class=HtmlRoute, include_in_schema=False)
root_router = APIRouter(include_in_schema=False)

STATIC_FILES = {"app.css": "text/css; charset=utf-8", "app.js": "text/javascript; charset=utf-8",
                "viewer.js": "text/javascript; charset=utf-8", "forms.js": "text/javascript; charset=utf-8"}
EXTENSION_TYPES = {".csv": "text/csv", ".parquet": "application/vnd.apache.parquet",
                   ".pq": "application/vnd.apache.parquet", ".arrow": "application/vnd.apache.arrow.stream",
                   ".arrows": "application/vnd.apache.arrow.stream", ".json": "application/json"}
TIME_SCALES = ("utc", "tai", "gps", "tt")


@root_router.get("/")
def root() -> RedirectResponse:
    return RedirectResponse("/ui/", status_code=303)


@router.get("/static/{name}")
def static(name: str) -> FileResponse:
    if name not in STATIC_FILES:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no static file {name!r}")
    return FileResponse(STATIC / name, media_type=STATIC_FILES[name], headers={"Cache-Control": "max-age=300"})


def _safe_next(target: str | None) -> str:
    """Only local UI paths are followed after sign-in (no open redirects)."""
    if target and target.startswith("/ui/") and not target.startswith("//") and "\\" not in target:
        return target
    return "/ui/"


@router.get("/login")
def login_form(request: Request, next: str | None = None) -> HTMLResponse:
    return page(request, "login.html", next=_safe_next(next), error=None)


@router.post("/login")
def login(request: Request, api_key: Annotated[str, Form()] = "",
          next: Annotated[str | None, Form()] = None) -> Response:
    check_same_site(request)
    secret = api_key.strip()
    address = client_address(request.scope)
    throttle = request.app.state.auth_throttle
    if (wait := throttle.wait(address)) > 0:
        return page(request, "login.html", status_code=429, next=_safe_next(next),
                    error=f"Too many failed sign-ins from this address; try again in {math.ceil(wait)} s.")
    token = start_ui_session(request, secret) if secret else None
    if token is None:
        if secret:
            throttle.failed(address)
        return page(request, "login.html", status_code=401, next=_safe_next(next),
                    error="This API key is not valid (unknown, expired or revoked).")
    response = RedirectResponse(_safe_next(next), status_code=303)
    response.set_cookie(COOKIE, token, path=COOKIE_PATH, httponly=True, samesite="lax",
                        secure=request.url.scheme == "https")
    return response


@router.post("/logout")
def logout(request: Request) -> RedirectResponse:
    check_same_site(request)
    end_ui_session(request)
    response = RedirectResponse("/ui/login", status_code=303)
    response.delete_cookie(COOKIE, path=COOKIE_PATH, httponly=True, samesite="lax",
                           secure=request.url.scheme == "https")
    return response


@router.get("/")
def index(request: Request, session: SessionDep, who: WebViewer) -> HTMLResponse:
    return page(request, "index.html", spacecraft=overview(session, who))


def _stripped(value: str | None) -> str | None:
    return value.strip() if value is not None else None


def parse_time(value: str | None, field: str) -> int | None:
    """ISO 8601 UTC (or seconds since 1970 UTC) to TAI ns; None for empty."""
    return parse_bound(_stripped(value), "utc", field)


@router.get("/spacecraft/{name}")
def spacecraft_page(request: Request, name: str, session: SessionDep, who: WebViewer, start: str | None = None,
                    end: str | None = None, uploaded: str | None = None, retracted: str | None = None,
                    created: str | None = None, config_version: int | None = None) -> HTMLResponse:
    sc = get_spacecraft(session, name, who)
    cfg = latest_config(session, sc)
    t0, t1 = parse_time(start, "start"), parse_time(end, "end")
    if t0 is not None and t1 is not None and t1 <= t0:
        raise HTTPException(422, "end must be after start")
    tl = coverage.build(session, sc.id, t0, t1)
    retractions = ingests.retractions(session, name, who, 20)
    recent = [(j, sc.name) for j in jobs.recent_jobs(session, sc, 20)]
    is_admin = who.role == "admin"
    return page(request, "spacecraft.html", sc=sc, config=cfg, specs=speclib.parse(cfg.config), timeline=tl,
                retractions=retractions, retracted=next((r for r in retractions if r.id == retracted), None),
                marked={r.id: ingests.marked_jobs(session, r) for r in retractions},
                quarantined=ingests.quarantined(session, name, who) if is_admin else [], is_admin=is_admin,
                created=bool(created), saved_version=config_version,
                geometry=timeline.geometry(tl) if tl is not None else None,
                ingests=telemetry.recent_ingests(session, sc, 20),
                jobs=recent, briefs=jobs.briefs(session, recent), streams=list(STREAMS),
                formats=sorted(d.name for d in telemetry.list_formats()), time_scales=TIME_SCALES,
                view_start=start or "", view_end=end or "",
                uploaded=telemetry.find_ingest(session, sc, uploaded) if uploaded else None,
                job_types=sorted(jobs.job_types(), key=lambda j: j.name))


@router.get("/spacecraft/{name}/telemetry/{stream}.csv")
def telemetry_csv(name: str, stream: str, session: SessionDep, store: StoreDep, who: WebViewer,
                  start: str | None = None, end: str | None = None, sensor: str | None = None) -> Response:
    """The stored samples of one stream in a window, as the API's CSV download."""
    table = telemetry.read(session, store, name, stream, who, start, end, "utc", sensor)
    return download_response(table_download(table, "csv", "utc", "iso", f"{name}_{stream}"))


def _content_type(upload: UploadFile) -> str:
    filename = (upload.filename or "").lower()
    for ext, media in EXTENSION_TYPES.items():
        if filename.endswith(ext):
            return media
    return upload.content_type or "application/octet-stream"


@router.post("/spacecraft/{name}/upload")
async def upload(request: Request, name: str, session: SessionDep, store: StoreDep, who: WebOperator,
                 stream: Annotated[str, Form()], file: Annotated[UploadFile, File()],
                 csrf: Annotated[str | None, Form()] = None, time_scale: Annotated[str, Form()] = "utc",
                 sensor: Annotated[str | None, Form()] = None,
                 quaternion_direction: Annotated[str, Form()] = "sensor_to_inertial",
                 format: Annotated[str | None, Form()] = None) -> Response:
    """The upload form: the same validation and all-or-nothing ingest as the API's upload route."""
    check_form(request, csrf)
    spec = telemetry.get_stream(stream)
    sc = get_spacecraft(session, name, who)
    config = latest_config(session, sc).config
    if time_scale not in TIME_SCALES:
        raise HTTPException(422, f"time_scale must be one of {', '.join(TIME_SCALES)}")
    body = await file.read()
    content_type = _content_type(file)
    meta = IngestMeta(filename=(file.filename or "")[:255] or None,
                      content_type=content_type[:100], size_bytes=len(body),
                      checksum_sha256=hashlib.sha256(body).hexdigest(), time_scale=time_scale, api_key_id=who.key_id)
    opts = telemetry.upload_options(config, time_scale, (sensor or "").strip() or None, 1e-3, quaternion_direction)
    context: dict[str, Any] = {"sc": sc, "stream": stream, "filename": file.filename}
    try:
        rec, _notes = await run_in_threadpool(
            telemetry.ingest_upload, session, store, sc, spec, body, content_type, opts, meta, config,
            (format or None) if format != "table" else None, request.app.state.settings.max_upload_rows,
            request.app.state.settings.max_upload_days)
    except UploadError as exc:
        return page(request, "upload_result.html", status_code=422,
                    message=f"upload rejected, nothing stored: {exc}",
                    errors=[e.as_dict() for e in exc.errors], **context)
    except ConflictError as exc:
        return page(request, "upload_result.html", status_code=409,
                    message=f"upload rejected, nothing stored: {exc.total} rows differ from stored samples with "
                            "the same identity (sensor, time)", errors=[], conflicts=exc.rows, **context)
    except (telemetry.TooManyRows, Unsupported) as exc:
        return page(request, "upload_result.html", status_code=http_status(exc), message=str(exc.detail), errors=[],
                    **context)
    target = f"/ui/spacecraft/{urllib.parse.quote(sc.name, safe='')}?{urllib.parse.urlencode({'uploaded': rec.id})}"
    return RedirectResponse(target + "#uploads", status_code=303)


@router.get("/spacecraft/{name}/trends")
def trends_page(request: Request, name: str, session: SessionDep, who: WebViewer, type: str | None = None,
                start: str | None = None, end: str | None = None) -> HTMLResponse:
    sel = trends.select_trends(session, name, who, type or None, _stripped(start), _stripped(end))
    figures = [{"title": t.metric.title, "unit": t.metric.unit, "key": t.metric.key, "job_type": t.metric.job_type,
                "png": trendlib.figure_png_b64(t), "n": len(t.points)} for t in sel.trends]
    query = urllib.parse.urlencode({k: v for k, v in (("type", type), ("start", start), ("end", end)) if v})
    return page(request, "trends.html", sc=sel.spacecraft, figures=figures, rows=trendlib.rows(sel.trends),
                available=sel.available, selected_type=type or "", view_start=start or "", view_end=end or "",
                csv_query=query)


@router.get("/spacecraft/{name}/trends.csv")
def trends_csv(name: str, session: SessionDep, who: WebViewer, type: str | None = None, start: str | None = None,
               end: str | None = None) -> Response:
    sel = trends.select_trends(session, name, who, type or None, _stripped(start), _stripped(end))
    buf = io.StringIO()
    fields = ["job_id", "job_type", "series", "window_start", "window_end", "metric", "component", "value", "unit",
              "sigma"]
    writer = csv.DictWriter(buf, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: csv_cell(v) for k, v in row.items()} for row in trendlib.rows(sel.trends))
    return Response(buf.getvalue(), media_type="text/csv",
                    headers={"Content-Disposition": f'attachment; filename="{sel.spacecraft.name}_trends.csv"',
                             "Cache-Control": "no-store"})
