"""The stores on an object store: a local S3-compatible server (moto in server mode, started here).

Object stores have no atomic rename: files are uploaded whole under their final names and published
through the catalog. These tests check that reads, orphan removal and failed uploads behave as on a
local disk, and that the whole service (uploads, jobs, artifacts) runs with ``ATTITUDE_DATA_URL``.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import time
import urllib.request
from dataclasses import replace

import numpy as np
import pyarrow as pa
import pyarrow.fs as pafs
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from storage import fs as storage_fs
from storage.jobs import ArtifactStore
from storage.parquet_store import ParquetStore
from tests.app.helpers import make_spacecraft, upload
from tests.app.test_jobs_api import wait

pytest.importorskip("moto")
BUCKET = "attitude-test"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def s3_endpoint():
    """A moto S3 server on a free loopback port, for this module only."""
    port = _free_port()
    # this interpreter's moto (a moto_server found on PATH may belong to another Python)
    proc = subprocess.Popen([sys.executable, "-m", "moto.server", "-H", "127.0.0.1", "-p", str(port)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}/moto-api/", timeout=1).close()
                break
            except OSError:
                assert proc.poll() is None, "moto_server exited"
                assert time.monotonic() < deadline, "moto_server did not start"
                time.sleep(0.1)
        yield f"127.0.0.1:{port}"
    finally:
        proc.terminate()
        proc.wait(10)


@pytest.fixture
def s3_url(s3_endpoint, request):
    """A fresh prefix in the test bucket; credentials and endpoint in the URL so that worker processes
    started at any time see them (production uses the AWS_* environment instead)."""
    query = f"endpoint_override={s3_endpoint}&scheme=http&region=us-east-1&allow_bucket_creation=true"
    fs, _ = pafs.FileSystem.from_uri(f"s3://key:secret@{BUCKET}?{query}")
    fs.create_dir(BUCKET)
    prefix = f"{request.node.name.replace('[', '-').replace(']', '')}-{time.monotonic_ns()}"
    return f"s3://key:secret@{BUCKET}/{prefix}?{query}"


def _table(times_s, value=1.0):
    t = np.asarray(times_s, dtype=np.int64) * 1_000_000_000
    n = len(t)
    return pa.table({"time_tai_ns": t, "sensor": ["gyro"] * n, "wx": [value] * n, "wy": [value] * n,
                     "wz": [value] * n})


def test_parquet_store_round_trip_and_orphans_on_s3(s3_url):
    store = ParquetStore(s3_url)
    assert not store.location.local
    day = 86_400
    written = store.write(1, "gyro", "ing1", _table([10, 20, day + 5]))
    assert [w.path for w in written] == ["sc=1/stream=gyro/day=1970-01-01/ing1.parquet",
                                         "sc=1/stream=gyro/day=1970-01-02/ing1.parquet"]
    tables = store.read([w.path for w in written], start_tai_ns=15 * 10**9)
    assert [t.column("time_tai_ns").to_pylist() for t in tables] == [[20 * 10**9], [(day + 5) * 10**9]]
    assert store.remove_orphans({written[0].path}) == []  # young files may belong to a live ingest
    assert store.remove_orphans({written[0].path}, older_than_s=0) == [written[1].path]
    assert [rel for rel, _ in store.location.list_files(".parquet")] == [written[0].path]
    store.remove([written[0].path])
    assert store.location.list_files(".parquet") == []


def test_failed_upload_leaves_no_object(s3_url, monkeypatch):
    store = ParquetStore(s3_url)
    real = storage_fs.Location.write_bytes

    def half_then_fail(self, rel, data):
        real(self, rel, data)  # the object arrived ...
        raise OSError("connection reset")  # ... but the client saw a failure

    monkeypatch.setattr(storage_fs.Location, "write_bytes", half_then_fail)
    with pytest.raises(OSError, match="connection reset"):
        store.write(1, "gyro", "ing2", _table([1, 2, 86_400 + 1]))
    monkeypatch.undo()
    assert store.location.list_files() == []


def test_artifacts_on_s3_are_served_through_a_local_cache(s3_url, tmp_path):
    store = ArtifactStore(s3_url, cache_dir=tmp_path / "cache")
    a = store.write("job1", "summary.json", b'{"ok": true}', kind="summary", media_type="application/json")
    assert store.read_bytes(a.path) == b'{"ok": true}'
    assert store.file_path(a.path).read_bytes() == b'{"ok": true}'
    assert not store.file_path("job1/missing.csv").exists()
    store.remove_job("job1")
    assert not store.location.exists(a.path) and not (tmp_path / "cache" / "job1").exists()
    with pytest.raises(ValueError, match="plain file names"):
        store.write("job1", "../x", b"", kind="file", media_type="text/plain")


def test_fsspec_only_filesystems_work_too():
    store = ParquetStore("memory://attitude-tests/telemetry")
    assert isinstance(store.location.fs, pafs.PyFileSystem)
    written = store.write(3, "gyro", "ing3", _table([5, 6]))
    assert store.read([written[0].path])[0].num_rows == 2
    store.remove([written[0].path])
    with pytest.raises(storage_fs.StorageURLError, match="bucket or directory"):
        storage_fs.resolve("memory://")


def test_the_service_runs_on_the_object_store(settings, s3_url):
    """Uploads, reads, a job with artifacts and a report, with ATTITUDE_DATA_URL on S3: no telemetry or
    artifact file is written to the local data directory (only the SQLite catalog, if that is used)."""
    settings = replace(settings, data_url=s3_url)
    with TestClient(create_app(settings)) as client:
        client.headers["Authorization"] = f"Bearer {settings.bootstrap_token}"
        make_spacecraft(client)
        csv = "time,wx,wy,wz\n" + "".join(f"2023-06-01T00:00:{i:02d}Z,1,2,3\n" for i in range(30))
        assert upload(client, "gyro", csv).status_code == 201
        assert upload(client, "gyro", csv).json()["duplicates"] == 30  # de-duplication reads the object store
        rows = client.get("/api/v1/spacecraft/sat1/telemetry/gyro", params={"format": "json"}).json()
        assert len(rows) == 30
        job = wait(client, client.post("/api/v1/jobs", json={"type": "telemetry_coverage",
                                                              "spacecraft": "sat1"}).json()["id"])
        assert job["status"] == "succeeded", job["error"]
        arts = {a["name"]: a for a in client.get(f"/api/v1/jobs/{job['id']}/artifacts").json()}
        png = client.get(arts["coverage.png"]["url"])
        assert png.status_code == 200 and png.content[:4] == b"\x89PNG"
        assert "data:image/png;base64," in client.get(f"/api/v1/jobs/{job['id']}/report").text
    objects = {rel.split("/", 1)[0] for rel, _ in ParquetStore(settings.data_url or "").location.list_files()}
    assert objects == {"telemetry", "artifacts"}
    assert not (settings.data_dir / "telemetry").exists() and not (settings.data_dir / "artifacts").exists()
