"""Python client of the service: ``from app.client import Client`` (for notebooks and scripts).

``Client`` covers spacecraft and their configuration, telemetry upload (a pandas DataFrame, an Arrow
table or a file) and read-back as a DataFrame (``time`` as ``datetime64[ns, UTC]`` beside the exact
``time_tai_ns``), jobs (submit, wait with a progress bar - tqdm when installed -, cancel, results,
headline, warnings, tables as DataFrames, reports and artifacts to files) and reference data. Ids may
be given as unique prefixes (the 8 characters the CLI and UI show). Errors are :class:`ApiError`
subclasses by status (:class:`NotFound`, :class:`ValidationFailed`, ...) carrying ``detail`` and the
API's ``errors`` (row, column, message); an unreachable service is :class:`ServiceUnreachable`, naming
the URL. ``ApiClient`` is the thin HTTP layer underneath (standard library only; demo, benchmarks).
"""

from __future__ import annotations

import http.client
import io
import json
import os
import re
import time
import urllib.parse
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

if TYPE_CHECKING:
    import pandas as pd


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


FINAL = ("succeeded", "failed", "cancelled")
PARQUET_TYPE = "application/vnd.apache.parquet"
ARROW_TYPE = "application/vnd.apache.arrow.stream"
UPLOAD_TYPES = {".csv": "text/csv", ".parquet": PARQUET_TYPE, ".pq": PARQUET_TYPE, ".arrow": ARROW_TYPE,
                ".arrows": ARROW_TYPE, ".json": "application/json"}
CHUNK_BYTES = 1 << 20


