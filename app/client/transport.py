"""The thin HTTP layer of the client (:class:`ApiClient`, standard library only; demo and benchmarks use it
directly): requests with the API key, errors as :class:`app.client.errors.ApiError`, streamed file uploads,
job submission and polling."""

from __future__ import annotations

import http.client
import io
import json
import os
import time
import urllib.parse
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from app.client.errors import ServiceUnreachable, api_error

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
