"""Job lifecycle through the HTTP API: submit, poll, artifacts, reports, cancel, failures, recovery."""

from __future__ import annotations

import datetime as dt
import io
import json
import time

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import delete

from app.main import create_app
from processing.simulate.seed003 import simulate_seed003
from processing.time import timescales
from storage.db import make_engine, session_factory, upgrade
from storage.models import Artifact, Job, Spacecraft, utcnow
from tests.app.helpers import PARQUET, make_spacecraft, upload

FINAL = ("succeeded", "failed", "cancelled")
START = int(timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])


def wait(client, job_id, timeout_s=60.0, until=FINAL):
    deadline = time.monotonic() + timeout_s
    while True:
        job = client.get(f"/api/v1/jobs/{job_id}").json()
        if job["status"] in until:
            return job
        assert time.monotonic() < deadline, f"job still {job['status']}"
        time.sleep(0.05)


def upload_columns(client, sc, stream, columns):
    cols = dict(columns)
    t = np.asarray(cols.pop("time_tai_ns"), dtype=np.int64)
    table = pa.table({"time": pa.array(t, pa.timestamp("ns")), **{k: np.asarray(v) for k, v in cols.items()}})
    buf = io.BytesIO()
    pq.write_table(table, buf)
    r = upload(client, stream, buf.getvalue(), PARQUET, sc=sc, time_scale="tai")
    assert r.status_code == 201, r.text


@pytest.fixture
def scenario():
    return simulate_seed003(start_tai_ns=START, duration_s=600.0, seed=11)


def test_coverage_job_finds_the_simulated_gaps_exactly(client, scenario):
    make_spacecraft(client, "meteor", scenario.config)
    for stream, columns in scenario.streams.items():
        upload_columns(client, "meteor", stream, columns)
    r = client.post("/api/v1/jobs", json={"type": "telemetry_coverage", "spacecraft": "meteor"})
    assert r.status_code == 202
    assert r.json()["status_url"] == f"/api/v1/jobs/{r.json()['id']}"
    job = wait(client, r.json()["id"])
    assert job["status"] == "succeeded", job["error"]
    assert job["progress"] == 1.0 and job["finished_at"] is not None
    st = next(s for s in job["result"]["streams"] if s["stream"] == "star_tracker")
    truth = np.asarray(scenario.truth.st_gap_intervals_tai_ns)
    assert st["n_gaps"] == len(truth) > 0
    assert [[g["before_tai_ns"], g["after_tai_ns"]] for g in st["gaps"]] == truth.tolist()
    assert st["missing_samples"] == len(scenario.truth.st_removed_time_tai_ns)
    assert st["period_s"] == pytest.approx(3.0)
    gyro = next(s for s in job["result"]["streams"] if s["stream"] == "gyro")
    assert gyro["n_gaps"] == 0 and gyro["n_samples"] == len(scenario.streams["gyro"]["time_tai_ns"])
    assert job["inputs"]["star_tracker"] == {"st1": len(scenario.streams["star_tracker"]["time_tai_ns"])}

    arts = {a["name"]: a for a in client.get(f"/api/v1/jobs/{job['id']}/artifacts").json()}
    assert {"summary.json", "gaps.csv", "gaps.parquet", "coverage.csv", "coverage.png"} <= set(arts)
    png = client.get(arts["coverage.png"]["url"])
    assert png.headers["content-type"] == "image/png" and png.content[:8] == b"\x89PNG\r\n\x1a\n"
    csv = client.get(arts["gaps.csv"]["url"])
    assert csv.headers["content-type"].startswith("text/csv")
    assert 'attachment; filename="gaps.csv"' in csv.headers["content-disposition"]
    assert csv.text.count("\n") == len(truth) + 1
    pq_table = pq.read_table(io.BytesIO(client.get(arts["gaps.parquet"]["url"]).content))
    assert pq_table.column("time_tai_ns").to_pylist() == truth[:, 0].tolist()
    assert client.get(f"/api/v1/jobs/{job['id']}/artifacts/nope.csv").status_code == 404
    # a long table is stored as Parquet only (app.jobs.outputs): its CSV is made from the Parquet on request,
    # streamed, with the same bytes as the stored CSV; a name with neither file stays 404
    with client.app.state.sessions.begin() as session:
        session.execute(delete(Artifact).where(Artifact.job_id == job["id"], Artifact.name == "gaps.csv"))
    again = client.get(arts["gaps.csv"]["url"])
    assert again.status_code == 200 and again.content == csv.content
    assert again.headers["content-type"].startswith("text/csv")
    assert 'attachment; filename="gaps.csv"' in again.headers["content-disposition"]
    assert client.get(f"/api/v1/jobs/{job['id']}/artifacts/summary.csv").status_code == 404

    html = client.get(f"/api/v1/jobs/{job['id']}/report")
    assert html.headers["content-type"].startswith("text/html")
    for text in ("Telemetry coverage", "meteor", "data:image/png;base64,", job["software_version"], "gap_factor"):
        assert text in html.text
    rep = client.get(f"/api/v1/jobs/{job['id']}/report?format=json").json()
    assert rep["summary"]["n_gaps"] == len(truth) and rep["parameters"] == {"gap_factor": 1.5}
    assert rep["configuration"]["version"] == 1 and rep["inputs"]["gyro"]["gyro"] > 0

    listed = client.get("/api/v1/jobs", params={"spacecraft": "meteor", "status": "succeeded"}).json()
    assert [j["id"] for j in listed] == [job["id"]]
    assert client.get("/api/v1/jobs", params={"type": "gyro_bias_fit"}).json() == []


