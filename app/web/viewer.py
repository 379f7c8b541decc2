"""The telemetry viewer page: a stream and sensor over a time range, zoomable, with the samples a screening
job rejected marked and listed, and a download of exactly the view (app/services/viewer.py)."""

from __future__ import annotations

import time
import urllib.parse
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request
from fastapi.responses import HTMLResponse, JSONResponse, Response

from app.api.deps import SessionDep, SettingsDep, StoreDep
from app.api.errors import http_status
from app.api.files import download_response
from app.services import jobs, viewer
from app.services.downloads import table_download
from app.services.errors import NotFound, ServiceError
from app.web.auth import WebViewer, current_principal
from app.web.render import NO_STORE, HtmlRoute, page

router = APIRouter(prefix="/ui/spacecraft/{name}/viewer", route_class=HtmlRoute, include_in_schema=False)
data_router = APIRouter(prefix="/ui/spacecraft/{name}/viewer", include_in_schema=False)

DEFAULT_WIDTH_PX = 1100


def _query(sel: viewer.Selection) -> dict[str, str]:
    return {"stream": sel.spec.name, "sensor": sel.sensor,
            "start": viewer.iso(sel.start_tai_ns), "end": viewer.iso(sel.end_tai_ns),
            "screening": sel.screening_job.id if sel.screening_job is not None else "none"}


@router.get("")
def viewer_page(request: Request, name: str, session: SessionDep, who: WebViewer, stream: str | None = None,
                sensor: str | None = None, start: str | None = None, end: str | None = None,
                screening: str | None = None) -> HTMLResponse:
    sel = viewer.select_view(session, name, who, stream or None, sensor or None, (start or "").strip() or None,
                             (end or "").strip() or None, screening)
    query = _query(sel)
    return page(request, "viewer.html", sc=sel.spacecraft, sel=sel, query=query,
                streams=viewer.stream_sensors(session, sel.spacecraft),
                data_url=f"/ui/spacecraft/{urllib.parse.quote(name, safe='')}/viewer/data.json",
                qs=urllib.parse.urlencode(query))


@data_router.get("/data.json")
def viewer_data(request: Request, name: str, session: SessionDep, store: StoreDep, settings: SettingsDep,
                stream: str | None = None, sensor: str | None = None, start: str | None = None,
                end: str | None = None, screening: str = "none",
                width: Annotated[int, Query(ge=100, le=4000)] = DEFAULT_WIDTH_PX) -> JSONResponse:
    """The decimated plot data of one window (fetched by static/viewer.js on load, zoom and pan)."""
    who = current_principal(request)
    if who is None:
        return JSONResponse({"detail": "sign in again"}, status_code=401, headers=NO_STORE)
    t0 = time.perf_counter()
    try:
        sel = viewer.select_view(session, name, who, stream, sensor, start, end, screening)
        body: dict[str, Any] = viewer.view_json(session, store, jobs.artifact_store(settings), sel, width)
    except ServiceError as exc:
        return JSONResponse({"detail": exc.detail}, status_code=http_status(exc), headers=NO_STORE)
    body["server_ms"] = round((time.perf_counter() - t0) * 1000.0, 1)
    query = urllib.parse.urlencode(_query(sel))
    base = f"/ui/spacecraft/{urllib.parse.quote(name, safe='')}/viewer"
    body["downloads"] = {"csv": f"{base}/download.csv?{query}", "parquet": f"{base}/download.parquet?{query}"}
    return JSONResponse(body, headers=NO_STORE)


@router.get("/download.{fmt}")
def viewer_download(name: str, fmt: str, session: SessionDep, store: StoreDep, settings: SettingsDep,
                    who: WebViewer, stream: str | None = None, sensor: str | None = None, start: str | None = None,
                    end: str | None = None, screening: str = "none") -> Response:
    """Exactly the view: every stored sample of the stream and sensor in the window, with ``rejected_by``."""
    if fmt not in ("csv", "parquet"):
        raise NotFound(f"no download format {fmt!r}; csv or parquet")
    sel = viewer.select_view(session, name, who, stream, sensor, start, end, screening)
    table = viewer.download_table(session, store, jobs.artifact_store(settings), sel)
    stem = f"{name}_{sel.spec.name}_{sel.sensor}_{_stamp(sel.start_tai_ns)}_{_stamp(sel.end_tai_ns)}"
    return download_response(table_download(table, fmt, "utc", "iso", stem))


def _stamp(tai_ns: int) -> str:
    return viewer.iso(tai_ns).replace(":", "").replace("-", "")[:15]
