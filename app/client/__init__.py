"""Python client of the service: ``from app.client import Client`` (for notebooks and scripts).

``Client`` covers spacecraft and their configuration, telemetry upload (a pandas DataFrame, an Arrow
table or a file) and read-back as a DataFrame (``time`` as ``datetime64[ns, UTC]`` beside the exact
``time_tai_ns``), jobs (submit, wait with a progress bar - tqdm when installed -, cancel, results,
headline, warnings, tables as DataFrames, reports and artifacts to files) and reference data. Ids may
be given as unique prefixes (the 8 characters the CLI and UI show). Errors are :class:`ApiError`
subclasses by status (:class:`NotFound`, :class:`ValidationFailed`, ...) carrying ``detail`` and the
API's ``errors`` (row, column, message); an unreachable service is :class:`ServiceUnreachable`, naming
the URL. ``ApiClient`` is the thin HTTP layer underneath (standard library only; demo, benchmarks).

Layout: app/client/errors.py (the errors), transport.py (``ApiClient``), ids.py (listings, short ids),
telemetry.py (spacecraft, telemetry, reference data), jobs.py (jobs, schedules); every name is importable
from ``app.client``.
"""

from __future__ import annotations

import os

from app.client.errors import (
    ERRORS,
    AmbiguousId,
    ApiError,
    BadRequest,
    Conflict,
    ErrorRow,
    Forbidden,
    Gone,
    NotFound,
    RateLimited,
    ServerError,
    ServiceUnreachable,
    TooLarge,
    Unauthorized,
    UnsupportedMediaType,
    ValidationFailed,
    api_error,
)
from app.client.ids import HEX_ID, SHORT_ID_MIN, ClientBase
from app.client.jobs import JobsClient
from app.client.telemetry import TelemetryClient, to_arrow
from app.client.transport import (
    ARROW_TYPE,
    CHUNK_BYTES,
    FINAL,
    PARQUET_TYPE,
    UPLOAD_TYPES,
    ApiClient,
)

__all__ = [
    "ARROW_TYPE",
    "AmbiguousId",
    "ApiClient",
    "ApiError",
    "BadRequest",
    "CHUNK_BYTES",
    "Client",
    "ClientBase",
    "Conflict",
    "ERRORS",
    "ErrorRow",
    "FINAL",
    "Forbidden",
    "Gone",
    "HEX_ID",
    "JobsClient",
    "NotFound",
    "PARQUET_TYPE",
    "RateLimited",
    "SHORT_ID_MIN",
    "ServerError",
    "ServiceUnreachable",
    "TelemetryClient",
    "TooLarge",
    "UPLOAD_TYPES",
    "Unauthorized",
    "UnsupportedMediaType",
    "ValidationFailed",
    "api_error",
    "to_arrow",
]


class Client(TelemetryClient, JobsClient):
    """The service from Python. ``Client()`` reads ``ATTITUDE_URL`` and ``ATTITUDE_TOKEN``.

    Example::

        c = Client("http://127.0.0.1:8000", token)
        c.create_spacecraft("sat1", {"star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]}}})
        c.upload("sat1", "gyro", frame)                      # time: datetime64[ns, UTC] or time_tai_ns
        gyro = c.telemetry("sat1", "gyro", start="2023-06-01T00:00:00Z")
        job = c.run("gyro_noise", "sat1")                    # submit and wait (progress bar)
        c.headline(job["id"]); c.tables(job["id"])["allan"]; c.report(job["id"], "report.html")
    """

    def __init__(self, url: str | None = None, token: str | None = None, timeout_s: float = 600.0) -> None:
        url = url or os.environ.get("ATTITUDE_URL") or "http://127.0.0.1:8000"
        token = token if token is not None else os.environ.get("ATTITUDE_TOKEN", "")
        if not token:
            raise ValueError("an API key is needed: token= or ATTITUDE_TOKEN")
        super().__init__(url, token, timeout_s=timeout_s)
