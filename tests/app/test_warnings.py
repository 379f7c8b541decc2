"""Result warnings: one mechanism for every job (summary ``warnings`` first; reports, UI and CLI show
them before anything else)."""

from __future__ import annotations

import argparse
import time

import pytest

from app.cli_remote import _job_outcome
from processing.tasks import WARNING_CODES, ResultWarning
from tests.app.helpers import SQLITE_ONLY, make_spacecraft

pytestmark = SQLITE_ONLY


def _run(client, params: dict) -> dict:
    job = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1", "params": params,
                                            "start": "2023-06-01T00:00:00Z", "end": "2023-06-01T00:01:00Z"})
    assert job.status_code == 202, job.text
    deadline = time.monotonic() + 60
    while (j := client.get(f"/api/v1/jobs/{job.json()['id']}").json())["status"] in ("queued", "running"):
        assert time.monotonic() < deadline
        time.sleep(0.05)
    return j


def test_warnings_come_first_in_the_summary_and_every_report(client):
    make_spacecraft(client)
    clean = _run(client, {})
    assert clean["result"]["warnings"] == []
    job = _run(client, {"warning": "not_observable"})
    summary = job["result"]
    assert next(iter(summary)) == "warnings"
    assert summary["warnings"] == [{"code": "not_observable", "message": "executor_check was asked to warn "
                                    "not_observable", "evidence": {"requested": True}}]
    report = client.get(f"/api/v1/jobs/{job['id']}/report", params={"format": "json"}).json()
    assert next(iter(report)) == "warnings" and report["warnings"][0]["code"] == "not_observable"
    html = client.get(f"/api/v1/jobs/{job['id']}/report").text
    assert 'id="warnings"' in html and html.index('id="warnings"') < html.index('id="summary"')
    assert "not_observable" in html


def test_unknown_codes_are_refused_and_the_cli_prints_warnings(capsys):
    with pytest.raises(ValueError, match="unknown warning code"):
        ResultWarning("made_up", "x")
    assert {"quaternion_convention", "time_offset", "correlated_residuals", "outliers_removed", "not_observable",
            "bias_not_constant", "filter_inconsistent"} <= set(WARNING_CODES)
    args = argparse.Namespace(json=False, url="http://x", quiet=True)
    job = {"id": "j1", "status": "succeeded", "report_url": "/r", "result": {"warnings": [
        {"code": "time_offset", "message": "gyro lags the star tracker by 0.5 s", "evidence": {}}]}}
    class Reports:  # the report's headline, as the service would give it
        def report_data(self, job_id: str) -> dict:
            assert job_id == "j1"
            return {"headline": {"verdict": "pass", "rows": [{"quantity": "gyro offset", "component": "x",
                                                               "text": "0.1 ± 0.01", "unit": "deg/h"}]}}

    assert _job_outcome(args, Reports(), job) == 0  # type: ignore[arg-type]
    out = capsys.readouterr().out
    assert "WARNING time_offset: gyro lags the star tracker by 0.5 s" in out
    assert "verdict: PASS" in out and "gyro offset x: 0.1 ± 0.01 deg/h" in out
