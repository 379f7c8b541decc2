"""The typed OpenAPI document (app/api/schemas.py): job params and results as unions on ``type``, the
spacecraft configuration, enums, request examples, per-route errors; and each job type's declared result
schema checked against what the job returns on simulated data (the report world: every job type run once)."""

from __future__ import annotations

import json
import re
from typing import Any

import jsonschema
import pytest
from fastapi.testclient import TestClient

from app.jobs.registry import registry
from app.jobs.results import summary_model
from app.main import create_app
from app.settings import Settings
from tests.app.report_world import report_world

TOKEN = "openapi-test-admin-token-0123456789"


@pytest.fixture(scope="module")
def doc(tmp_path_factory) -> dict[str, Any]:
    data = tmp_path_factory.mktemp("openapi")
    settings = Settings(data_dir=data, database_url=f"sqlite:///{data / 'catalog.db'}", bootstrap_token=TOKEN)
    with TestClient(create_app(settings)) as client:
        schema: dict[str, Any] = client.get("/openapi.json").json()
        assert client.get("/openapi.json").json() == schema  # built once, stable
        return schema


def validator(doc: dict[str, Any], component: str) -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator({"$ref": f"#/components/schemas/{component}",
                                            "components": doc["components"]})


def operations(doc: dict[str, Any]):
    for path, ops in doc["paths"].items():
        for method, op in ops.items():
            yield path, method, op


def test_job_params_are_a_union_on_type(doc):
    union = doc["components"]["schemas"]["JobRequest"]
    body = doc["paths"]["/api/v1/jobs"]["post"]["requestBody"]["content"]["application/json"]["schema"]
    assert body == {"$ref": "#/components/schemas/JobRequest"}
    assert union["discriminator"]["propertyName"] == "type"
    assert set(union["discriminator"]["mapping"]) == set(registry())
    check = validator(doc, "JobRequest")
    assert check.is_valid({"type": "telemetry_coverage", "spacecraft": "s", "params": {"gap_factor": 2.0}})
    # each member carries its type's parameter model: bounds and unknown names are schema errors
    assert not check.is_valid({"type": "telemetry_coverage", "spacecraft": "s", "params": {"gap_factor": 0.5}})
    assert not check.is_valid({"type": "telemetry_coverage", "spacecraft": "s", "params": {"gap_factr": 2.0}})
    assert not check.is_valid({"type": "no_such_type", "spacecraft": "s"})
    assert not check.is_valid({"type": "telemetry_coverage", "spacecraft": "s", "time_scale": "utc1"})
    for name, jt in registry().items():
        member = doc["components"]["schemas"][union["discriminator"]["mapping"][name].rsplit("/", 1)[1]]
        params = doc["components"]["schemas"][member["properties"]["params"]["$ref"].rsplit("/", 1)[1]]
        assert set(params.get("properties", {})) == set(jt.params.model_fields), name


def test_jobs_are_answered_as_a_union_with_typed_results(doc):
    typed = {"$ref": "#/components/schemas/TypedJobOut"}
    paths = doc["paths"]
    assert paths["/api/v1/jobs/{job_id}"]["get"]["responses"]["200"]["content"]["application/json"]["schema"] == typed
    assert paths["/api/v1/jobs"]["get"]["responses"]["200"]["content"]["application/json"]["schema"]["items"] == typed
    union = doc["components"]["schemas"]["TypedJobOut"]
    assert set(union["discriminator"]["mapping"]) == set(registry())
    coverage = doc["components"]["schemas"]["TelemetryCoverageSummary"]
    assert {"streams", "n_gaps", "warnings"} <= set(coverage["properties"])
    warning = doc["components"]["schemas"]["WarningOut"]
    assert warning["properties"]["code"]["$ref"].endswith("/WarningCode")
    from processing.tasks import WARNING_CODES

    assert set(doc["components"]["schemas"]["WarningCode"]["enum"]) == set(WARNING_CODES)


