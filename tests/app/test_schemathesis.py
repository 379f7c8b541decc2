"""Property-based fuzzing of the whole HTTP API against its own OpenAPI schema (schemathesis).

A real server (SQLite) with a spacecraft, telemetry and a finished job; every operation gets bounded
positive and negative examples, checked for: no 5xx, documented status codes, responses matching
their schema, and invalid data rejected.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
import urllib.request

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis.errors import Unsatisfiable
from schemathesis import GenerationMode
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    negative_data_rejection,
    response_schema_conformance,
    status_code_conformance,
)

from app.devserver import running_server

TOKEN = "schemathesis-admin-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
MAX_EXAMPLES = int(os.environ.get("ATTITUDE_FUZZ_EXAMPLES", "12"))
pytestmark = pytest.mark.slow


def _call(base, method, path, body=None, content_type="application/json"):
    req = urllib.request.Request(base + path, data=body, method=method,
                                 headers={**AUTH, "Content-Type": content_type})
    with urllib.request.urlopen(req, timeout=120) as r:  # the first job submission imports every job type
        return json.loads(r.read())


@pytest.fixture(scope="module")
def api_schema():
    with tempfile.TemporaryDirectory() as tmp:
        env = {"ATTITUDE_DATA_DIR": tmp, "ATTITUDE_BOOTSTRAP_TOKEN": TOKEN, "ATTITUDE_DATABASE_URL": "",
               "ATTITUDE_RATE_LIMIT_PER_MINUTE": "1000000", "ATTITUDE_AUTH_FAILURES_PER_MINUTE": "1000000",
               "ATTITUDE_MAX_JOBS": "1"}
        with running_server(env) as base:
            _call(base, "POST", "/api/v1/spacecraft", json.dumps({"name": "sat1"}).encode())
            csv = "time,wx,wy,wz\n" + "".join(f"2023-06-01T00:00:{i:02d}Z,1,2,3\n" for i in range(10))
            _call(base, "POST", "/api/v1/spacecraft/sat1/telemetry/gyro", csv.encode(), "text/csv")
            job = _call(base, "POST", "/api/v1/jobs", json.dumps(
                {"type": "telemetry_coverage", "spacecraft": "sat1"}).encode())
            for _ in range(200):
                if _call(base, "GET", f"/api/v1/jobs/{job['id']}")["status"] != "queued":
                    break
                time.sleep(0.1)
            yield schemathesis.openapi.from_url(f"{base}/openapi.json")


@schemathesis.auth()
class BearerToken:
    """The admin key, applied the way the schema declares it (so negative cases can still drop it)."""

    def get(self, case, context):
        return TOKEN

    def set(self, case, data, context):
        case.headers = {**(case.headers or {}), "Authorization": f"Bearer {data}"}


CHECKS = [not_a_server_error, status_code_conformance, response_schema_conformance, negative_data_rejection]


def test_api_conforms_to_its_schema(api_schema):
    """Every operation, positive and negative examples (the schemathesis pytest plugin does not run
    under pytest 9, so the operations' hypothesis strategies are driven directly)."""
    failures = []
    operations = [result.ok() for result in api_schema.get_all_operations()]
    assert len(operations) > 20
    for operation in operations:
        for mode in (GenerationMode.POSITIVE, GenerationMode.NEGATIVE):
            @given(case=operation.as_strategy(generation_mode=mode))
            @settings(max_examples=MAX_EXAMPLES, deadline=None, database=None, derandomize=True,
                      suppress_health_check=list(HealthCheck))
            def check(case):
                case.call_and_validate(checks=CHECKS)

            try:
                check()
            except Unsatisfiable:  # no invalid input exists (e.g. an operation without parameters)
                assert mode is GenerationMode.NEGATIVE, operation.path
            except (Exception, BaseExceptionGroup) as exc:  # noqa: BLE001 - collect all failures, then report
                failures.append(f"{operation.method.upper()} {operation.path} [{mode.value}]: {exc}"[:2000])
    assert not failures, "\n\n".join(failures)
