"""Rerun from the report: every job type's report carries the request (and the UI link) that runs it again,
and running it reproduces the result. Apart from tests/app/test_reports.py (whose report world it shares) so
that the reruns, which cost as much as building the world, run beside the other report tests."""

from __future__ import annotations

import json
import urllib.parse

import pytest

from tests.app.report_world import all_type_names, strip_volatile
from tests.app.test_jobs_api import wait
from tests.app.test_reports import expected_rerun, finished, world  # noqa: F401  (world: the module fixture)


@pytest.mark.parametrize("job_type", all_type_names())
def test_rerun_from_the_report_reproduces_it(world, job_type):  # noqa: F811  (the imported fixture)
    job = finished(world, job_type)
    client = world.client
    rep = client.get(f"/api/v1/jobs/{job['id']}/report", params={"format": "json"}).json()
    body = rep["reproduce"]["request"]
    ui = urllib.parse.urlsplit(rep["reproduce"]["ui_url"])
    query = dict(urllib.parse.parse_qsl(ui.query))
    assert body == expected_rerun(job)
    assert ui.path == "/ui/jobs/new"
    assert (query["type"], query["spacecraft"], query.get("start"), query.get("end")) == (
        job_type, job["spacecraft"], body.get("start"), body.get("end"))
    assert json.loads(query["params"]) == job["params"]
    r = client.post("/api/v1/jobs", json=body)
    assert r.status_code == 202, r.text
    again = wait(client, r.json()["id"], timeout_s=900)
    assert again["status"] == "succeeded", again["error"]
    assert (again["params"], again["reference"]) == (job["params"], job["reference"])
    if "start" in body:
        assert (again["start"], again["end"]) == (job["start"], job["end"])
    assert again["inputs"] == job["inputs"]
    assert strip_volatile(again["result"]) == strip_volatile(job["result"])
