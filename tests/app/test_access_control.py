"""Access control of every route, driven by a table: a route missing from ACCESS fails the test.

For each route: no key -> 401; revoked or expired key -> 401; a role below the required one -> 403;
a key granted only spacecraft A gets 404 for spacecraft B's objects (and never sees them in lists).
"""

from __future__ import annotations

import pytest
from fastapi.routing import APIRoute

from tests.app.helpers import issue_keys, make_spacecraft, run_coverage_jobs, upload
from tests.web.access_table import WEB_ACCESS

PUBLIC = "public"
# (method, path) -> (role, scope). scope: "global" (not tied to a spacecraft), "spacecraft" (path or
# body names one: checked for BOLA), "list" (results filtered by the key's grants).
ACCESS: dict[tuple[str, str], tuple[str, str]] = {
    ("GET", "/healthz"): (PUBLIC, PUBLIC),
    ("GET", "/openapi.json"): (PUBLIC, PUBLIC),
    ("GET", "/docs"): (PUBLIC, PUBLIC),
    ("GET", "/docs/oauth2-redirect"): (PUBLIC, PUBLIC),
    ("GET", "/redoc"): (PUBLIC, PUBLIC),
    ("POST", "/api/v1/spacecraft"): ("admin", "global"),
    ("GET", "/api/v1/spacecraft"): ("viewer", "list"),
    ("GET", "/api/v1/spacecraft/{name}"): ("viewer", "spacecraft"),
    ("PUT", "/api/v1/spacecraft/{name}/config"): ("admin", "global"),
    ("POST", "/api/v1/spacecraft/{name}/telemetry/{stream}"): ("operator", "spacecraft"),
    ("GET", "/api/v1/spacecraft/{name}/telemetry/{stream}"): ("viewer", "spacecraft"),
    ("GET", "/api/v1/spacecraft/{name}/ingests"): ("viewer", "spacecraft"),
    ("DELETE", "/api/v1/spacecraft/{name}/ingests/{ingest_id}"): ("operator", "spacecraft"),
    ("GET", "/api/v1/spacecraft/{name}/retractions"): ("viewer", "spacecraft"),
    ("GET", "/api/v1/spacecraft/{name}/quarantine"): ("admin", "spacecraft"),
    ("POST", "/api/v1/spacecraft/{name}/quarantine/{file_id}/restore"): ("admin", "spacecraft"),
    ("GET", "/api/v1/spacecraft/{name}/calibrations"): ("viewer", "spacecraft"),
    ("GET", "/api/v1/spacecraft/{name}/export/oem"): ("viewer", "spacecraft"),
    ("GET", "/api/v1/formats"): ("viewer", "global"),
    ("POST", "/api/v1/keys"): ("admin", "global"),
    ("GET", "/api/v1/keys"): ("admin", "global"),
    ("DELETE", "/api/v1/keys/{key_id}"): ("admin", "global"),
    ("POST", "/api/v1/jobs"): ("operator", "spacecraft"),
    ("GET", "/api/v1/jobs"): ("viewer", "list"),
    ("GET", "/api/v1/jobs/types"): ("viewer", "global"),
    ("GET", "/api/v1/jobs/{job_id}"): ("viewer", "spacecraft"),
    ("POST", "/api/v1/jobs/{job_id}/cancel"): ("operator", "spacecraft"),
    ("GET", "/api/v1/jobs/{job_id}/artifacts"): ("viewer", "spacecraft"),
    ("GET", "/api/v1/jobs/{job_id}/artifacts/{name}"): ("viewer", "spacecraft"),
    ("GET", "/api/v1/jobs/{job_id}/report"): ("viewer", "spacecraft"),
    ("GET", "/api/v1/reference/kinds"): ("viewer", "global"),
    ("POST", "/api/v1/reference/{kind}"): ("operator", "global"),
    ("GET", "/api/v1/reference"): ("viewer", "global"),
    ("GET", "/api/v1/reference/{kind}/{dataset_id}"): ("viewer", "global"),
    ("GET", "/api/v1/reference/{kind}/{dataset_id}/data"): ("viewer", "global"),
    ("DELETE", "/api/v1/reference/{kind}/{dataset_id}"): ("admin", "global"),
    # schedules: per-spacecraft grants are checked in tests/app/test_schedules.py (needs schedules of A and B)
    ("POST", "/api/v1/schedules"): ("operator", "global"),
    ("GET", "/api/v1/schedules"): ("viewer", "list"),
    ("GET", "/api/v1/schedules/{schedule}"): ("viewer", "global"),
    ("GET", "/api/v1/schedules/{schedule}/runs"): ("viewer", "global"),
    ("DELETE", "/api/v1/schedules/{schedule}"): ("operator", "global"),
}
LOWER = {"viewer": None, "operator": "viewer", "admin": "operator"}


