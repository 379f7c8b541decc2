"""Access control of every web UI route, driven by a table: a /ui route missing from WEB_ACCESS fails.

The UI signs in with the API's keys and must enforce the API's rules: without a valid session a page
redirects to the sign-in form (the live-status JSON answers 401); a role below the route's is 403; a key
granted only spacecraft A gets 404 for spacecraft B's objects; forms need the session's token and are
refused cross-site. The session cookie is HttpOnly, SameSite=Lax, limited to /ui, Secure over https.
"""

from __future__ import annotations

import pytest

from app.web.auth import COOKIE, csrf_token
from tests.app.helpers import SQLITE_ONLY, issue_keys, make_spacecraft, run_coverage_jobs, upload
from tests.app.test_access_control import app_routes
from tests.web.access_table import JSON_ROUTES, PUBLIC, WEB_ACCESS

pytestmark = SQLITE_ONLY

GYRO_CSV = "time,wx,wy,wz\n2023-06-01T00:00:00Z,1,2,3\n2023-06-01T00:00:01Z,1,2,3\n"
LOWER = {"viewer": None, "operator": "viewer", "admin": "operator"}


def web_routes(client) -> list[tuple[str, str]]:
    return [(m, p) for m, p in app_routes(client) if p == "/" or p.startswith("/ui")]


