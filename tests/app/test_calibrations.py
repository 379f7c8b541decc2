"""Calibration versions: alignment_calibration stores one; later gyro jobs apply the latest and say so."""

from __future__ import annotations

import numpy as np
import pytest

from processing.simulate.seed000 import simulate_seed000
from processing.time import timescales
from tests.app.test_jobs_api import upload_columns, wait

START = int(timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])


@pytest.mark.slow
def test_calibration_is_stored_and_applied(client):
    sc = simulate_seed000(start_tai_ns=START, duration_s=900.0, seed=1)
    client.post("/api/v1/spacecraft", json={"name": "agile", "config": sc.config})
    for stream, columns in sc.streams.items():
        upload_columns(client, "agile", stream, columns)
    r = client.post("/api/v1/jobs", json={"type": "alignment_calibration", "spacecraft": "agile"})
    job = wait(client, r.json()["id"], timeout_s=240)
    assert job["status"] == "succeeded", job["error"]
    assert job["result"]["calibration_complete"] is True
    cals = client.get("/api/v1/spacecraft/agile/calibrations").json()
    assert [(c["kind"], c["version"], c["job_id"]) for c in cals] == [("gyro", 1, job["id"])]
    assert np.allclose(cals[0]["values"]["drift_rad_s"], job["result"]["drift_rad_s"])

    # a later job that uses gyro data pins the latest version and reports it; "none" opts out
    later = client.post("/api/v1/jobs", json={"type": "star_tracker_accuracy", "spacecraft": "agile",
                                              "params": {"use_gyro": False}}).json()
    assert client.get(f"/api/v1/jobs/{later['id']}").json()["reference"] == {"calibration:gyro": cals[0]["id"]}
    raw = client.post("/api/v1/jobs", json={"type": "star_tracker_accuracy", "spacecraft": "agile",
                                            "calibration": "none", "params": {"use_gyro": False}}).json()
    assert client.get(f"/api/v1/jobs/{raw['id']}").json()["reference"] == {}
    r = client.post("/api/v1/jobs", json={"type": "star_tracker_accuracy", "spacecraft": "agile",
                                          "calibration": "nosuch"})
    assert r.status_code == 422
    done = wait(client, later["id"], timeout_s=240)
    assert any("calibration version 1" in n for n in done["notes"]), done["notes"]


@pytest.mark.slow
def test_no_calibration_version_from_undeterminable_values(client):
    """Issue 17: a nadir-pointing arc (the orbital rate only) determines neither misalignment nor scale factor
    nor drift: the job succeeds with nulls and not_observable, and stores no calibration version."""
    sc = simulate_seed000(start_tai_ns=START, duration_s=600.0, seed=2, initial_hold_s=1e6)
    client.post("/api/v1/spacecraft", json={"name": "nadir", "config": sc.config})
    for stream, columns in sc.streams.items():
        upload_columns(client, "nadir", stream, columns)
    r = client.post("/api/v1/jobs", json={"type": "alignment_calibration", "spacecraft": "nadir"})
    job = wait(client, r.json()["id"], timeout_s=240)
    assert job["status"] == "succeeded", job["error"]
    res = job["result"]
    assert res["calibration_complete"] is False and res["scale_factor_error"] is None
    assert [w["code"] for w in res["warnings"]] == ["not_observable"]
    assert client.get("/api/v1/spacecraft/nadir/calibrations").json() == []
