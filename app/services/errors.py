"""What a service refuses: the API answers these with 4xx (app/api/errors.py), the UI with error pages.

``detail`` says what was expected and what came: a string, or ``{"message": ..., "errors": [...]}``
with one ``{"row", "column", "message"}`` item per invalid field.
"""

from __future__ import annotations

from typing import Any


class ServiceError(Exception):
    """Base of the refusals of app/services."""

    def __init__(self, detail: Any) -> None:
        super().__init__(detail)
        self.detail = detail


class NotFound(ServiceError):
    """The thing does not exist, or the caller's key may not see it (so keys cannot probe)."""


class Conflict(ServiceError):
    """The request contradicts the stored state (a name taken, a job already finished)."""


class Invalid(ServiceError):
    """An argument is not acceptable (time, window, parameters, reference, cursor, ...)."""


class TooLarge(ServiceError):
    """More than a configured limit (bytes, rows)."""


class Unsupported(ServiceError):
    """A media type or encoding the service does not read."""


class Gone(ServiceError):
    """Recorded in the catalog but missing from the store."""


class Forbidden(ServiceError):
    """The caller's key may not do this, whatever the object (HTTP 403)."""


class Busy(ServiceError):
    """The caller has too much in progress (queued jobs): retry later (HTTP 429)."""