def app_routes(client) -> list[tuple[str, str]]:
    """Every (method, path) the app serves, including routes of included routers and hidden ones."""
    routes = []
    for r in client.app.routes:
        if isinstance(r, APIRoute):
            routes += [(m, r.path) for m in sorted(r.methods - {"HEAD", "OPTIONS"})]
        elif hasattr(r, "effective_route_contexts"):  # FastAPI >= 0.16x keeps included routers whole
            for ctx in r.effective_route_contexts():
                routes += [(m, ctx.path) for m in sorted(set(ctx.methods) - {"HEAD", "OPTIONS"})]
        elif getattr(r, "methods", None):
            routes += [(m, r.path) for m in sorted(r.methods - {"HEAD", "OPTIONS"})]
    assert len(routes) > 20, routes
    return routes


@pytest.fixture
def world(client):
    """Spacecraft A and B with telemetry and a finished job each, and keys of every kind."""
    ingests = {}
    for sc in ("A", "B"):
        make_spacecraft(client, sc, {"star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]}}})
        r = upload(client, "gyro", "time,wx,wy,wz\n2023-06-01T00:00:00Z,1,2,3\n2023-06-01T00:00:01Z,1,2,3\n", sc=sc)
        ingests[sc] = r.json()["ingest_id"]
        upload(client, "gnss", "time,x,y,z,vx,vy,vz\n2023-06-01T00:00:00Z,7000000,0,0,0,7500,0\n"
                               "2023-06-01T00:00:01Z,6999996,7500,0,-8,7500,0\n", sc=sc)
    jobs = run_coverage_jobs(client, ("A", "B"))
    keys, key = issue_keys(client, revoked_role="admin")
    keys["expired"] = key("admin", expires_at="2001-01-01T00:00:00Z")["secret"]
    return {"jobs": jobs, "keys": keys, "ingests": ingests}


def fill(path: str, sc: str, world) -> str:
    return (path.replace("{name}/telemetry", f"{sc}/telemetry").replace("spacecraft/{name}", f"spacecraft/{sc}")
            .replace("{stream}", "gyro").replace("{job_id}", world["jobs"][sc])
            .replace("artifacts/{name}", "artifacts/summary.json").replace("{key_id}", "nosuch")
            .replace("{kind}", "nosuch").replace("{dataset_id}", "nosuch").replace("{file_id}", "999999")
            .replace("{ingest_id}", world["ingests"][sc] + "?reason=access%20check"))


def call(client, method, path, secret, sc="A"):
    headers = {"Authorization": f"Bearer {secret}"} if secret else {"Authorization": ""}
    kwargs = {}
    if method == "POST" and path == "/api/v1/jobs":
        kwargs["json"] = {"type": "executor_check", "spacecraft": sc}
    elif method in ("POST", "PUT"):
        kwargs["json"] = {}
    return client.request(method, path, headers=headers, **kwargs)


def test_every_route_has_an_access_rule(client):
    missing = [r for r in app_routes(client) if r not in ACCESS and r not in WEB_ACCESS]
    assert not missing, f"routes without an entry in ACCESS (add one, with its check): {missing}"


def test_authentication_and_roles(client, world):
    keys = world["keys"]
    for method, template in app_routes(client):
        if (method, template) in WEB_ACCESS:  # the web UI's cookie sessions: tests/web/test_web_access.py
            continue
        role, _scope = ACCESS[(method, template)]
        path = fill(template, "A", world)
        if role == PUBLIC:
            assert call(client, method, path, None).status_code < 400, (method, path)
            continue
        for secret in (None, keys["revoked"], keys["expired"], "att_not_a_key"):
            r = call(client, method, path, secret)
            assert r.status_code == 401, (method, path, secret, r.status_code)
        if LOWER[role]:
            r = call(client, method, path, keys[LOWER[role]])
            assert r.status_code == 403, (method, path, r.status_code)
        r = call(client, method, path, keys[role])
        assert r.status_code not in (401, 403), (method, path, r.status_code, r.text)


def test_keys_granted_one_spacecraft_cannot_reach_another(client, world):
    keys = world["keys"]
    for method, template in app_routes(client):
        if (method, template) in WEB_ACCESS:
            continue
        role, scope = ACCESS[(method, template)]
        if scope != "spacecraft" or role == "admin":
            continue
        secret = keys[f"{role}_A"]
        own = call(client, method, fill(template, "A", world), secret, "A")
        assert own.status_code not in (401, 403, 404), (method, template, own.status_code, own.text)
        other = call(client, method, fill(template, "B", world), secret, "B")
        assert other.status_code == 404, (method, template, other.status_code)
        assert "B" not in other.text.replace("Bearer", "") or "not found" in other.text


def test_lists_are_filtered_by_grants(client, world):
    headers = {"Authorization": f"Bearer {world['keys']['viewer_A']}"}
    assert [s["name"] for s in client.get("/api/v1/spacecraft", headers=headers).json()] == ["A"]
    jobs = client.get("/api/v1/jobs", headers=headers).json()
    assert {j["spacecraft"] for j in jobs} == {"A"}
    assert client.get("/api/v1/jobs", params={"spacecraft": "B"}, headers=headers).status_code == 404
    everything = {"Authorization": f"Bearer {world['keys']['viewer']}"}
    assert len(client.get("/api/v1/spacecraft", headers=everything).json()) == 2


def test_admin_keys_cannot_be_restricted_and_unknown_spacecraft_are_refused(client, world):
    assert client.post("/api/v1/keys", json={"name": "x", "role": "admin", "spacecraft": ["A"]}).status_code == 422
    r = client.post("/api/v1/keys", json={"name": "x", "role": "viewer", "spacecraft": ["A", "Z"]})
    assert r.status_code == 422 and "Z" in r.json()["detail"]
    listed = {k["name"]: k for k in client.get("/api/v1/keys").json()}
    assert listed["viewer-1"]["spacecraft"] == ["A"]


ORBIT = "# frame: ITRF\ntime,x,y,z,vx,vy,vz\n" + "".join(
    f"2023-06-01T00:00:0{i}Z,7000000,{7500 * i},0,0,7500,0\n" for i in range(4))


def _as(secret):
    return {"Authorization": f"Bearer {secret}"}


def test_reference_data_follow_spacecraft_grants(client):
    """The red team's case: an operator granted only A uploaded a reference orbit that B's next
    data_screening job picked up. Now: reference data are scoped to a spacecraft the key is granted, and
    only an admin uploads data shared by every spacecraft."""
    for sc in ("A", "B"):
        make_spacecraft(client, sc, {})
        assert upload(client, "gnss", ORBIT.split("\n", 1)[1], sc=sc).status_code == 201
    keys, _ = issue_keys(client)
    op_a = _as(keys["operator_A"])
    post = "/api/v1/reference/reference_orbit"
    r = client.post(post, content=ORBIT.encode(), headers=op_a)  # shared: not for an operator
    assert r.status_code == 403 and "admin" in r.json()["detail"]
    assert client.post(post, content=ORBIT.encode(), params={"spacecraft": "B"}, headers=op_a).status_code == 404
    r = client.post(post, content=ORBIT.encode(), params={"spacecraft": "A"}, headers=op_a)
    assert r.status_code == 201 and r.json()["spacecraft"] == "A"
    own_a = r.json()["id"]
    assert client.get("/api/v1/reference").json()[0]["spacecraft"] == "A"  # admins see everything

    def picked(sc, **extra):
        r = client.post("/api/v1/jobs", json={"type": "data_screening", "spacecraft": sc, **extra})
        return r.status_code, (client.get(f"/api/v1/jobs/{r.json()['id']}").json()["reference"]
                               if r.status_code == 202 else r.json())

    assert picked("A")[1].get("reference_orbit") == own_a
    assert "reference_orbit" not in picked("B")[1]  # B's jobs never pick up A's data
    status, body = picked("B", reference={"reference_orbit": own_a})  # nor when named explicitly
    assert status == 422 and "for B" in body["detail"]
    r = client.post("/api/v1/schedules", json={"name": "b-screen", "cron": "0 2 * * *", "type": "data_screening",
                                               "spacecraft": "B", "reference": {"reference_orbit": own_a}})
    assert r.status_code == 422, r.text

    shared = client.post(post, content=ORBIT.encode()).json()  # the admin's shared data set
    assert shared["spacecraft"] is None
    assert picked("B")[1].get("reference_orbit") == shared["id"]
    # who sees what: B's key never sees A's data set; everyone sees the shared one
    b_viewer = client.post("/api/v1/keys", json={"name": "vb", "role": "viewer", "spacecraft": ["B"]}).json()["secret"]
    seen = {d["id"] for d in client.get("/api/v1/reference", headers=_as(b_viewer)).json()}
    assert seen == {shared["id"]}
    for path in (f"/api/v1/reference/reference_orbit/{own_a}", f"/api/v1/reference/reference_orbit/{own_a}/data"):
        assert client.get(path, headers=_as(b_viewer)).status_code == 404
        assert client.get(path, headers=_as(keys["viewer_A"])).status_code == 200
    assert {d["id"] for d in client.get("/api/v1/reference", headers=_as(keys["viewer_A"])).json()} == {
        own_a, shared["id"]}
