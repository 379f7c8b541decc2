"""Roles and keys, spacecraft configuration validation and versioning."""

from __future__ import annotations

import pytest

from tests.app.helpers import CONFIG, make_spacecraft, upload

GYRO = "time,wx,wy,wz\n2023-06-01T00:00:00Z,1,2,3\n"


def new_key(client, role: str, **extra) -> str:
    r = client.post("/api/v1/keys", json={"name": f"{role}-key", "role": role, **extra})
    assert r.status_code == 201, r.text
    return r.json()["secret"]


def test_every_api_route_needs_a_key(client):
    anonymous = {"Authorization": ""}
    for method, path in [("get", "/api/v1/spacecraft"), ("post", "/api/v1/spacecraft"),
                         ("get", "/api/v1/spacecraft/x/telemetry/gyro"),
                         ("post", "/api/v1/spacecraft/x/telemetry/gyro"), ("get", "/api/v1/keys"),
                         ("get", "/api/v1/spacecraft/x/ingests")]:
        r = getattr(client, method)(path, headers=anonymous)
        assert r.status_code == 401, (method, path, r.status_code)
        assert r.headers["www-authenticate"] == "Bearer"
    r = client.get("/api/v1/spacecraft", headers={"Authorization": "Bearer att_wrong"})
    assert r.status_code == 401


def test_health_and_docs_are_public(client):
    assert client.get("/healthz", headers={"Authorization": ""}).json()["status"] == "ok"
    assert client.get("/docs", headers={"Authorization": ""}).status_code == 200
    schema = client.get("/openapi.json").json()
    assert "/api/v1/spacecraft/{name}/telemetry/{stream}" in schema["paths"]


def test_roles(client):
    make_spacecraft(client)
    viewer = {"Authorization": f"Bearer {new_key(client, 'viewer')}"}
    operator = {"Authorization": f"Bearer {new_key(client, 'operator')}"}
    assert client.get("/api/v1/spacecraft", headers=viewer).status_code == 200
    r = client.post("/api/v1/spacecraft/sat1/telemetry/gyro", content=GYRO,
                    headers={**viewer, "Content-Type": "text/csv"})
    assert r.status_code == 403 and "operator" in r.json()["detail"]
    r = client.post("/api/v1/spacecraft/sat1/telemetry/gyro", content=GYRO,
                    headers={**operator, "Content-Type": "text/csv"})
    assert r.status_code == 201
    assert client.post("/api/v1/spacecraft", json={"name": "x"}, headers=operator).status_code == 403
    assert client.put("/api/v1/spacecraft/sat1/config", json=CONFIG, headers=operator).status_code == 403
    assert client.get("/api/v1/keys", headers=operator).status_code == 403


def test_revoked_and_expired_keys_are_refused(client):
    secret = new_key(client, "viewer")
    key_id = next(k["id"] for k in client.get("/api/v1/keys").json() if k["name"] == "viewer-key")
    headers = {"Authorization": f"Bearer {secret}"}
    assert client.get("/api/v1/spacecraft", headers=headers).status_code == 200
    assert client.delete(f"/api/v1/keys/{key_id}").json()["revoked_at"] is not None
    assert client.get("/api/v1/spacecraft", headers=headers).status_code == 401
    expired = new_key(client, "viewer", expires_at="2020-01-01T00:00:00Z")
    assert client.get("/api/v1/spacecraft", headers={"Authorization": f"Bearer {expired}"}).status_code == 401
    assert client.post("/api/v1/keys", json={"name": "x", "role": "root"}).status_code == 422
    assert "secret" not in client.get("/api/v1/keys").json()[0]


def test_spacecraft_create_read_version(client):
    make_spacecraft(client)
    assert client.post("/api/v1/spacecraft", json={"name": "sat1"}).status_code == 409
    sc = client.get("/api/v1/spacecraft/sat1").json()
    assert sc["config_version"] == 1 and sc["config"]["star_trackers"]["st1"]["q_BS"] == [1, 0, 0, 0]
    new = {**CONFIG, "star_trackers": {"st1": {"q_BS": [0, 0, 0, -1]}}}
    r = client.put("/api/v1/spacecraft/sat1/config", json=new)
    assert r.status_code == 200 and r.json()["config_version"] == 2
    assert r.json()["config"]["star_trackers"]["st1"]["q_BS"] == [0, 0, 0, 1]  # canonical sign
    assert client.get("/api/v1/spacecraft/sat1?version=1").json()["config_version"] == 1
    assert client.get("/api/v1/spacecraft/sat1?version=7").status_code == 404
    assert [s["name"] for s in client.get("/api/v1/spacecraft").json()] == ["sat1"]
    assert client.get("/api/v1/spacecraft/nosuch").status_code == 404