def test_spacecraft_config_is_typed(doc):
    config = doc["components"]["schemas"]["SpacecraftOut"]["properties"]["config"]
    assert config["$ref"].rsplit("/", 1)[1].startswith("SpacecraftConfig")
    check = validator(doc, "SpacecraftOut")
    out = {"name": "s", "created_at": "2023-01-01T00:00:00Z", "config_version": 1,
           "config_created_at": "2023-01-01T00:00:00Z", "config": {"star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]}}}}
    assert check.is_valid(out)
    assert not check.is_valid({**out, "config": {"star_trackrs": {}}})


def test_enums_not_patterns(doc):
    text = json.dumps(doc)
    assert not re.search(r'"pattern": "\^\(\w+(\|\w+)+\)\$"', text)
    params = {p["name"]: p["schema"] for p in
              doc["paths"]["/api/v1/spacecraft/{name}/telemetry/{stream}"]["get"]["parameters"]}
    assert params["format"]["enum"] == ["csv", "parquet", "arrow", "json"]
    assert params["time_scale"]["enum"] == ["utc", "tai", "gps", "tt"]
    oem = {p["name"]: p["schema"] for p in doc["paths"]["/api/v1/spacecraft/{name}/export/oem"]["get"]["parameters"]}
    assert oem["version"]["enum"] == ["2.0", "3.0"] and oem["frame"]["enum"] == ["ITRF", "GCRF", "EME2000"]
    assert doc["components"]["schemas"]["KeyCreate"]["properties"]["role"]["enum"] == ["viewer", "operator", "admin"]


def test_every_request_body_has_an_example_that_fits(doc):
    bodies = [(path, method, op["requestBody"]) for path, method, op in operations(doc) if "requestBody" in op]
    assert len(bodies) >= 7
    for path, method, body in bodies:
        examples = {t: c["example"] for t, c in body["content"].items() if "example" in c}
        assert examples, f"{method.upper()} {path} has no example"
        schema = body["content"].get("application/json", {}).get("schema")
        if "application/json" in examples and "$ref" in (schema or {}):
            component = schema["$ref"].rsplit("/", 1)[1]
            errors = list(validator(doc, component).iter_errors(examples["application/json"]))
            assert not errors, (path, [e.message for e in errors])


def test_error_responses_follow_the_route(doc):
    for path, method, op in operations(doc):
        codes = {int(c) for c in op["responses"] if int(c) >= 400}
        if path.startswith("/api/v1"):
            assert {401, 403, 422, 429} <= codes, (method, path)
            if method == "get":
                assert not codes & {400, 409, 413, 415}, (method, path, codes)
        else:
            assert not codes & {401, 403}, path
        for code in codes:
            assert op["responses"][str(code)]["description"], (method, path, code)
    upload = doc["paths"]["/api/v1/spacecraft/{name}/telemetry/{stream}"]["post"]["responses"]
    assert {"404", "409", "413", "415", "422"} <= set(upload)
    assert "404" not in doc["paths"]["/api/v1/formats"]["get"]["responses"]


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return report_world(tmp_path_factory, "openapi-world")


def test_declared_results_match_what_each_job_returns(world, doc):
    """Every job type of the report world: the job as the API answers it validates against TypedJobOut,
    and every top-level key of its summary is declared in its result model (typed, not left to 'extra')."""
    check = validator(doc, "TypedJobOut")
    jobs = registry()
    assert set(world.jobs) == set(world.where) and world.where
    for name, job in world.jobs.items():
        assert job["status"] == "succeeded", (name, job.get("error"))
        errors = [f"{'/'.join(map(str, e.absolute_path))}: {e.message[:200]}" for e in check.iter_errors(job)]
        assert not errors, (name, errors[:5])
        declared = set(summary_model(jobs[name]).model_fields)
        undeclared = sorted(set(job["result"]) - declared)
        assert not undeclared, f"{name}: summary keys without a declared type (app/jobs/results.py): {undeclared}"
        summary_model(jobs[name]).model_validate(job["result"])
    # a wrong type for a declared key, an unknown warning code, a result under another type: caught
    job = world.jobs["telemetry_coverage"]
    assert not check.is_valid({**job, "result": {**job["result"], "n_gaps": "three"}})
    assert not check.is_valid({**job, "result": {**job["result"], "warnings": [
        {"code": "no_such_code", "message": "m", "evidence": {}}]}})
    assert not check.is_valid({**job, "type": "gyro_bias_fit", "result": {**job["result"], "converged": "yes"}})
    assert not check.is_valid({**job, "status": "finished"})
