"""The shape of error answers (4xx), declared in the OpenAPI schema of every route."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict


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
COMMON_ERRORS = error_responses(400, 401, 403, 404, 409, 413, 415, 422, 429, 500, 503, 507)
