"""Web UI pages that change the catalog: spacecraft and their configurations (admins), schedules
(operators), retraction of uploads (operators) and the quarantine of damaged files (admins).

Every action goes through the service the API uses (app/services), so the UI applies the API's checks;
invalid input comes back on the same form with one message per field.
"""

from __future__ import annotations

import json
import urllib.parse
from typing import Annotated, Any

from fastapi import APIRouter, Form, Request
from fastapi.responses import HTMLResponse, RedirectResponse, Response
from pydantic import ValidationError

from app.api.deps import SessionDep, StoreDep
from app.api.errors import http_status
from app.config_schema import SpacecraftConfig
from app.names import valid_name
from app.services import ingests, jobs, schedules
from app.services import spacecraft as spacecraft_service
from app.services.errors import ServiceError
from app.services.schedules import ScheduleSpec
from app.services.spacecraft import visible_spacecraft
from app.services.suggest import field_errors
from app.web.auth import WebAdmin, WebOperator, WebViewer, check_form
from app.web.render import HtmlRoute, page

router = APIRouter(prefix="/ui", route_class=HtmlRoute, include_in_schema=False)

CONFIG_EXAMPLE = {"star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]}}, "gyro": {"q_BG": [1, 0, 0, 0]}}
WINDOWS = ("previous", "since_last_success")


def _q(name: str) -> str:
    return urllib.parse.quote(name, safe="")


def _config_help() -> list[tuple[str, str]]:
    props = SpacecraftConfig.model_json_schema().get("properties", {})
    return [(k, str(v.get("description") or "")) for k, v in props.items()]


def _parse_config(text: str) -> tuple[SpacecraftConfig | None, list[dict[str, Any]]]:
    """The configuration of a form's JSON text, or the errors (one per field)."""
    try:
        raw = json.loads(text or "{}")
    except json.JSONDecodeError as exc:
        return None, [{"row": None, "column": "config", "message": f"not JSON: {exc.msg} at line {exc.lineno}, "
                                                                    f"column {exc.colno}"}]
    if not isinstance(raw, dict):
        return None, [{"row": None, "column": "config", "message": "expected a JSON object {...}"}]
    try:
        return SpacecraftConfig.model_validate(raw), []
    except ValidationError as exc:
        return None, field_errors(exc, SpacecraftConfig, prefix="config.")


def _config_form(request: Request, *, mode: str, name: str, text: str, errors: list[dict[str, Any]],
                 status_code: int = 200, sc: Any = None, versions: Any = None, message: str | None = None
                 ) -> HTMLResponse:
    return page(request, "spacecraft_form.html", status_code=status_code, mode=mode, name=name, text=text,
                errors=errors, sc=sc, versions=versions or [], message=message, fields=_config_help())


@router.get("/spacecraft/new")
def new_spacecraft(request: Request, who: WebAdmin) -> HTMLResponse:
    return _config_form(request, mode="create", name="", text=json.dumps(CONFIG_EXAMPLE, indent=2), errors=[])


@router.post("/spacecraft")
def create_spacecraft(request: Request, session: SessionDep, who: WebAdmin, name: Annotated[str, Form()] = "",
                      config: Annotated[str, Form()] = "{}", csrf: Annotated[str | None, Form()] = None) -> Response:
    check_form(request, csrf)
    name = name.strip()
    parsed, errors = _parse_config(config)
    if not valid_name(name):
        errors.insert(0, {"row": None, "column": "name", "message": f"1-64 letters, digits, _ . - ; got {name!r}"})
    if errors or parsed is None:
        return _config_form(request, mode="create", name=name, text=config, errors=errors, status_code=422,
                            message="not created: fix the fields below")
    try:
        spacecraft_service.create(session, name, parsed, who)
    except ServiceError as exc:
        return _config_form(request, mode="create", name=name, text=config, status_code=http_status(exc),
                            errors=[{"row": None, "column": "name", "message": str(exc.detail)}],
                            message="not created")
    return RedirectResponse(f"/ui/spacecraft/{_q(name)}?created=1", status_code=303)


def _versions(sc: Any) -> list[Any]:
    return sorted(sc.configs, key=lambda c: c.version, reverse=True)


@router.get("/spacecraft/{name}/config")
def config_page(request: Request, name: str, session: SessionDep, who: WebViewer) -> HTMLResponse:
    current = spacecraft_service.read(session, name, who)
    return _config_form(request, mode="edit", name=name, sc=current.spacecraft, versions=_versions(current.spacecraft),
                        text=json.dumps(current.config.config, indent=2), errors=[])


@router.post("/spacecraft/{name}/config")
def save_config(request: Request, name: str, session: SessionDep, who: WebAdmin,
                config: Annotated[str, Form()] = "{}", csrf: Annotated[str | None, Form()] = None) -> Response:
    check_form(request, csrf)
    current = spacecraft_service.read(session, name, who)
    parsed, errors = _parse_config(config)
    if errors or parsed is None:
        return _config_form(request, mode="edit", name=name, sc=current.spacecraft, text=config, errors=errors,
                            versions=_versions(current.spacecraft), status_code=422,
                            message="not saved: fix the fields below; the stored configuration is unchanged")
    saved = spacecraft_service.update_config(session, name, parsed, who)
    return RedirectResponse(f"/ui/spacecraft/{_q(name)}?config_version={saved.config.version}", status_code=303)


@router.post("/spacecraft/{name}/ingests/{ingest_id}/retract")
def retract_upload(request: Request, name: str, ingest_id: str, session: SessionDep, store: StoreDep,
                   who: WebOperator, reason: Annotated[str, Form()] = "",
                   csrf: Annotated[str | None, Form()] = None) -> RedirectResponse:
    check_form(request, csrf)
    r = ingests.retract(session, store, name, ingest_id, reason, who)
    return RedirectResponse(f"/ui/spacecraft/{_q(name)}?{urllib.parse.urlencode({'retracted': r.id})}#uploads",
                            status_code=303)


@router.post("/spacecraft/{name}/quarantine/{file_id}/restore")
def restore_file(request: Request, name: str, file_id: int, session: SessionDep, store: StoreDep, who: WebAdmin,
                 csrf: Annotated[str | None, Form()] = None) -> RedirectResponse:
    check_form(request, csrf)
    ingests.restore(session, store, name, file_id, who)
    return RedirectResponse(f"/ui/spacecraft/{_q(name)}#quarantine", status_code=303)


# -- schedules ----------------------------------------------------------------------------------------

def _schedules_page(request: Request, session: Any, who: Any, values: dict[str, str] | None = None,
                    errors: list[dict[str, Any]] | None = None, message: str | None = None,
                    status_code: int = 200) -> HTMLResponse:
    return page(request, "schedules.html", status_code=status_code, schedules=schedules.list_schedules(session, who),
                spacecraft_names=[s.name for s in visible_spacecraft(session, who)],
                types=sorted(jt.name for jt in jobs.job_types()), windows=WINDOWS,
                values=values or {"name": "", "cron": "0 2 * * *", "type": "", "spacecraft": "", "window": "previous",
                                  "window_s": "", "params": "{}", "enabled": "true"},
                errors=errors or [], message=message)


@router.get("/schedules")
def schedules_page(request: Request, session: SessionDep, who: WebViewer) -> HTMLResponse:
    return _schedules_page(request, session, who)


@router.post("/schedules")
def create_schedule(request: Request, session: SessionDep, who: WebOperator, name: Annotated[str, Form()] = "",
                    cron: Annotated[str, Form()] = "", type: Annotated[str, Form()] = "",
                    spacecraft: Annotated[str, Form()] = "", window: Annotated[str, Form()] = "previous",
                    window_s: Annotated[str, Form()] = "", params: Annotated[str, Form()] = "{}",
                    enabled: Annotated[str, Form()] = "true", csrf: Annotated[str | None, Form()] = None) -> Response:
    check_form(request, csrf)
    values = {"name": name.strip(), "cron": cron.strip(), "type": type, "spacecraft": spacecraft, "window": window,
              "window_s": window_s.strip(), "params": params, "enabled": enabled}
    errors = []
    try:
        parsed = json.loads(params or "{}")
        if not isinstance(parsed, dict):
            raise ValueError("expected a JSON object {...}")
    except ValueError as exc:
        errors.append({"row": None, "column": "params", "message": f"not a JSON object: {exc}"})
        parsed = {}
    seconds: int | None = None
    if values["window_s"]:
        try:
            seconds = int(values["window_s"])
            if not 0 < seconds <= 366 * 86_400:
                raise ValueError
        except ValueError:
            errors.append({"row": None, "column": "window_s", "message": "a whole number of seconds, 1 .. 31622400"})
    if not valid_name(values["name"]):
        errors.append({"row": None, "column": "name", "message": "1-64 letters, digits, _ . -"})
    if window not in WINDOWS:
        errors.append({"row": None, "column": "window", "message": f"one of {', '.join(WINDOWS)}"})
    if errors:
        return _schedules_page(request, session, who, values, errors, "not created", 422)
    try:
        s, _ = schedules.create(session, ScheduleSpec(
            name=values["name"], cron=values["cron"], job_type=type, spacecraft=spacecraft, params=parsed,
            reference={}, window=window, window_s=seconds, enabled=enabled == "true"), who,
            min_period_s=request.app.state.settings.min_schedule_period_s)
    except ServiceError as exc:
        detail = exc.detail
        if isinstance(detail, dict):
            return _schedules_page(request, session, who, values, detail.get("errors") or [],
                                   str(detail.get("message")), http_status(exc))
        column = str(detail).split(":", 1)[0] if ":" in str(detail) else None
        return _schedules_page(request, session, who, values, [{"row": None, "column": column,
                                                                 "message": str(detail)}],
                               "not created", http_status(exc))
    return RedirectResponse(f"/ui/schedules/{s.id}", status_code=303)


@router.get("/schedules/{schedule_id}")
def schedule_page(request: Request, schedule_id: str, session: SessionDep, who: WebViewer) -> HTMLResponse:
    s, sc = schedules.get_schedule(session, schedule_id, who)
    return page(request, "schedule.html", s=s, sc=sc, runs=schedules.runs(session, schedule_id, who, 200))


@router.post("/schedules/{schedule_id}/delete")
def delete_schedule(request: Request, schedule_id: str, session: SessionDep, who: WebOperator,
                    csrf: Annotated[str | None, Form()] = None) -> RedirectResponse:
    check_form(request, csrf)
    schedules.delete(session, schedule_id, who)
    return RedirectResponse("/ui/schedules?deleted=1", status_code=303)
