"""Small builders shared by the API tests."""

from __future__ import annotations

import io
import time
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from fastapi.testclient import TestClient

SQLITE_ONLY = pytest.mark.sqlite_only
"""For tests whose subject does not touch what differs between catalog backends (numerics, formats, pages):
PostgreSQL runs the storage, ingest, job-claiming, access, schedule and crash tests (tests/conftest.py)."""

CSV = {"Content-Type": "text/csv"}
PARQUET = {"Content-Type": "application/vnd.apache.parquet"}
ARROW = {"Content-Type": "application/vnd.apache.arrow.stream"}

CONFIG = {
    "star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]}},
    "gyro": {"q_BG": [1, 0, 0, 0]},
    "solar_panels": [{"normal_B": [1, 0, 0], "max_current_a": 1.2},
                     {"normal_B": [0, 1, 0], "max_current_a": 1.2}],
}


def make_spacecraft(client: TestClient, name: str = "sat1", config: dict | None = None) -> None:
    r = client.post("/api/v1/spacecraft", json={"name": name, "config": CONFIG if config is None else config})
    assert r.status_code == 201, r.text


def parquet_bytes(table: pa.Table) -> bytes:
    buf = io.BytesIO()
    pq.write_table(table, buf)
    return buf.getvalue()


def arrow_bytes(table: pa.Table) -> bytes:
    sink = io.BytesIO()
    with pa.ipc.new_stream(sink, table.schema) as writer:
        writer.write_table(table)
    return sink.getvalue()


def upload(client: TestClient, stream: str, body: bytes | str, headers: dict | None = None,
           sc: str = "sat1", **params: object):
    return client.post(f"/api/v1/spacecraft/{sc}/telemetry/{stream}", content=body,
                       headers=headers or CSV, params=params)


def stored_files(settings) -> list:
    root = settings.telemetry_dir
    return sorted(p for p in root.rglob("*.parquet")) if root.exists() else []


def assert_json_plain(value: Any, path: str = "summary") -> None:
    """Only dict/list/str/int/float/bool/None, finite floats (no numpy scalars)."""
    if isinstance(value, dict):
        for k, v in value.items():
            assert isinstance(k, str), path
            assert_json_plain(v, f"{path}.{k}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            assert_json_plain(v, f"{path}[{i}]")
    elif isinstance(value, float):
        assert np.isfinite(value), path
    else:
        assert value is None or type(value) in (str, int, bool), f"{path}: {type(value)}"


def run_coverage_jobs(client: TestClient, spacecraft: Iterable[str], timeout_s: float = 60.0) -> dict[str, str]:
    """A telemetry_coverage job per spacecraft, waited for until it succeeded: {spacecraft: job id}."""
    jobs = {sc: client.post("/api/v1/jobs", json={"type": "telemetry_coverage", "spacecraft": sc}).json()["id"]
            for sc in spacecraft}
    deadline = time.monotonic() + timeout_s
    while any(client.get(f"/api/v1/jobs/{j}").json()["status"] != "succeeded" for j in jobs.values()):
        assert time.monotonic() < deadline, "coverage jobs did not succeed in time"
        time.sleep(0.05)
    return jobs


def issue_keys(client: TestClient, revoked_role: str = "admin") -> tuple[dict[str, str], Callable[..., dict]]:
    """Secrets of keys of every role, of viewer/operator keys granted only spacecraft "A" (``viewer_A``,
    ``operator_A``) and of a revoked ``revoked_role`` key (``revoked``); and the function that made them."""

    def key(role: str, **extra: Any) -> dict:
        r = client.post("/api/v1/keys", json={"name": f"{role}-{len(extra)}", "role": role, **extra})
        assert r.status_code == 201, r.text
        return r.json()

    keys = {role: key(role)["secret"] for role in ("viewer", "operator", "admin")}
    keys["viewer_A"] = key("viewer", spacecraft=["A"])["secret"]
    keys["operator_A"] = key("operator", spacecraft=["A"])["secret"]
    revoked = key(revoked_role)
    client.delete(f"/api/v1/keys/{revoked['id']}")
    keys["revoked"] = revoked["secret"]
    return keys, key
