"""Who may use each web UI route (tests/web/test_web_access.py checks every entry).

A table of its own so that the API's access test can leave these routes to the web test:
``(method, path) -> (role, scope)``; scope "global", "spacecraft" (the path or form names one),
"list" (results filtered by the key's spacecraft grants).
"""

from __future__ import annotations

PUBLIC = "public"
JSON_ROUTES = ("/ui/jobs/status", "/ui/spacecraft/{name}/viewer/data.json")
"""Routes fetched by the pages' scripts: without a session they answer 401 (JSON), not the sign-in form."""
WEB_ACCESS: dict[tuple[str, str], tuple[str, str]] = {
    ("GET", "/"): (PUBLIC, PUBLIC),
    ("GET", "/ui/static/{name}"): (PUBLIC, PUBLIC),
    ("GET", "/ui/login"): (PUBLIC, PUBLIC),
    ("POST", "/ui/login"): (PUBLIC, PUBLIC),
    ("POST", "/ui/logout"): (PUBLIC, PUBLIC),
    ("GET", "/ui/"): ("viewer", "list"),
    ("GET", "/ui/spacecraft/{name}"): ("viewer", "spacecraft"),
    ("GET", "/ui/spacecraft/{name}/telemetry/{stream}.csv"): ("viewer", "spacecraft"),
    ("POST", "/ui/spacecraft/{name}/upload"): ("operator", "spacecraft"),
    ("GET", "/ui/spacecraft/new"): ("admin", "global"),
    ("POST", "/ui/spacecraft"): ("admin", "global"),
    ("GET", "/ui/spacecraft/{name}/config"): ("viewer", "spacecraft"),
    ("POST", "/ui/spacecraft/{name}/config"): ("admin", "global"),  # admin keys are never restricted
    ("POST", "/ui/spacecraft/{name}/ingests/{ingest_id}/retract"): ("operator", "spacecraft"),
    ("POST", "/ui/spacecraft/{name}/quarantine/{file_id}/restore"): ("admin", "global"),
    ("GET", "/ui/spacecraft/{name}/viewer"): ("viewer", "spacecraft"),
    ("GET", "/ui/spacecraft/{name}/viewer/data.json"): ("viewer", "spacecraft"),
    ("GET", "/ui/spacecraft/{name}/viewer/download.{fmt}"): ("viewer", "spacecraft"),
    ("GET", "/ui/schedules"): ("viewer", "list"),
    ("POST", "/ui/schedules"): ("operator", "global"),
    ("GET", "/ui/schedules/{schedule_id}"): ("viewer", "global"),
    ("POST", "/ui/schedules/{schedule_id}/delete"): ("operator", "global"),
    ("GET", "/ui/spacecraft/{name}/trends"): ("viewer", "spacecraft"),
    ("GET", "/ui/spacecraft/{name}/trends.csv"): ("viewer", "spacecraft"),
    ("GET", "/ui/jobs"): ("viewer", "list"),
    ("GET", "/ui/jobs/status"): ("viewer", "list"),
    ("GET", "/ui/jobs/new"): ("operator", "global"),
    ("POST", "/ui/jobs"): ("operator", "spacecraft"),
    ("GET", "/ui/jobs/{job_id}"): ("viewer", "spacecraft"),
    ("POST", "/ui/jobs/{job_id}/cancel"): ("operator", "spacecraft"),
    ("GET", "/ui/jobs/{job_id}/report"): ("viewer", "spacecraft"),
    ("GET", "/ui/jobs/{job_id}/report.pdf"): ("viewer", "spacecraft"),
    ("GET", "/ui/jobs/{job_id}/report.json"): ("viewer", "spacecraft"),
    ("GET", "/ui/jobs/{job_id}/artifacts/{name}"): ("viewer", "spacecraft"),
}