class ApiClient:
    def __init__(self, base_url: str, token: str, timeout_s: float = 600.0) -> None:
        self.base_url = base_url.rstrip("/")
        url = urllib.parse.urlsplit(base_url)
        self.https = url.scheme == "https"
        self.host = url.hostname or "127.0.0.1"
        self.port = url.port or (443 if self.https else 80)
        self.prefix = url.path.rstrip("/")
        self.token = token
        self.timeout_s = timeout_s

    def _connection(self) -> http.client.HTTPConnection:
        if self.https:
            return http.client.HTTPSConnection(self.host, self.port, timeout=self.timeout_s)
        return http.client.HTTPConnection(self.host, self.port, timeout=self.timeout_s)

    def request(self, method: str, path: str, *, json_body: Any = None, body: bytes | Iterator[bytes] | None = None,
                content_type: str | None = None, params: Mapping[str, Any] | None = None,
                expect: tuple[int, ...] = (200, 201, 202), content_length: int | None = None,
                ) -> tuple[int, Any, dict[str, str]]:
        headers = {"Authorization": f"Bearer {self.token}"}
        if json_body is not None:
            body = json.dumps(json_body).encode()
            content_type = "application/json"
        if content_type:
            headers["Content-Type"] = content_type
        if content_length is not None:  # a streamed body (an iterator of chunks)
            headers["Content-Length"] = str(content_length)
        path = self.prefix + path
        if params:
            path = f"{path}?{urllib.parse.urlencode({k: v for k, v in params.items() if v is not None})}"
        conn = self._connection()
        try:
            try:
                conn.request(method, path, body=body, headers=headers)
                resp = conn.getresponse()
                raw = resp.read()
            except (OSError, http.client.HTTPException) as exc:
                raise ServiceUnreachable(self.base_url, exc) from exc
            resp_headers = {k.lower(): v for k, v in resp.getheaders()}
        finally:
            conn.close()
        ctype = resp_headers.get("content-type", "")
        data: Any = json.loads(raw) if ctype.startswith("application/json") and raw else raw
        if resp.status not in expect:
            raise api_error(resp.status, data, f"{self.base_url}{path[len(self.prefix):]}", method, resp_headers)
        return resp.status, data, resp_headers

    def get(self, path: str, **kw: Any) -> Any:
        return self.request("GET", path, **kw)[1]

    def post(self, path: str, json_body: Any = None, **kw: Any) -> Any:
        return self.request("POST", path, json_body=json_body, **kw)[1]

    def upload_columns(self, spacecraft: str, stream: str, columns: Mapping[str, Any], **params: Any) -> Any:
        """Upload canonical columns (``time_tai_ns`` + stream columns) exactly, as Parquet on the TAI scale."""
        cols = dict(columns)
        t = np.asarray(cols.pop("time_tai_ns"), dtype=np.int64)
        table = pa.table({"time": pa.array(t, pa.timestamp("ns")), **{k: np.asarray(v) for k, v in cols.items()}})
        buf = io.BytesIO()
        pq.write_table(table, buf)
        return self.post(f"/api/v1/spacecraft/{spacecraft}/telemetry/{stream}", body=buf.getvalue(),
                         content_type="application/vnd.apache.parquet", params={"time_scale": "tai", **params})

    def wait_for_job(self, job_id: str, timeout_s: float = 600.0, poll_s: float = 0.2,
                     on_progress: Any = None) -> dict[str, Any]:
        deadline = time.monotonic() + timeout_s
        while True:
            job: dict[str, Any] = self.get(f"/api/v1/jobs/{job_id}")
            if on_progress:
                on_progress(job)
            if job["status"] in FINAL:
                return job
            if time.monotonic() > deadline:
                raise TimeoutError(f"job {job_id} still {job['status']} after {timeout_s} s")
            time.sleep(poll_s)

    def delete(self, path: str, **kw: Any) -> Any:
        return self.request("DELETE", path, expect=(200, 204), **kw)[1]

    def upload_file(self, spacecraft: str, stream: str, path: str | os.PathLike[str], *,
                    content_type: str | None = None,
                    on_progress: Callable[[int, int], None] | None = None, **params: Any) -> Any:
        """Stream a telemetry file (CSV, Parquet, Arrow IPC stream, JSON) in 1 MiB chunks.

        The media type follows the file extension unless given; ``on_progress(sent, total)`` is called
        after every chunk; other keyword arguments are upload query parameters (time_scale, sensor, ...).
        """
        path = Path(path)
        ctype = content_type or UPLOAD_TYPES.get(path.suffix.lower())
        if ctype is None:
            raise ValueError(f"cannot tell the format of {path.name!r} from its extension; give content_type "
                             f"({', '.join(sorted(set(UPLOAD_TYPES.values())))})")
        total = os.path.getsize(path)

        def chunks() -> Iterator[bytes]:
            sent = 0
            with open(path, "rb") as fh:
                while chunk := fh.read(CHUNK_BYTES):
                    sent += len(chunk)
                    yield chunk
                    if on_progress:
                        on_progress(sent, total)

        params.setdefault("filename", path.name)
        return self.request("POST", f"/api/v1/spacecraft/{spacecraft}/telemetry/{stream}", body=chunks(),
                            content_type=ctype, params=params, content_length=total)[1]

    def submit_job(self, job_type: str, spacecraft: str, *, start: str | float | None = None,
                   end: str | float | None = None, time_scale: str = "utc", params: Mapping[str, Any] | None = None,
                   reference: Mapping[str, str] | None = None) -> dict[str, Any]:
        body: dict[str, Any] = {"type": job_type, "spacecraft": spacecraft, "time_scale": time_scale,
                                "params": dict(params or {}), "reference": dict(reference or {})}
        if start is not None:
            body["start"] = start
        if end is not None:
            body["end"] = end
        accepted: dict[str, Any] = self.post("/api/v1/jobs", body)
        return accepted

    def list_jobs(self, **filters: Any) -> list[dict[str, Any]]:
        jobs: list[dict[str, Any]] = self.get("/api/v1/jobs", params=filters)
        return jobs

    def create_schedule(self, body: Mapping[str, Any]) -> dict[str, Any]:
        created: dict[str, Any] = self.post("/api/v1/schedules", dict(body))
        return created

    def list_schedules(self) -> list[dict[str, Any]]:
        schedules: list[dict[str, Any]] = self.get("/api/v1/schedules")
        return schedules


# -- the notebook client ----------------------------------------------------------------------------
HEX_ID = re.compile(r"^[0-9a-f]{32}$")
SHORT_ID_MIN = 4  # shorter prefixes are refused (too many candidates to be useful)