def test_explicit_window(client):
    make_spacecraft(client)
    csv = "time,wx,wy,wz\n" + "".join(f"2023-06-01T00:00:{i:02d}Z,1,2,3\n" for i in range(30))
    upload(client, "gyro", csv)
    r = client.post("/api/v1/jobs", json={"type": "telemetry_coverage", "spacecraft": "sat1",
                                          "start": "2023-06-01T00:00:10Z", "end": "2023-06-01T00:00:19Z"})
    job = wait(client, r.json()["id"])
    assert job["start"] == "2023-06-01T00:00:10Z" and job["end"] == "2023-06-01T00:00:19Z"
    assert job["result"]["streams"][0]["n_samples"] == 10


@pytest.mark.parametrize(
    ("body", "status", "fragment"),
    [
        ({"type": "no_such_job", "spacecraft": "sat1"}, 422, "unknown job type"),
        ({"type": "telemetry_coverage", "spacecraft": "nosuch"}, 404, "not found"),
        ({"type": "telemetry_coverage", "spacecraft": "sat1", "params": {"gap_factor": 0.5}}, 422, "gap_factor"),
        ({"type": "telemetry_coverage", "spacecraft": "sat1", "params": {"bogus": 1}}, 422, "bogus"),
        ({"type": "telemetry_coverage", "spacecraft": "sat1", "start": "2020-01-01T00:00:00Z",
          "end": "2020-01-02T00:00:00Z"}, 422, "no telemetry"),
        ({"type": "telemetry_coverage", "spacecraft": "sat1", "start": "2023-06-02T00:00:00Z",
          "end": "2023-06-01T00:00:00Z"}, 422, "after start"),
        ({"type": "telemetry_coverage", "spacecraft": "sat1", "start": "noon"}, 422, "start"),
    ],
)
def test_bad_submissions_are_rejected(client, body, status, fragment):
    make_spacecraft(client)
    upload(client, "gyro", "time,wx,wy,wz\n2023-06-01T00:00:00Z,1,2,3\n2023-06-01T00:00:01Z,1,2,3\n")
    r = client.post("/api/v1/jobs", json=body)
    assert r.status_code == status
    assert fragment in json.dumps(r.json())
    assert client.get("/api/v1/jobs").json() == []


def test_job_needing_absent_stream_is_rejected(client):
    from app.jobs.registry import registry

    needs_streams = [j for j in registry().values() if j.streams]
    if not needs_streams:
        pytest.skip("no job type with required streams registered yet")
    make_spacecraft(client)
    r = client.post("/api/v1/jobs", json={"type": needs_streams[0].name, "spacecraft": "sat1"})
    assert r.status_code == 422 and "samples" in r.json()["detail"]
    # A type whose streams are all optional (gyro_noise: gyro or increments) with none stored: 422, not 500.
    optional_only = [j for j in registry().values() if not j.streams and j.optional_streams]
    for jt in optional_only:
        r = client.post("/api/v1/jobs", json={"type": jt.name, "spacecraft": "sat1"})
        assert r.status_code == 422 and "needs one of them" in r.json()["detail"], (jt.name, r.text)


def test_failure_comes_back_with_its_reason(client):
    make_spacecraft(client)
    r = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1", "params": {"fail": True}})
    job = wait(client, r.json()["id"])
    assert job["status"] == "failed" and job["error"] == "executor_check was asked to fail"
    assert client.get(f"/api/v1/jobs/{job['id']}/artifacts").json() == []
    assert "executor_check was asked to fail" in client.get(f"/api/v1/jobs/{job['id']}/report").text


