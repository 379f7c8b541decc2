"""Error answers (4xx): their shape, declared in the OpenAPI schema of every route, and the status of
each refusal of the service layer."""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict

from app.services.errors import Busy, Conflict, Forbidden, Gone, Invalid, NotFound, ServiceError, TooLarge, Unsupported


class ErrorItem(BaseModel):
    row: int | None = None
    column: str | None = None
    message: str


class ErrorOut(BaseModel):
    """``detail`` says what went wrong; uploads add ``errors`` (row/column/message) or ``conflicts``."""

    model_config = ConfigDict(extra="allow")
    detail: Any
    errors: list[ErrorItem] | None = None
    error_count: int | None = None
    conflicts: list[ErrorItem] | None = None
    conflict_count: int | None = None


def error_responses(*codes: int) -> dict[int | str, dict[str, Any]]:
    return {code: {"model": ErrorOut} for code in codes}


# What any authenticated /api/v1 route may answer besides its own results.
COMMON_ERRORS = error_responses(400, 401, 403, 404, 409, 413, 414, 415, 422, 429, 500, 503, 507)


# The HTTP status of each refusal of the service layer (app/services/errors.py); the UI shows the same.
SERVICE_STATUS: dict[type[ServiceError], int] = {NotFound: 404, Conflict: 409, Gone: 410, TooLarge: 413,
                                                 Unsupported: 415, Invalid: 422, Forbidden: 403, Busy: 429}


def http_status(exc: ServiceError) -> int:
    """The status answering ``exc`` (by its class or nearest base; 400 for other refusals)."""
    return next((SERVICE_STATUS[c] for c in type(exc).__mro__ if c in SERVICE_STATUS), 400)


async def service_error_handler(_: Request, exc: Exception) -> JSONResponse:
    """A service's refusal as ``{"detail": ...}`` with its status, like an HTTPException."""
    assert isinstance(exc, ServiceError)
    return JSONResponse({"detail": exc.detail}, status_code=http_status(exc))


def handle_service_errors(app: FastAPI) -> None:
    """Answer the service layer's refusals on every route."""
    app.add_exception_handler(ServiceError, service_error_handler)
