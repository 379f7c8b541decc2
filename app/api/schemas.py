"""The typed OpenAPI document: what FastAPI derives from the routes, made precise where the routes take or
give open JSON (``params``, ``result``, ``config``), with real enums, request examples and the error
answers each route can give.

- ``POST /api/v1/jobs`` takes a ``JobRequest``: a union discriminated on ``type`` whose members carry
  the job type's parameter model (``<Type>Params``; the same models the service validates with).
- Jobs are answered as ``TypedJobOut``: the same union on ``type``, whose ``result`` is the job type's
  declared summary (``<Type>Summary``, app/jobs/results.py: the top-level keys typed, more allowed).
- ``SpacecraftOut.config`` is the ``SpacecraftConfig`` schema (app/config_schema.py).
- Patterns that only list alternatives (``^(utc|tai|gps|tt)$``) are published as enums.
- Each operation lists the error statuses its dependencies and service calls can answer.
The service's validation is unchanged: the schema describes it (schemathesis checks both agree).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Annotated, Any, Literal, Union

from fastapi import FastAPI
from pydantic import BaseModel, Field, TypeAdapter, create_model

REF = "#/components/schemas/{model}"
ENUM_PATTERN = re.compile(r"^\^\(((?:[A-Za-z0-9_\-]|\\\.)+(?:\|(?:[A-Za-z0-9_\-]|\\\.)+)*)\)\$$")

ERROR_TEXT = {
    400: "the body cannot be parsed (e.g. not JSON)",
    401: "missing, invalid, expired or revoked API key",
    403: "the key's role is too low",
    404: "not found (or not visible to this key)",
    409: "conflicts with the stored state (the detail says which)",
    410: "a stored file has gone",
    413: "body or row count above the limits",
    415: "unsupported media type",
    422: "invalid parameters or body: `errors` lists each field (row, column, message)",
    429: "rate limit of the key exceeded (Retry-After)",
    500: "internal error (JSON body; the server log has the details)",
    503: "a damaged telemetry file is in the way (quarantined; the body names it)",
    507: "the telemetry store is full",
}

EXAMPLES: dict[tuple[str, str], dict[str, Any]] = {
    ("post", "/api/v1/spacecraft"): {"application/json": {
        "name": "sat1", "config": {"star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]}}, "gyro": {"q_BG": [1, 0, 0, 0]}}}},
    ("put", "/api/v1/spacecraft/{name}/config"): {"application/json": {
        "star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]},
                          "st2": {"q_BS": [0.7071067811865476, 0.7071067811865476, 0, 0]}},
        "gyro": {"q_BG": [1, 0, 0, 0]}, "inertia_kg_m2": [[51.44, 0, 0], [0, 51.48, 0], [0, 0, 0.76]]}},
    ("post", "/api/v1/spacecraft/{name}/telemetry/{stream}"): {
        "text/csv": "time,wx,wy,wz\n2023-06-01T00:00:00Z,0.0012,-0.0003,0.0001\n"
                    "2023-06-01T00:00:01Z,0.0012,-0.0003,0.0002\n",
        "application/json": [{"time": "2023-06-01T00:00:00Z", "wx": 0.0012, "wy": -0.0003, "wz": 0.0001}]},
    ("post", "/api/v1/keys"): {"application/json": {"name": "pipeline", "role": "operator",
                                                    "expires_at": "2027-01-01T00:00:00Z", "spacecraft": ["sat1"]}},
    ("post", "/api/v1/jobs"): {"application/json": {
        "type": "gyro_bias_fit", "spacecraft": "sat1", "start": "2023-06-01T00:00:00Z",
        "end": "2023-06-02T00:00:00Z", "time_scale": "utc", "params": {}}},
    ("post", "/api/v1/schedules"): {"application/json": {
        "name": "nightly-coverage", "cron": "0 2 * * *", "type": "telemetry_coverage", "spacecraft": "sat1",
        "params": {"gap_factor": 2.0}, "window": "previous", "window_s": 86400}},
    ("post", "/api/v1/reference/{kind}"): {"application/octet-stream": (  # IERS finals2000A, 2 days
        "17 1 1 57754.00 I  0.080504 0.000028  0.263145 0.000028  I 0"
        ".5912821 0.0000077  1.0342 0.0050  I     0.012    0.119    -"
        "0.168    0.018  0.080450  0.263074  0.5912975    -0.019    -0.057\n"
        "17 1 2 57755.00 I  0.080285 0.000029  0.263605 0.000032  I 0"
        ".5901752 0.0000063  1.1730 0.0048  I    -0.001    0.040    -"
        "0.156    0.033  0.080275  0.263595  0.5902149    -0.027    -0.065\n")},
}


def _camel(name: str) -> str:
    return "".join(part.capitalize() for part in name.split("_"))


def _enums(node: Any) -> None:
    """``pattern: ^(a|b)$`` -> ``enum: [a, b]``, everywhere in the document."""
    if isinstance(node, dict):
        pattern = node.get("pattern")
        m = ENUM_PATTERN.match(pattern) if isinstance(pattern, str) else None
        if m:
            del node["pattern"]
            node["enum"] = [alt.replace("\\.", ".") for alt in m.group(1).split("|")]
        for value in node.values():
            _enums(value)
    elif isinstance(node, list):
        for value in node:
            _enums(value)


def _add_union(schema: dict[str, Any], name: str, members: list[type[BaseModel]], description: str,
               mode: Literal["validation", "serialization"]) -> None:
    """A union of models discriminated on ``type`` as component ``name`` (its models beside it)."""
    union: Any = Annotated[Union[tuple(members)], Field(discriminator="type")]  # noqa: UP007 - a runtime tuple
    doc = TypeAdapter(union).json_schema(ref_template=REF, mode=mode)
    components = schema.setdefault("components", {}).setdefault("schemas", {})
    for key, value in doc.pop("$defs", {}).items():
        components.setdefault(key, value)
    components[name] = {**doc, "description": description}


def _job_unions(schema: dict[str, Any]) -> None:
    from app.api.routes.jobs import JobOut
    from app.jobs.registry import registry
    from app.jobs.results import summary_model
    from app.services.jobs import JobCreate

    requests: list[type[BaseModel]] = []
    answers: list[type[BaseModel]] = []
    for name, jt in sorted(registry().items()):
        camel = _camel(name)
        params = create_model(f"{camel}Params", __base__=jt.params, __doc__=f"parameters of {name}: {jt.title}")
        request: dict[str, Any] = {"type": (Literal[name], ...), "params": (params, Field(default_factory=dict))}
        requests.append(create_model(f"{camel}Request", __base__=JobCreate, **request))
        answer: dict[str, Any] = {"type": (Literal[name], ...), "result": (
            summary_model(jt) | None, Field(description=f"the summary of {name} (null until it succeeded)"))}
        answers.append(create_model(f"{camel}Job", __base__=JobOut, **answer))
    _add_union(schema, "JobRequest", requests, "a job request: `params` are those of its `type`", "validation")
    _add_union(schema, "TypedJobOut", answers, "a job: `result` is the summary of its `type`", "serialization")
    ops = schema["paths"]
    ops["/api/v1/jobs"]["post"]["requestBody"]["content"]["application/json"]["schema"] = {"$ref": REF.format(
        model="JobRequest")}
    typed = {"$ref": REF.format(model="TypedJobOut")}
    for path, method in (("/api/v1/jobs/{job_id}", "get"), ("/api/v1/jobs/{job_id}/cancel", "post")):
        ops[path][method]["responses"]["200"]["content"]["application/json"]["schema"] = typed
    listing = ops["/api/v1/jobs"]["get"]["responses"]["200"]["content"]["application/json"]["schema"]
    listing["items"] = typed


def _spacecraft_config(schema: dict[str, Any]) -> None:
    components = schema["components"]["schemas"]
    config = next(k for k in ("SpacecraftConfig-Output", "SpacecraftConfig") if k in components)
    out = components["SpacecraftOut"]["properties"]
    out["config"] = {"$ref": REF.format(model=config), "description": "the configuration of this version"}


# operations whose service calls can refuse with 409 (app/services: already exists, retracted, finished, ...)
CONFLICTS = {("post", "/api/v1/spacecraft"), ("put", "/api/v1/spacecraft/{name}/config"),
             ("post", "/api/v1/spacecraft/{name}/telemetry/{stream}"),
             ("delete", "/api/v1/spacecraft/{name}/ingests/{ingest_id}"),
             ("post", "/api/v1/spacecraft/{name}/quarantine/{file_id}/restore"),
             ("post", "/api/v1/jobs/{job_id}/cancel"), ("post", "/api/v1/schedules")}
RAW_UPLOADS = {("post", "/api/v1/spacecraft/{name}/telemetry/{stream}"), ("post", "/api/v1/reference/{kind}")}


def _statuses(path: str, method: str, op: dict[str, Any]) -> set[int]:
    """The error statuses the operation can answer (its dependencies and its service calls)."""
    if not path.startswith("/api/v1"):
        return set()
    codes = {401, 403, 422, 429, 500}  # key, role, request validation (also unknown query parameters), rate, bugs
    has_body = "requestBody" in op
    if "{" in path or any(p.get("name") in ("spacecraft", "kind") for p in op.get("parameters", [])) or has_body:
        codes.add(404)  # a named spacecraft, job, key, data set, schedule or artifact may not exist (or be hidden)
    if (method, path) in CONFLICTS:
        codes.add(409)
    if has_body:
        codes |= {400, 413}  # 400: a body that is not parsable (e.g. broken JSON)
    if (method, path) in RAW_UPLOADS:
        codes |= {413, 415}  # also gzip bodies inflating beyond the limit, unknown Content-Encoding
    if path.endswith("/telemetry/{stream}") and method == "post":
        codes |= {503, 507}
    if path.endswith("/telemetry/{stream}") and method == "get" or "/export/" in path:
        codes.add(503)
    if path.startswith("/api/v1/spacecraft/{name}/ingests") or path.endswith("/restore"):
        codes |= {503, 507}
    if path.startswith("/api/v1/jobs/{job_id}/artifacts/"):
        codes.add(410)
    if path == "/api/v1/jobs" and method == "post":
        codes.add(503)  # the window's files are read to check the job has samples
    return codes


def _errors(schema: dict[str, Any]) -> None:
    for path, ops in schema["paths"].items():
        for method, op in ops.items():
            codes = _statuses(path, method, op)
            responses = op.setdefault("responses", {})
            for key in [k for k in responses if k.isdigit() and int(k) >= 400]:
                if int(key) not in codes:
                    del responses[key]
            for code in codes:
                entry = responses.setdefault(str(code), {"content": {"application/json": {
                    "schema": {"$ref": REF.format(model="ErrorOut")}}}})
                if entry.get("description") in (None, "", "Error Response", "Unprocessable Content"):
                    entry["description"] = ERROR_TEXT[code]
                entry.setdefault("content", {"application/json": {"schema": {"$ref": REF.format(model="ErrorOut")}}})


def _examples(schema: dict[str, Any]) -> None:
    for (method, path), by_type in EXAMPLES.items():
        op = schema["paths"].get(path, {}).get(method)
        if op is None or "requestBody" not in op:
            continue
        content = op["requestBody"].setdefault("content", {})
        for media_type, example in by_type.items():
            if media_type in content:
                content[media_type]["example"] = example


def typed(schema: dict[str, Any]) -> dict[str, Any]:
    """Make FastAPI's document precise (in place; see the module docstring)."""
    _job_unions(schema)
    _spacecraft_config(schema)
    _enums(schema)
    _errors(schema)
    _examples(schema)
    return schema


def install(app: FastAPI) -> None:
    """Serve the typed document at /openapi.json (and /docs), built once on first use."""
    plain: Callable[[], dict[str, Any]] = app.openapi
    done: list[bool] = []

    def openapi() -> dict[str, Any]:
        schema = plain()
        if not done:
            typed(schema)
            done.append(True)
        return schema

    app.openapi = openapi  # type: ignore[method-assign]