def test_crashed_worker_fails_the_job(client):
    make_spacecraft(client)
    r = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1", "params": {"crash": True}})
    job = wait(client, r.json()["id"])
    assert job["status"] == "failed" and "exited with code 3" in job["error"]


def test_cancel_running_and_queued_jobs(client):
    make_spacecraft(client)
    ids = [client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1",
                                            "params": {"duration_s": 60}}).json()["id"] for _ in range(3)]
    running = wait(client, ids[0], until=("running",))
    assert running["stage"] in ("starting", "loading telemetry", "computing", "waiting")
    wait(client, ids[1], until=("running",))  # max_jobs = 2 in the test settings
    assert client.get(f"/api/v1/jobs/{ids[2]}").json()["status"] == "queued"
    queued = client.post(f"/api/v1/jobs/{ids[2]}/cancel").json()
    assert queued["status"] == "cancelled"
    for job_id in ids[:2]:
        assert client.post(f"/api/v1/jobs/{job_id}/cancel").json()["cancel_requested"] is True
    for job_id in ids[:2]:
        job = wait(client, job_id, timeout_s=20)
        assert job["status"] == "cancelled", job
    assert client.post(f"/api/v1/jobs/{ids[0]}/cancel").status_code == 409
    assert client.get("/api/v1/jobs/nosuch").status_code == 404


def test_timeout_fails_the_job(settings):
    from dataclasses import replace

    with TestClient(create_app(replace(settings, job_timeout_s=1))) as client:
        client.headers["Authorization"] = f"Bearer {settings.bootstrap_token}"
        make_spacecraft(client)
        r = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1",
                                              "params": {"duration_s": 30}})
        job = wait(client, r.json()["id"], timeout_s=30)
    assert job["status"] == "failed" and "timed out after 1 s" in job["error"]


def test_restart_recovery(settings):
    """A job 'running' when the service died is failed at start-up; a queued one runs."""
    from dataclasses import replace

    engine = make_engine(settings.database_url)
    upgrade(engine)
    with session_factory(engine).begin() as session:
        sc = Spacecraft(name="sat1")
        session.add(sc)
        session.flush()
        from storage.models import SpacecraftConfig

        session.add(SpacecraftConfig(spacecraft_id=sc.id, version=1, config={}))
        common = {"spacecraft_id": sc.id, "config_version": 1, "start_tai_ns": START, "end_tai_ns": START + 10**9,
                  "params": {}, "software_version": "test", "cancel_requested": False, "progress": 0.0}
        session.add(Job(id="interrupted", type="executor_check", status="running", stage="computing",
                        started_at=utcnow() - dt.timedelta(minutes=5),
                        heartbeat_at=utcnow() - dt.timedelta(minutes=5), **common))
        session.add(Job(id="waiting", type="executor_check", status="queued", stage="queued", **common))
    engine.dispose()
    with TestClient(create_app(replace(settings, heartbeat_timeout_s=60))) as client:
        client.headers["Authorization"] = f"Bearer {settings.bootstrap_token}"
        lost = client.get("/api/v1/jobs/interrupted").json()
        assert lost["status"] == "failed" and "stopped while the job was running" in lost["error"]
        assert wait(client, "waiting")["status"] == "succeeded"


def test_job_types_listing(client):
    types = {t["type"]: t for t in client.get("/api/v1/jobs/types").json()}
    assert "telemetry_coverage" in types and "properties" in types["telemetry_coverage"]["params_schema"]


def test_viewer_cannot_submit_or_cancel(client):
    make_spacecraft(client)
    secret = client.post("/api/v1/keys", json={"name": "v", "role": "viewer"}).json()["secret"]
    headers = {"Authorization": f"Bearer {secret}"}
    r = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1"}, headers=headers)
    assert r.status_code == 403
    assert client.get("/api/v1/jobs", headers=headers).status_code == 200


def test_task_files_become_artifacts(tmp_path):
    from app.jobs.outputs import write_outputs
    from processing.tasks import TaskResult
    from storage.jobs import ArtifactStore

    result = TaskResult(summary={}, files={"attitude.aem": (b"CCSDS_AEM_VERS = 2.0\n", "text/plain")})
    stored = write_outputs(ArtifactStore(tmp_path), "job1", result, {}, {})
    aem = next(a for a in stored if a.name == "attitude.aem")
    assert aem.kind == "file" and aem.media_type == "text/plain"
    assert (tmp_path / "job1" / "attitude.aem").read_bytes() == b"CCSDS_AEM_VERS = 2.0\n"