def _progress_bar(total: float, desc: str) -> Any:
    """A tqdm bar when tqdm is installed (notebooks get the widget), else None."""
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None
    return tqdm(total=total, desc=desc, unit="%", bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} % {postfix}")


def to_arrow(data: Any) -> pa.Table:
    """A pandas DataFrame (a DatetimeIndex becomes the ``time`` column) or an Arrow table, as an Arrow table."""
    if isinstance(data, pa.Table):
        return data
    import pandas as pd

    if isinstance(data, pd.DataFrame):
        frame = data
        if isinstance(frame.index, pd.DatetimeIndex):
            frame = frame.rename_axis(frame.index.name or "time").reset_index()
        return pa.Table.from_pandas(frame, preserve_index=False)
    raise TypeError(f"expected a pandas DataFrame, a pyarrow Table or a file path, got {type(data).__name__}")


class Client(ApiClient):
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

    # -- listings and short ids ---------------------------------------------------------------------
    def pages(self, path: str, **params: Any) -> Iterator[dict[str, Any]]:
        """Every item of a paginated listing (following ``X-Next-Cursor``)."""
        query: dict[str, Any] = {"limit": 500, **params}
        while True:
            _, items, headers = self.request("GET", path, params=query)
            yield from items
            cursor = headers.get("x-next-cursor")
            if not cursor:
                return
            query["cursor"] = cursor

    def _resolve(self, what: str, prefix: str, ids: Callable[[], Iterator[str]]) -> str:
        prefix = prefix.strip().lower()
        if HEX_ID.match(prefix):
            return prefix
        if len(prefix) < SHORT_ID_MIN or not re.fullmatch(r"[0-9a-f]+", prefix):
            raise ValueError(f"{what} id {prefix!r}: expected the full id or at least {SHORT_ID_MIN} of its first "
                             "hexadecimal characters")
        found = sorted({i for i in ids() if i.startswith(prefix)})
        if not found:
            raise api_error(404, {"detail": f"no {what} id starts with {prefix!r}"})
        if len(found) > 1:
            raise AmbiguousId(what, prefix, found)
        return found[0]

    def resolve_job(self, job_id: str) -> str:
        """The full id of a job given by a unique prefix (or its full id)."""
        return self._resolve("job", job_id, lambda: (j["id"] for j in self.pages("/api/v1/jobs")))

    def resolve_ingest(self, spacecraft: str, ingest_id: str) -> str:
        return self._resolve("ingest", ingest_id, lambda: (
            i["ingest_id"] for i in self.pages(f"/api/v1/spacecraft/{_q(spacecraft)}/ingests")))

    def resolve_reference(self, kind: str, dataset_id: str) -> str:
        return self._resolve("reference data set", dataset_id, lambda: (
            d["id"] for d in self.pages("/api/v1/reference", kind=kind)))

    def resolve_schedule(self, name_or_id: str) -> str:
        """A schedule's name or id as the service takes it: a name or full id as given, else a unique id prefix."""
        items = self.list_schedules()
        if any(name_or_id in (s["name"], s["id"]) for s in items):
            return name_or_id
        if not re.fullmatch(r"[0-9a-fA-F]{4,31}", name_or_id):
            return name_or_id  # the service answers 404 (the CLI adds the nearest name)
        return self._resolve("schedule", name_or_id, lambda: (s["id"] for s in items))

    # -- spacecraft ----------------------------------------------------------------------------------
    def spacecraft(self) -> list[dict[str, Any]]:
        """Every spacecraft the key may see, with its latest configuration."""
        out: list[dict[str, Any]] = self.get("/api/v1/spacecraft")
        return out

    def spacecraft_info(self, name: str, version: int | None = None) -> dict[str, Any]:
        out: dict[str, Any] = self.get(f"/api/v1/spacecraft/{_q(name)}", params={"version": version})
        return out

    def create_spacecraft(self, name: str, config: Mapping[str, Any] | None = None) -> dict[str, Any]:
        out: dict[str, Any] = self.post("/api/v1/spacecraft", {"name": name, "config": dict(config or {})})
        return out

    def config(self, name: str, version: int | None = None) -> dict[str, Any]:
        """The configuration (latest, or ``version``) as a dict."""
        config: dict[str, Any] = self.spacecraft_info(name, version)["config"]
        return config

    def set_config(self, name: str, config: Mapping[str, Any]) -> dict[str, Any]:
        """Store a new configuration version; returns the spacecraft with ``config_version``."""
        out: dict[str, Any] = self.request("PUT", f"/api/v1/spacecraft/{_q(name)}/config", json_body=dict(config))[1]
        return out

    def calibrations(self, name: str, kind: str | None = None) -> list[dict[str, Any]]:
        out: list[dict[str, Any]] = self.get(f"/api/v1/spacecraft/{_q(name)}/calibrations", params={"kind": kind})
        return out

    # -- telemetry -----------------------------------------------------------------------------------
    def upload(self, spacecraft: str, stream: str, data: Any, *, time_scale: str = "utc", sensor: str | None = None,
               quaternion_direction: str | None = None, filename: str | None = None,
               format: str | None = None) -> dict[str, Any]:
        """Upload a DataFrame, an Arrow table or a file (path) to ``stream``; returns the ingest record.

        Times: a ``time`` column (timestamps; tz-aware ones are UTC and need ``time_scale="utc"``; ISO
        strings; seconds since 1970 on ``time_scale``) and/or ``time_tai_ns`` (exact, integer TAI ns).
        All or nothing: a :class:`ValidationFailed` lists every bad row and column.
        """
        params: dict[str, Any] = {"time_scale": time_scale, "sensor": sensor,
                                  "quaternion_direction": quaternion_direction, "format": format}
        if isinstance(data, (str, os.PathLike)):
            out: dict[str, Any] = self.upload_file(spacecraft, stream, data, filename=filename, **params)
            return out
        buf = io.BytesIO()
        pq.write_table(to_arrow(data), buf)
        params["filename"] = filename
        out = self.post(f"/api/v1/spacecraft/{_q(spacecraft)}/telemetry/{_q(stream)}", body=buf.getvalue(),
                        content_type=PARQUET_TYPE, params=params)
        return out

    def telemetry_table(self, spacecraft: str, stream: str, start: str | float | None = None,
                        end: str | float | None = None, *, sensor: str | None = None,
                        time_scale: str = "utc") -> pa.Table:
        """Stored samples in [start, end] as an Arrow table: ``time`` (timestamp ns; UTC tz-aware on the UTC
        scale, naive readings on tai/gps/tt), ``time_tai_ns`` (exact), ``sensor`` and the stream's columns."""
        raw = self.get(f"/api/v1/spacecraft/{_q(spacecraft)}/telemetry/{_q(stream)}", params={
            "start": start, "end": end, "sensor": sensor, "time_scale": time_scale, "format": "parquet"})
        return pq.read_table(io.BytesIO(raw))

    def telemetry(self, spacecraft: str, stream: str, start: str | float | None = None,
                  end: str | float | None = None, *, sensor: str | None = None,
                  time_scale: str = "utc") -> pd.DataFrame:
        """Stored samples as a DataFrame (``time`` is ``datetime64[ns, UTC]`` on the UTC scale)."""
        return self.telemetry_table(spacecraft, stream, start, end, sensor=sensor, time_scale=time_scale).to_pandas()

    def ingests(self, spacecraft: str, stream: str | None = None) -> list[dict[str, Any]]:
        return list(self.pages(f"/api/v1/spacecraft/{_q(spacecraft)}/ingests", stream=stream))

    def retract(self, spacecraft: str, ingest_id: str, reason: str) -> dict[str, Any]:
        full = self.resolve_ingest(spacecraft, ingest_id)
        out: dict[str, Any] = self.delete(f"/api/v1/spacecraft/{_q(spacecraft)}/ingests/{full}",
                                          params={"reason": reason})
        return out

    # -- jobs ----------------------------------------------------------------------------------------
    def job_types(self) -> list[dict[str, Any]]:
        out: list[dict[str, Any]] = self.get("/api/v1/jobs/types")
        return out

    def submit(self, job_type: str, spacecraft: str, *, start: str | float | None = None,
               end: str | float | None = None, time_scale: str = "utc", params: Mapping[str, Any] | None = None,
               reference: Mapping[str, str] | None = None, calibration: str | None = None,
               screened: bool | None = None) -> dict[str, Any]:
        """Submit a job; returns ``{id, status, status_url}`` (202). Bad parameters: :class:`ValidationFailed`."""
        body: dict[str, Any] = {"type": job_type, "spacecraft": spacecraft, "time_scale": time_scale,
                                "params": dict(params or {}), "reference": dict(reference or {})}
        for key, value in (("start", start), ("end", end), ("calibration", calibration), ("screened", screened)):
            if value is not None:
                body[key] = value
        out: dict[str, Any] = self.post("/api/v1/jobs", body)
        return out

    def job(self, job_id: str) -> dict[str, Any]:
        out: dict[str, Any] = self.get(f"/api/v1/jobs/{self.resolve_job(job_id)}")
        return out

    def jobs(self, *, spacecraft: str | None = None, type: str | None = None, status: str | None = None,
             limit: int | None = None) -> list[dict[str, Any]]:
        """Jobs, newest first (all pages, or the first ``limit``)."""
        filters = {"spacecraft": spacecraft, "type": type, "status": status}
        if limit is not None:
            return self.list_jobs(**filters, limit=limit)
        return list(self.pages("/api/v1/jobs", **filters))

    def wait(self, job_id: str, *, timeout_s: float = 3600.0, poll_s: float = 0.5,
             progress: bool = True) -> dict[str, Any]:
        """Poll a job until it ends; a tqdm progress bar when tqdm is installed and ``progress``."""
        full = self.resolve_job(job_id)
        bar = _progress_bar(100, f"job {full[:8]}") if progress else None
        try:
            def show(job: dict[str, Any]) -> None:
                if bar is not None:
                    bar.n = round(job["progress"] * 100, 1)
                    bar.set_postfix_str(f"{job['status']}: {job['stage']}", refresh=False)
                    bar.refresh()

            return self.wait_for_job(full, timeout_s=timeout_s, poll_s=poll_s, on_progress=show)
        finally:
            if bar is not None:
                bar.close()

    def run(self, job_type: str, spacecraft: str, *, timeout_s: float = 3600.0, progress: bool = True,
            **submit: Any) -> dict[str, Any]:
        """Submit and wait; returns the finished job (``status`` succeeded, failed or cancelled)."""
        return self.wait(self.submit(job_type, spacecraft, **submit)["id"], timeout_s=timeout_s, progress=progress)

    def cancel(self, job_id: str) -> dict[str, Any]:
        out: dict[str, Any] = self.post(f"/api/v1/jobs/{self.resolve_job(job_id)}/cancel")
        return out

    def result(self, job_id: str) -> dict[str, Any] | None:
        """The job's summary (units in the key names; ``warnings`` inside), None before it succeeded."""
        summary: dict[str, Any] | None = self.job(job_id)["result"]
        return summary

    def report_data(self, job_id: str) -> dict[str, Any]:
        """The report as a dict: warnings, headline (verdict, rows), job, window, inputs, ..."""
        out: dict[str, Any] = self.get(f"/api/v1/jobs/{self.resolve_job(job_id)}/report", params={"format": "json"})
        return out

    def headline(self, job_id: str) -> pd.DataFrame:
        """The report's headline rows (quantity, component, value, sigma, unit, frame, verdict) as a DataFrame."""
        import pandas as pd

        rows = self.report_data(job_id)["headline"]["rows"]
        columns = ["quantity", "component", "value", "sigma", "unit", "frame", "verdict", "key", "text"]
        return pd.DataFrame(rows, columns=columns if not rows else None)

    def warnings(self, job_id: str) -> list[dict[str, Any]]:
        """The job's warnings ``{code, message, evidence}``."""
        return list((self.result(job_id) or {}).get("warnings", []))

    def artifacts(self, job_id: str) -> list[dict[str, Any]]:
        out: list[dict[str, Any]] = self.get(f"/api/v1/jobs/{self.resolve_job(job_id)}/artifacts")
        return out

    def artifact_bytes(self, job_id: str, name: str) -> bytes:
        raw: bytes = self.get(f"/api/v1/jobs/{self.resolve_job(job_id)}/artifacts/{_q(name)}")
        return raw if isinstance(raw, bytes) else json.dumps(raw).encode()

    def table(self, job_id: str, name: str) -> pd.DataFrame:
        """One result table (its Parquet artifact) as a DataFrame; beside ``time_tai_ns`` its ``time`` (ISO text
        in the file) becomes ``datetime64[ns, UTC]`` (POSIX: a leap second holds at the next midnight)."""
        stem = name.removesuffix(".parquet")
        table = pq.read_table(io.BytesIO(self.artifact_bytes(job_id, f"{stem}.parquet")))
        if "time_tai_ns" in table.column_names and "time" in table.column_names \
                and not pa.types.is_timestamp(table.schema.field("time").type):
            from processing.time.timescales import tai_ns_to_epoch_ns

            utc = pa.array(tai_ns_to_epoch_ns(table.column("time_tai_ns").to_numpy(), "utc"), pa.timestamp("ns", "UTC"))
            table = table.set_column(table.column_names.index("time"), "time", utc)
        return table.to_pandas()

    def tables(self, job_id: str) -> dict[str, pd.DataFrame]:
        """Every result table of the job, by name, as DataFrames."""
        full = self.resolve_job(job_id)
        names = [a["name"] for a in self.artifacts(full) if a["kind"] == "table" and a["name"].endswith(".parquet")]
        return {n.removesuffix(".parquet"): self.table(full, n) for n in names}

    def download_artifact(self, job_id: str, name: str, path: str | Path | None = None) -> Path:
        """Save an artifact (to ``path``, a directory or file; default: the current directory)."""
        target = Path(path) if path is not None else Path(name)
        if target.is_dir():
            target = target / name
        target.write_bytes(self.artifact_bytes(job_id, name))
        return target

    def download_artifacts(self, job_id: str, directory: str | Path = ".", kind: str | None = None) -> list[Path]:
        """Save every artifact (or those of ``kind``: table, figure, file, summary) into ``directory``."""
        full = self.resolve_job(job_id)
        folder = Path(directory)
        folder.mkdir(parents=True, exist_ok=True)
        return [self.download_artifact(full, a["name"], folder / a["name"])
                for a in self.artifacts(full) if kind is None or a["kind"] == kind]

    def report(self, job_id: str, path: str | Path | None = None, format: str | None = None) -> Path:
        """Save the report (html, pdf or json; from ``path``'s extension unless given) and return its path."""
        full = self.resolve_job(job_id)
        fmt = format or (Path(path).suffix.lstrip(".").lower() if path is not None else "html") or "html"
        if fmt not in ("html", "pdf", "json"):
            raise ValueError(f"report format must be html, pdf or json, got {fmt!r}")
        target = Path(path) if path is not None else Path(f"report_{full[:8]}.{fmt}")
        raw = self.get(f"/api/v1/jobs/{full}/report", params={"format": fmt})
        target.write_bytes(raw if isinstance(raw, bytes) else json.dumps(raw, indent=2).encode())
        return target

    # -- reference data and schedules ------------------------------------------------------------------
    def reference_kinds(self) -> list[dict[str, Any]]:
        out: list[dict[str, Any]] = self.get("/api/v1/reference/kinds")
        return out

    def upload_reference(self, kind: str, path: str | Path, name: str | None = None) -> dict[str, Any]:
        """Upload a reference file (EOP, RINEX navigation, ...); parsed at once (422 with the reason)."""
        path = Path(path)
        out: dict[str, Any] = self.post(f"/api/v1/reference/{_q(kind)}", body=path.read_bytes(),
                                        content_type="application/octet-stream",
                                        params={"name": name, "filename": path.name})
        return out

    def reference(self, kind: str | None = None) -> list[dict[str, Any]]:
        return list(self.pages("/api/v1/reference", kind=kind))

    def schedules(self) -> list[dict[str, Any]]:
        return self.list_schedules()


def _q(part: str) -> str:
    """A path segment, quoted."""
    return urllib.parse.quote(str(part), safe="")
