"""Atomic publish: a crash between the file write and the catalog commit leaves readers consistent."""

from __future__ import annotations

import os

import numpy as np
import pyarrow as pa
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from processing.streams import STREAMS
from storage.db import make_engine, session_factory
from storage.parquet_store import ParquetStore
from tests.app.helpers import make_spacecraft, stored_files, upload

GYRO = "time,wx,wy,wz\n2023-06-01T00:00:00Z,1,2,3\n2023-06-02T00:00:00Z,1,2,3\n"


def _rows(client):
    return client.get("/api/v1/spacecraft/sat1/telemetry/gyro?format=json").json()


def test_commit_failure_removes_written_files(client, settings, monkeypatch):
    make_spacecraft(client)
    from sqlalchemy.orm import Session

    real_commit = Session.commit

    def failing_commit(self):
        if self.info.get("written_files"):
            raise RuntimeError("simulated crash before the catalog commit")
        return real_commit(self)

    monkeypatch.setattr(Session, "commit", failing_commit)
    with pytest.raises(RuntimeError, match="simulated crash"):
        upload(client, "gyro", GYRO)
    monkeypatch.setattr(Session, "commit", real_commit)
    assert stored_files(settings) == []
    assert _rows(client) == []
    assert client.get("/api/v1/spacecraft/sat1/ingests").json() == []


def test_process_death_after_rename_leaves_invisible_orphans(client, settings):
    """Files renamed into place whose catalog row never committed (the process died) are not read,
    and the next start-up removes them once they are old enough to belong to no live ingest."""
    make_spacecraft(client)
    assert upload(client, "gyro", GYRO).status_code == 201
    store = ParquetStore(settings.telemetry_dir)
    spec = STREAMS["gyro"]
    t = np.array([1_685_577_700_000_000_000, 1_685_664_000_000_000_000], dtype=np.int64)
    orphan_table = pa.table({"time_tai_ns": t, "sensor": ["gyro", "gyro"], "wx": [9.0, 9.0],
                             "wy": [9.0, 9.0], "wz": [9.0, 9.0]})
    written = store.write(1, spec.name, "deadbeef" * 4, orphan_table)  # the "crash": no commit follows
    assert len(written) == 2
    assert len(_rows(client)) == 2 and all(r["wx"] == 1 for r in _rows(client))
    for w in written:
        os.utime(settings.telemetry_dir / w.path, (0, 0))
    with TestClient(create_app(settings)) as restarted:  # start-up cleans the orphans
        restarted.headers["Authorization"] = client.headers["Authorization"]
        assert len(_rows(restarted)) == 2
    remaining = {str(p.relative_to(settings.telemetry_dir)) for p in stored_files(settings)}
    assert not remaining & {w.path for w in written}
    assert len(remaining) == 2


def test_recent_unreferenced_files_are_kept_for_a_live_ingest(tmp_path):
    store = ParquetStore(tmp_path / "t")
    table = pa.table({"time_tai_ns": np.array([1], dtype=np.int64), "sensor": ["g"], "wx": [1.0],
                      "wy": [1.0], "wz": [1.0]})
    w = store.write(1, "gyro", "abc", table)
    assert store.remove_orphans(set()) == []
    assert store.remove_orphans(set(), older_than_s=0) == [w[0].path]


def test_temporary_files_never_match_published_names(tmp_path, monkeypatch):
    """If the write itself dies, only a hidden temporary file could remain, never a final name."""
    store = ParquetStore(tmp_path / "t")
    table = pa.table({"time_tai_ns": np.array([1], dtype=np.int64), "sensor": ["g"], "wx": [1.0],
                      "wy": [1.0], "wz": [1.0]})

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        store.write(1, "gyro", "abc", table)
    assert list((tmp_path / "t").rglob("*.parquet")) == []


def test_catalog_lists_only_complete_files(client, settings):
    make_spacecraft(client)
    upload(client, "gyro", GYRO)
    engine = make_engine(settings.database_url)
    from storage.telemetry import referenced_paths

    with session_factory(engine)() as session:
        refs = referenced_paths(session)
    engine.dispose()
    on_disk = {str(p.relative_to(settings.telemetry_dir)) for p in stored_files(settings)}
    assert refs == on_disk and len(refs) == 2  # two TAI days
