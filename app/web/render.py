"""Page rendering for the web UI: templates, HTML error pages, sign-in redirects."""

from __future__ import annotations

import urllib.parse
from collections.abc import Callable, Coroutine, Mapping
from pathlib import Path
from typing import Any

from fastapi import HTTPException, Request, Response
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, RedirectResponse
from fastapi.routing import APIRoute
from jinja2 import Environment, FileSystemLoader, select_autoescape

from app.api.errors import http_status
from app.reports.summary import iso, wall
from app.services.access import Principal
from app.services.errors import ServiceError
from app.version import __version__
from app.web.auth import LoginRequired, csrf_token, session_secret
from storage.keys import role_at_least

TEMPLATES = Path(__file__).parent / "templates"
REPORT_TEMPLATES = Path(__file__).parents[1] / "reports" / "templates"  # shared partials (warnings.html)
STATIC = Path(__file__).parent / "static"

env = Environment(loader=FileSystemLoader([TEMPLATES, REPORT_TEMPLATES]), autoescape=select_autoescape(["html"]),
                  trim_blocks=True, lstrip_blocks=True)
env.filters["iso"] = iso
env.filters["wall"] = wall
env.filters["q"] = lambda s: urllib.parse.quote(str(s), safe="")
NO_STORE = {"Cache-Control": "no-store"}


def page(request: Request, template: str, status_code: int = 200, **context: Any) -> HTMLResponse:
    """A page of the UI; pages show private data, so browsers must not keep them."""
    who: Principal | None = getattr(request.state, "principal", None)
    secret = session_secret(request)
    html = env.get_template(template).render(
        request=request, who=who, version=__version__,
        csrf=csrf_token(secret) if secret and who else "",
        can_operate=who is not None and role_at_least(who.role, "operator"), **context)
    return HTMLResponse(html, status_code=status_code, headers=NO_STORE)


def error_page(request: Request, status_code: int, detail: Any,
               headers: Mapping[str, str] | None = None) -> HTMLResponse:
    if isinstance(detail, dict):
        message = str(detail.get("message") or detail)
        errors = detail.get("errors") or []
    else:
        message, errors = str(detail), []
    response = page(request, "error.html", status_code=status_code, status=status_code, message=message,
                    errors=errors)
    for k, v in (headers or {}).items():
        response.headers[k] = v
    return response


def login_redirect(request: Request) -> RedirectResponse:
    target = request.url.path + (f"?{request.url.query}" if request.url.query else "")
    return RedirectResponse(f"/ui/login?{urllib.parse.urlencode({'next': target})}", status_code=303)


class HtmlRoute(APIRoute):
    """UI routes answer errors (HTTP errors and the refusals of app/services, with the API's status codes)
    with HTML pages and missing sessions with the sign-in form."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()

        async def html_errors(request: Request) -> Response:
            try:
                return await handler(request)
            except LoginRequired:
                return login_redirect(request)
            except HTTPException as exc:
                return error_page(request, exc.status_code, exc.detail, exc.headers)
            except ServiceError as exc:
                return error_page(request, http_status(exc), exc.detail)
            except RequestValidationError as exc:
                errors = [{"row": None, "column": ".".join(str(p) for p in e.get("loc", ())[1:]) or None,
                           "message": e.get("msg", "invalid")} for e in exc.errors()]
                return error_page(request, 422, {"message": "invalid request", "errors": errors})

        return html_errors
