"""A damaged telemetry file is named, quarantined and refused, the rest of the stream stays readable;
a full disk is a 507; every 5xx body is JSON. (Before: a plain-text 500 on every read and upload that
touched the file, and jobs failing with "Corrupt snappy compressed data".)"""

from __future__ import annotations

import errno
import time

import pyarrow.parquet as pq
import pytest
from sqlalchemy import select

from storage.db import make_engine, session_factory
from storage.models import TelemetryFile
from storage.parquet_store import ParquetStore
from storage.telemetry import quarantined_files, restore_file, retract_ingest
from tests.app.helpers import make_spacecraft, stored_files, upload

DAY1 = "time,wx,wy,wz\n" + "".join(f"2023-06-01T00:00:{i:02d}Z,1,2,3\n" for i in range(30))
DAY2 = "time,wx,wy,wz\n" + "".join(f"2023-06-02T00:00:{i:02d}Z,1,2,3\n" for i in range(30))
GYRO = "/api/v1/spacecraft/sat1/telemetry/gyro"


def _damage(settings, day: str) -> str:
    (path,) = [p for p in stored_files(settings) if f"day={day}" in str(p)]
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 3: len(raw) // 3 + 64] = b"\xff" * 64  # inside the column data
    path.write_bytes(bytes(raw))
    return str(path.relative_to(settings.telemetry_dir))


def test_damaged_file_is_named_quarantined_and_the_rest_readable(client, settings):
    make_spacecraft(client)
    assert upload(client, "gyro", DAY1).status_code == 201
    good = client.get(GYRO).content
    assert upload(client, "gyro", DAY2).status_code == 201
    rel = _damage(settings, "2023-06-02")

    r = client.get(GYRO, params={"format": "csv"})
    assert r.status_code == 503 and r.headers["content-type"].startswith("application/json")
    body = r.json()
    assert body["file"] == rel and body["stream"] == "gyro" and "quarantined" in body["detail"]
    r = client.get(GYRO, params={"end": "2023-06-01T23:00:00Z"})  # the other day reads as before
    assert r.status_code == 200 and r.content == good
    # An upload into the damaged span is refused (de-duplication cannot see its samples): nothing stored.
    n_files = len(stored_files(settings))
    r = upload(client, "gyro", DAY2.replace(",1,2,3", ",1,2,4"))
    assert r.status_code == 503 and r.json()["file"] == rel
    assert len(stored_files(settings)) == n_files
    # A job over the window fails naming the file.
    job = client.post("/api/v1/jobs", json={"type": "telemetry_coverage", "spacecraft": "sat1"}).json()
    deadline = time.monotonic() + 60
    while (j := client.get(f"/api/v1/jobs/{job['id']}").json())["status"] in ("queued", "running"):
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert j["status"] == "failed" and rel in j["error"]

    engine = make_engine(settings.database_url)
    sessions = session_factory(engine)
    store = ParquetStore(settings.telemetry_url)
    with sessions() as session:
        (q,) = quarantined_files(session)
        assert q.path == rel and q.quarantined and q.quarantined_at is not None
        with pytest.raises(Exception, match="damaged"):
            restore_file(session, store, q.id)
        removed = retract_ingest(session, store, q.ingest_id)
        assert removed == [rel]
        assert session.scalars(select(TelemetryFile)).all()[0].path != rel
    engine.dispose()
    r = client.get(GYRO)
    assert r.status_code == 200 and r.content == good
    assert upload(client, "gyro", DAY2).status_code == 201  # and the day can be uploaded again


def test_disk_full_is_507_and_nothing_is_stored(client, settings, monkeypatch):
    make_spacecraft(client)

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(pq.ParquetWriter, "write_table", full)  # whole and streamed uploads write through it
    r = upload(client, "gyro", DAY1)
    assert r.status_code == 507 and "full" in r.json()["detail"]
    assert stored_files(settings) == []
    assert client.get("/api/v1/spacecraft/sat1/ingests").json() == []


def test_an_unexpected_error_is_a_json_500(settings, monkeypatch):
    from fastapi.testclient import TestClient

    from app.main import create_app
    from tests.conftest import ADMIN_TOKEN

    def boom(*args, **kwargs):
        raise RuntimeError("simulated bug")

    monkeypatch.setattr("app.services.telemetry.read_window", boom)
    with TestClient(create_app(settings), raise_server_exceptions=False) as c:
        c.headers["Authorization"] = f"Bearer {ADMIN_TOKEN}"
        make_spacecraft(c)
        r = c.get(GYRO)
    assert r.status_code == 500 and r.json()["detail"].startswith("internal error (RuntimeError)")
