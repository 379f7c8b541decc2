"""The client's errors: :class:`ApiError` and its subclasses by HTTP status (with the API's row/column
``errors``), :class:`ServiceUnreachable` (naming the URL) and :class:`AmbiguousId` (a short id matching several)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class ErrorRow:
    """One problem the service named: ``row`` (0-based data record, or None), ``column``, ``message``."""

    row: int | None
    column: str | None
    message: str

    def __str__(self) -> str:
        where = ", ".join(x for x in (f"row {self.row}" if self.row is not None else "",
                                      f"column {self.column}" if self.column else "") if x)
        return f"{where}: {self.message}" if where else self.message


class ApiError(RuntimeError):
    """An answer of the service outside 2xx. ``status``, ``body`` (parsed JSON or bytes), ``detail``
    (what went wrong), ``errors`` (row/column/message items: upload or request validation errors, and
    upload ``conflicts``), ``error_count`` (all of them; ``errors`` lists up to 100), ``url``."""

    def __init__(self, status: int, body: Any, url: str = "", method: str = "",
                 headers: Mapping[str, str] | None = None) -> None:
        self.status = status
        self.headers = dict(headers or {})
        self.body = body
        self.url = url
        self.method = method
        data = body if isinstance(body, dict) else {}
        detail = data.get("detail", body)
        if isinstance(detail, bytes):
            detail = detail.decode(errors="replace")
        self.detail: Any = detail
        items = (data.get("errors") or []) + (data.get("conflicts") or [])
        self.errors = [ErrorRow(e.get("row"), e.get("column"), str(e.get("message", e)))
                       if isinstance(e, dict) else ErrorRow(None, None, str(e)) for e in items]
        self.error_count = int(data.get("error_count") or data.get("conflict_count") or len(self.errors))
        super().__init__(f"HTTP {status}: {body}")

    def describe(self) -> str:
        """Every line a person needs: the status and detail, then each error row."""
        detail = self.detail if isinstance(self.detail, str) else json.dumps(self.detail)
        lines = [f"the service answered {self.status}: {detail}"]
        lines += [f"  {e}" for e in self.errors]
        if self.error_count > len(self.errors):
            lines.append(f"  ... and {self.error_count - len(self.errors)} more")
        return "\n".join(lines)


class BadRequest(ApiError):
    """400"""


class Unauthorized(ApiError):
    """401: no, an invalid, expired or revoked API key"""


class Forbidden(ApiError):
    """403: the key's role is too low"""


class NotFound(ApiError):
    """404 (also for spacecraft the key may not see)"""


class Conflict(ApiError):
    """409: e.g. rows that differ from stored samples (``errors`` lists them), a name taken"""


class Gone(ApiError):
    """410"""


class TooLarge(ApiError):
    """413: body or row limit"""


class UnsupportedMediaType(ApiError):
    """415"""


class ValidationFailed(ApiError):
    """422: invalid request or upload rows (``errors``: row, column, message); nothing stored"""


class RateLimited(ApiError):
    """429 (``retry_after_s``)"""

    @property
    def retry_after_s(self) -> float | None:
        value = self.headers.get("retry-after")
        return float(value) if value else None


class ServerError(ApiError):
    """5xx"""


ERRORS: dict[int, type[ApiError]] = {400: BadRequest, 401: Unauthorized, 403: Forbidden, 404: NotFound, 409: Conflict,
                                     410: Gone, 413: TooLarge, 415: UnsupportedMediaType, 422: ValidationFailed,
                                     429: RateLimited}


def api_error(status: int, body: Any, url: str = "", method: str = "",
              headers: Mapping[str, str] | None = None) -> ApiError:
    """The ApiError subclass of ``status``."""
    cls = ERRORS.get(status, ServerError if status >= 500 else ApiError)
    return cls(status, body, url, method, headers)


class ServiceUnreachable(ConnectionError):
    """The service did not answer (refused, timed out, name not resolved); the message names the URL."""

    def __init__(self, url: str, reason: BaseException) -> None:
        self.url = url
        super().__init__(f"cannot reach the service at {url}: {reason}")


class AmbiguousId(ValueError):
    """A short id that more than one object starts with (``candidates`` lists them)."""

    def __init__(self, what: str, prefix: str, candidates: list[str]) -> None:
        self.candidates = candidates
        shown = ", ".join(candidates[:10]) + (" ..." if len(candidates) > 10 else "")
        super().__init__(f"{what} id {prefix!r} is ambiguous: {len(candidates)} match ({shown}); give more characters")
