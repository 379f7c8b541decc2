"""Retraction of uploads: the samples disappear from reads and new jobs, the log says who, when and why,
the jobs that had read them are marked, nothing else changes; the quarantine of damaged files for admins."""

from __future__ import annotations

from tests.app.helpers import issue_keys, make_spacecraft, upload
from tests.app.test_jobs_api import wait

DAY1 = "time,wx,wy,wz\n" + "".join(f"2023-06-01T00:00:{s:02d}Z,1,2,3\n" for s in range(10))
DAY2 = "time,wx,wy,wz\n" + "".join(f"2023-06-02T00:00:{s:02d}Z,4,5,6\n" for s in range(6))
GNSS = ("time,x,y,z,vx,vy,vz\n2023-06-01T00:00:00Z,7000000,0,0,0,7500,0\n"
        "2023-06-01T00:00:01Z,6999996,7500,0,-8,7500,0\n")


def _job(client, **body) -> dict:
    r = client.post("/api/v1/jobs", json={"type": "telemetry_coverage", "spacecraft": "sat1", **body})
    assert r.status_code == 202, r.text
    job = wait(client, r.json()["id"])
    assert job["status"] == "succeeded", job["error"]
    return job


def test_retraction_hides_the_samples_logs_and_marks_only_the_jobs_that_used_them(client):
    make_spacecraft(client)
    first = upload(client, "gyro", DAY1, filename="mistake.csv").json()
    upload(client, "gyro", DAY2)
    upload(client, "gnss", GNSS)
    used = _job(client)  # reads both gyro days and the GNSS samples
    other = _job(client, start="2023-06-02T00:00:00Z", end="2023-06-02T00:01:00Z")  # day 2 only
    make_spacecraft(client, "A", {})  # issue_keys grants keys to a spacecraft "A"
    keys, _ = issue_keys(client)
    path = f"/api/v1/spacecraft/sat1/ingests/{first['ingest_id']}"

    assert client.delete(path).status_code == 422  # a reason is required
    viewer = {"Authorization": f"Bearer {keys['viewer']}"}
    assert client.delete(path, params={"reason": "wrong file"}, headers=viewer).status_code == 403
    operator = {"Authorization": f"Bearer {keys['operator']}"}
    r = client.delete(path, params={"reason": "uploaded the calibration run by mistake"}, headers=operator)
    assert r.status_code == 200, r.text
    log = r.json()
    assert log["ingest_id"] == first["ingest_id"] and log["samples_removed"] == 10 and log["files_removed"] == 1
    assert log["reason"] == "uploaded the calibration run by mistake" and log["retracted_by"] == "operator-0"
    assert log["filename"] == "mistake.csv" and log["jobs_marked"] == [used["id"]]

    # reads and new jobs no longer see the samples; the other upload is untouched
    rows = client.get("/api/v1/spacecraft/sat1/telemetry/gyro").text.strip().splitlines()[1:]
    assert len(rows) == 6 and all(r.startswith('"2023-06-02') for r in rows)
    again = _job(client)
    assert again["inputs"]["gyro"] == {"gyro": 6}
    # the log, the marked job's report and the unmarked ones
    (entry,) = client.get("/api/v1/spacecraft/sat1/retractions").json()
    assert entry["retraction_id"] == log["retraction_id"] and entry["retracted_at"]
    report = client.get(f"/api/v1/jobs/{used['id']}/report", params={"format": "json"}).json()
    assert [r["reason"] for r in report["retracted_inputs"]] == ["uploaded the calibration run by mistake"]
    assert "Based on retracted data" in client.get(f"/api/v1/jobs/{used['id']}/report").text
    for job in (other, again):
        assert client.get(f"/api/v1/jobs/{job['id']}/report", params={"format": "json"}).json()[
            "retracted_inputs"] == []
    # the job that used the samples keeps its result as it was
    assert client.get(f"/api/v1/jobs/{used['id']}").json()["result"] == used["result"]
    assert client.delete(path, params={"reason": "again"}).status_code == 409
    assert client.delete("/api/v1/spacecraft/sat1/ingests/nosuch", params={"reason": "why"}).status_code == 404
    assert len(client.get("/api/v1/spacecraft/sat1/ingests").json()) == 2  # the other uploads are listed as before


def test_quarantine_is_for_admins(client):
    make_spacecraft(client)
    make_spacecraft(client, "A", {})
    keys, _ = issue_keys(client)
    assert client.get("/api/v1/spacecraft/sat1/quarantine").json() == []
    operator = {"Authorization": f"Bearer {keys['operator']}"}
    assert client.get("/api/v1/spacecraft/sat1/quarantine", headers=operator).status_code == 403
    assert client.post("/api/v1/spacecraft/sat1/quarantine/1/restore").status_code == 404
