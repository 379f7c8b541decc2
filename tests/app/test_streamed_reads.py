"""Large telemetry reads are streamed in chunks (CSV, JSON, Arrow, Parquet): the same bytes/rows as a whole read,
in the same order, across many files, several sensors and overlapping uploads; whole reads keep the row cap."""

from __future__ import annotations

import io
import json
from dataclasses import replace

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.services import downloads
from processing.time import timescales
from tests.app.helpers import SQLITE_ONLY, make_spacecraft
from tests.app.test_jobs_api import upload_columns
from tests.conftest import ADMIN_TOKEN

pytestmark = SQLITE_ONLY  # the chunking reads the catalog's file list, the same on both backends

DAY_NS = 86_400 * 10**9
START = int(timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])


def _client(settings) -> TestClient:  # noqa: ANN001
    c = TestClient(create_app(settings))
    c.headers["Authorization"] = f"Bearer {ADMIN_TOKEN}"
    return c


@pytest.fixture
def stored(settings):  # noqa: ANN001, ANN201
    """Three days of two gyro sensors in several uploads, one of them interleaved in time with another."""
    with _client(settings) as c:
        make_spacecraft(c)
        rng = np.random.default_rng(3)
        for day in range(3):
            for sensor in ("g1", "g2"):
                t = START + day * DAY_NS + np.arange(0, 400, dtype=np.int64) * 10**9 * 60
                cols = {"time_tai_ns": t, "wx": rng.normal(size=t.size), "wy": rng.normal(size=t.size),
                        "wz": rng.normal(size=t.size), "sensor": np.full(t.size, sensor, dtype=object)}
                upload_columns(c, "sat1", "gyro", cols)
        # a later upload interleaved in time with day 1 of g1: files that overlap, read in the right order
        t = START + DAY_NS + np.arange(100, 200, dtype=np.int64) * 10**9 * 60 + 30 * 10**9
        upload_columns(c, "sat1", "gyro", {"time_tai_ns": t, "wx": np.zeros(t.size), "wy": np.zeros(t.size),
                                           "wz": np.zeros(t.size), "sensor": np.full(t.size, "g1", dtype=object)})
    return settings


def _get(settings, **params) -> bytes:  # noqa: ANN001
    with _client(settings) as c:
        r = c.get("/api/v1/spacecraft/sat1/telemetry/gyro", params=params)
        assert r.status_code == 200, r.text
        return r.content


@pytest.mark.parametrize("fmt", ["csv", "json", "arrow", "parquet"])
def test_streamed_read_equals_the_whole_read(stored, fmt, monkeypatch):  # noqa: ANN001
    whole = _get(stored, format=fmt)
    monkeypatch.setattr(downloads, "TEXT_PIECE_ROWS", 37)  # CSV/JSON chunks encoded in pieces
    streamed = _get(replace(stored, stream_read_rows=150), format=fmt)  # chunks of a file or so
    if fmt == "arrow":
        a = pa.ipc.open_stream(io.BytesIO(whole)).read_all()
        b = pa.ipc.open_stream(io.BytesIO(streamed)).read_all()
        assert a.num_rows == 2500 and a.equals(b)
    elif fmt == "parquet":  # one row group per chunk, the same rows and types
        a, f = pq.read_table(io.BytesIO(whole)), pq.ParquetFile(io.BytesIO(streamed))
        assert f.metadata.num_row_groups > 5 and a.num_rows == 2500 and a.equals(f.read())
    else:
        assert streamed == whole
    if fmt == "json":
        rows = json.loads(streamed)
        assert len(rows) == 2500 and [r["sensor"] for r in rows[:1]] == ["g1"] and rows[-1]["sensor"] == "g2"


def test_streamed_window_and_sensor_and_the_whole_read_cap(stored):  # noqa: ANN001
    window = {"start": str((START + DAY_NS // 2) / 1e9), "end": str((START + 2 * DAY_NS + 3600 * 10**9) / 1e9),
              "time_scale": "tai", "sensor": "g2", "format": "csv"}
    small = replace(stored, stream_read_rows=100, max_read_rows=500)
    assert _get(small, **window) == _get(stored, **window)
    with _client(small) as c:  # streamed: the cap of whole reads does not apply
        assert c.get("/api/v1/spacecraft/sat1/telemetry/gyro", params={"format": "parquet"}).status_code == 200
    with _client(replace(stored, max_read_rows=500)) as c:  # read whole: the cap answers 413 before reading
        r = c.get("/api/v1/spacecraft/sat1/telemetry/gyro", params={"format": "parquet"})
        assert r.status_code == 413 and "ATTITUDE_MAX_READ_ROWS" in r.json()["detail"]