@pytest.mark.parametrize(
    ("config", "fragment"),
    [
        ({"star_trackers": {"st1": {"q_BS": [1, 0, 0, 0.1]}}}, "norm"),
        ({"star_trackers": {"st1": {"q_BS": [1, 0, 0]}}}, "4 components"),
        ({"star_tracker": {}}, "Extra inputs"),
        ({"inertia_kg_m2": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}, "positive definite"),
        ({"inertia_kg_m2": [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]}, "symmetric"),
        ({"solar_panels": [{"normal_B": [0, 0, 0], "max_current_a": 1}]}, "non-zero"),
        ({"solar_panels": [{"normal_B": [1, 0, 0], "max_current_a": -1}]}, "greater than 0"),
        ({"star_trackers": {"bad name!": {"q_BS": [1, 0, 0, 0]}}}, "must be 1-64"),
    ],
)
def test_bad_configuration_is_422(client, config, fragment):
    r = client.post("/api/v1/spacecraft", json={"name": "sat1", "config": config})
    assert r.status_code == 422
    assert any(fragment in e["message"] for e in r.json()["errors"]), r.json()
    assert client.get("/api/v1/spacecraft").json() == []


def test_bad_spacecraft_name(client):
    assert client.post("/api/v1/spacecraft", json={"name": "a/b"}).status_code == 422


def test_upload_checks_against_current_configuration(client):
    make_spacecraft(client, config={})
    r = upload(client, "star_tracker", "time,q0,q1,q2,q3\n2023-06-01T00:00:00Z,1,0,0,0\n")
    assert r.status_code == 422 and "no star tracker is configured" in r.json()["errors"][0]["message"]


def _near_valid(secret: str) -> list[str]:
    """Authorization values that are almost those of a valid key."""
    return [f"Bearer {secret} ", f"Bearer  {secret}", f"Bearer {secret[:-1]}", f"Bearer {secret}x",
            f"Bearer {secret.upper()}", f"Basic {secret}", secret, f"Bearer {secret}\t", f"Bearer {secret},x"]


def test_authentication_comes_first_on_every_route(client):
    """Over the whole route table, with near-valid tokens and a request that would fail every other check
    (bad content type, unparsable and over-deep body, unknown query parameters, a path that names nothing):
    always 401 (the red team's case: a token with a trailing space on an upload answered 415)."""
    from tests.app.test_access_control import app_routes

    make_spacecraft(client)
    secret = new_key(client, "admin")
    routes = [(m, p) for m, p in app_routes(client) if p.startswith("/api/")]
    assert len(routes) > 30
    body = b"[" * 5000 + b"\xff"
    checked = 0
    for method, path in routes:
        filled = (path.replace("{name}", "sat1").replace("{stream}", "gyro").replace("{job_id}", "nosuch")
                  .replace("{kind}", "eop").replace("{dataset_id}", "x").replace("{key_id}", "x")
                  .replace("{ingest_id}", "x").replace("{file_id}", "x").replace("{schedule}", "x"))
        for value in _near_valid(secret):
            r = client.request(method, filled, content=body, params={"bogus": "1", "cursor": "!!"},
                               headers={"Authorization": value, "Content-Type": "text/plain",
                                        "Content-Encoding": "br"})
            assert r.status_code == 401, (method, path, value, r.status_code, r.text[:200])
            assert r.json()["detail"] and r.headers["www-authenticate"] == "Bearer"
            checked += 1
    assert checked == len(routes) * len(_near_valid(secret))
    r = client.post("/api/v1/spacecraft/sat1/telemetry/gyro", content=b"x",
                    headers={"Authorization": f"Bearer {secret}", "Content-Type": "text/plain"})
    assert r.status_code == 415  # the same request with the exact key gets as far as its content type
    assert client.get("/api/v1/spacecraft/sat1/ingests").json() == []


def test_failed_authentications_are_throttled_per_address(settings):
    from dataclasses import replace

    from fastapi.testclient import TestClient

    from app.main import create_app

    app = create_app(replace(settings, auth_failures_per_minute=5))
    with TestClient(app) as client, TestClient(app, client=("10.0.0.2", 5000)) as other:
        good = {"Authorization": f"Bearer {settings.bootstrap_token}"}
        statuses = [client.get("/api/v1/spacecraft", headers={"Authorization": f"Bearer att_guess{i}"}).status_code
                    for i in range(7)]
        assert statuses[:5] == [401] * 5 and statuses[5:] == [429, 429]
        r = client.get("/api/v1/spacecraft", headers=good)  # while throttled, even a valid key is not looked at
        assert r.status_code == 429 and int(r.headers["retry-after"]) >= 1 and "failed authentications" in r.text
        assert other.get("/api/v1/spacecraft", headers=good).status_code == 200  # another address is not
        assert client.get("/api/v1/spacecraft", headers={"Authorization": ""}).status_code == 429