@pytest.fixture
def world(client, monkeypatch):
    monkeypatch.setenv("ATTITUDE_CHROMIUM", "/nonexistent/chromium")  # PDFs here need no browser
    for sc in ("A", "B"):
        make_spacecraft(client, sc, {"star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]}}})
        assert upload(client, "gyro", GYRO_CSV, sc=sc).status_code == 201
    jobs = run_coverage_jobs(client, ("A", "B"))
    keys, _ = issue_keys(client, revoked_role="operator")
    return {"jobs": jobs, "keys": keys}


def fill(path: str, sc: str, world) -> str:
    return (path.replace("{name}/telemetry/{stream}", f"{sc}/telemetry/gyro").replace("{stream}", "gyro")
            .replace("spacecraft/{name}", f"spacecraft/{sc}").replace("{job_id}", world["jobs"][sc])
            .replace("artifacts/{name}", "artifacts/coverage.csv").replace("static/{name}", "static/app.css")
            .replace("{fmt}", "csv").replace("{ingest_id}", "nosuch").replace("{file_id}", "999999")
            .replace("{schedule_id}", "nosuch"))


def session_of(client, secret: str) -> str:
    """The session id a sign-in with the key ``secret`` gives (cached per client); for a key that cannot
    sign in (revoked, expired), the key itself, so that the cookie holds something a browser might send."""
    cache = client.__dict__.setdefault("_ui_sessions", {})
    if secret not in cache:
        r = client.post("/ui/login", data={"api_key": secret}, headers={"Authorization": ""}, follow_redirects=False)
        cache[secret] = r.cookies.get(COOKIE) if r.status_code == 303 else secret
        client.cookies.clear()
    return cache[secret]


def call(client, method: str, path: str, secret: str | None, sc: str = "A", token: bool = True, **headers):
    """A browser-like request: the session cookie (no Authorization header) and the form token."""
    h = {"Authorization": "", **headers}
    sid = session_of(client, secret) if secret else None
    if sid:
        h["Cookie"] = f"{COOKIE}={sid}"
    kwargs: dict = {}
    if method == "POST":
        data = {"csrf": csrf_token(sid) if sid and token else ""}
        if path == "/ui/jobs":
            data.update(type="executor_check", spacecraft=sc)
        elif path.endswith("/upload"):
            data.update(stream="gyro")
            kwargs["files"] = {"file": ("gyro.csv", GYRO_CSV.encode(), "text/csv")}
        elif path == "/ui/login":
            data = {"api_key": secret or "", "next": "/ui/"}
        kwargs["data"] = data
    return client.request(method, path, headers=h, follow_redirects=False, **kwargs)


def is_login_redirect(r) -> bool:
    return r.status_code == 303 and r.headers["location"].startswith("/ui/login?next=")


def test_every_web_route_has_an_access_rule(client):
    routes = web_routes(client)
    assert len(routes) >= len(WEB_ACCESS)
    missing = [r for r in routes if r not in WEB_ACCESS]
    assert not missing, f"web routes without an entry in WEB_ACCESS (add one, with its check): {missing}"


def test_sessions_and_roles(client, world):
    keys = world["keys"]
    for method, template in web_routes(client):
        role, _scope = WEB_ACCESS[(method, template)]
        path = fill(template, "A", world)
        if role == PUBLIC:
            r = call(client, method, path, None)
            assert r.status_code < 400 or (path == "/ui/login" and r.status_code == 401), (method, path)
            continue
        for secret in (None, keys["revoked"], "att_not_a_key"):
            r = call(client, method, path, secret)
            if template in JSON_ROUTES:
                assert r.status_code == 401, (method, path, r.status_code)
            else:
                assert is_login_redirect(r), (method, path, secret, r.status_code)
        if LOWER[role]:
            r = call(client, method, path, keys[LOWER[role]])
            assert r.status_code == 403 and "text/html" in r.headers["content-type"], (method, path, r.status_code)
        r = call(client, method, path, keys[role])
        assert r.status_code not in (401, 403) and not is_login_redirect(r), (method, path, r.status_code, r.text)


def test_keys_granted_one_spacecraft_cannot_reach_another(client, world):
    keys = world["keys"]
    for method, template in web_routes(client):
        role, scope = WEB_ACCESS[(method, template)]
        if scope != "spacecraft":
            continue
        secret = keys[f"{role}_A"]
        own = call(client, method, fill(template, "A", world), secret, "A")
        assert own.status_code not in (401, 403, 404), (method, template, own.status_code, own.text)
        other = call(client, method, fill(template, "B", world), secret, "B")
        assert other.status_code == 404, (method, template, other.status_code)


def test_lists_are_filtered_by_grants(client, world):
    secret = world["keys"]["viewer_A"]
    page = call(client, "GET", "/ui/", secret).text
    assert 'href="/ui/spacecraft/A"' in page and 'href="/ui/spacecraft/B"' not in page
    jobs = call(client, "GET", "/ui/jobs", secret).text
    assert world["jobs"]["A"] in jobs and world["jobs"]["B"] not in jobs
    status = call(client, "GET", f"/ui/jobs/status?ids={world['jobs']['A']},{world['jobs']['B']}", secret).json()
    assert list(status) == [world["jobs"]["A"]] and status[world["jobs"]["A"]]["status"] == "succeeded"
    assert call(client, "GET", "/ui/jobs?spacecraft=B", secret).status_code == 404


def test_forms_need_the_session_token_and_same_site(client, world):
    op = world["keys"]["operator"]
    assert call(client, "POST", "/ui/jobs", op, token=False).status_code == 403
    r = call(client, "POST", "/ui/jobs", op, **{"Sec-Fetch-Site": "cross-site"})
    assert r.status_code == 403 and "cross-site" in r.text
    assert call(client, "POST", "/ui/jobs", op, **{"Sec-Fetch-Site": "same-origin"}).status_code == 303
    assert call(client, "POST", "/ui/login", op, **{"Sec-Fetch-Site": "cross-site"}).status_code == 403
    other = world["keys"]["admin"]
    r = client.post("/ui/jobs", headers={"Authorization": "", "Cookie": f"{COOKIE}={session_of(client, op)}"},
                    follow_redirects=False,
                    data={"type": "executor_check", "spacecraft": "A", "csrf": csrf_token(session_of(client, other))})
    assert r.status_code == 403  # another session's token


def test_session_cookie_attributes_and_sign_out(settings):
    from fastapi.testclient import TestClient

    from app.main import create_app

    with TestClient(create_app(settings), base_url="https://testserver") as client:
        r = client.post("/ui/login", data={"api_key": settings.bootstrap_token, "next": "https://evil.example/x"},
                        follow_redirects=False)
        assert r.status_code == 303 and r.headers["location"] == "/ui/"  # no open redirect
        cookie = r.headers["set-cookie"]
        for attribute in ("HttpOnly", "SameSite=lax", "Path=/ui", "Secure"):
            assert attribute.lower() in cookie.lower(), cookie
        assert "expires" not in cookie.lower() and "max-age" not in cookie.lower()  # a session cookie
        r = client.post("/ui/login", data={"api_key": "att_wrong"}, follow_redirects=False)
        assert r.status_code == 401 and "set-cookie" not in r.headers
        r = client.post("/ui/logout", follow_redirects=False)
        assert r.status_code == 303 and 'attitude_session=""' in r.headers["set-cookie"]
    with TestClient(create_app(settings)) as plain:
        r = plain.post("/ui/login", data={"api_key": settings.bootstrap_token}, follow_redirects=False)
        assert "secure" not in r.headers["set-cookie"].lower()


def test_bearer_headers_do_not_open_the_ui(client):
    r = client.get("/ui/", follow_redirects=False)  # the fixture's admin Authorization header alone
    assert is_login_redirect(r)


def test_pages_are_not_cached_and_carry_the_csp(client, world):
    r = call(client, "GET", "/ui/", world["keys"]["viewer"])
    assert r.headers["cache-control"] == "no-store"
    assert "script-src 'self'" in r.headers["content-security-policy"]
    assert '<script src="/ui/static/app.js' in r.text and "<script>" not in r.text


def test_the_session_cookie_is_an_opaque_server_side_session(settings):
    """The cookie holds a random session id, not the key; the session ends on sign-out, on expiry and when
    the key is revoked; a key put into the cookie opens nothing."""
    import datetime as dt

    from fastapi.testclient import TestClient

    from app.main import create_app
    from storage.models import UiSession

    with TestClient(create_app(settings)) as client:
        client.headers["Authorization"] = f"Bearer {settings.bootstrap_token}"
        created = client.post("/api/v1/keys", json={"name": "ui", "role": "viewer"}).json()
        sid = session_of(client, created["secret"])
        assert sid and sid != created["secret"] and created["secret"] not in sid
        assert call(client, "GET", "/ui/", created["secret"]).status_code == 200
        raw = client.get("/ui/", headers={"Authorization": "", "Cookie": f"{COOKIE}={created['secret']}"},
                         follow_redirects=False)
        assert is_login_redirect(raw)  # the key itself is no session
        with client.app.state.sessions() as s:  # only the digest is stored
            stored = [row.token_sha256 for row in s.query(UiSession)]
            assert sid not in stored and len(stored) == 1

        def page_with(token):
            return client.get("/ui/", headers={"Authorization": "", "Cookie": f"{COOKIE}={token}"},
                              follow_redirects=False)

        assert page_with(sid).status_code == 200
        r = client.post("/ui/logout", headers={"Authorization": "", "Cookie": f"{COOKIE}={sid}"},
                        follow_redirects=False)
        assert r.status_code == 303 and is_login_redirect(page_with(sid))  # ended on the server too
        client.cookies.clear()
        client.__dict__.pop("_ui_sessions")
        sid = session_of(client, created["secret"])
        with client.app.state.sessions.begin() as s:  # expiry
            for row in s.query(UiSession):
                row.expires_at = dt.datetime.now(dt.UTC) - dt.timedelta(seconds=1)
        assert is_login_redirect(page_with(sid))
        client.__dict__.pop("_ui_sessions")
        sid = session_of(client, created["secret"])
        assert page_with(sid).status_code == 200
        assert client.delete(f"/api/v1/keys/{created['id']}").status_code == 200  # revocation
        assert is_login_redirect(page_with(sid))
        with client.app.state.sessions() as s:
            assert s.query(UiSession).filter(UiSession.key_id == created["id"]).count() == 0


def test_failed_sign_ins_are_throttled(settings):
    from dataclasses import replace

    from fastapi.testclient import TestClient

    from app.main import create_app

    with TestClient(create_app(replace(settings, auth_failures_per_minute=3))) as client:
        statuses = [client.post("/ui/login", data={"api_key": f"att_guess{i}"}, follow_redirects=False).status_code
                    for i in range(4)]
        assert statuses == [401, 401, 401, 429]
        r = client.post("/ui/login", data={"api_key": settings.bootstrap_token}, follow_redirects=False)
        assert r.status_code == 429 and "set-cookie" not in r.headers
