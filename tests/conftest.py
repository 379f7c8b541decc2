"""Shared fixtures: a catalog on SQLite and, when ATTITUDE_TEST_DATABASE_URL is set, on PostgreSQL.

Each PostgreSQL-backed test gets a schema of its own (created here, dropped afterwards), so runs
never see each other's rows and leave the database clean.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import create_engine, text
from sqlalchemy.engine import make_url

from app.jobs.executor import start_forkserver
from app.main import create_app
from app.settings import Settings

PG_URL = os.environ.get("ATTITUDE_TEST_DATABASE_URL")
ADMIN_TOKEN = "test-admin-token-0123456789"

BACKENDS = ["sqlite", pytest.param("postgresql", marks=pytest.mark.skipif(
    not PG_URL, reason="ATTITUDE_TEST_DATABASE_URL not set"))]


@pytest.fixture(scope="session", autouse=True)
def job_forkserver() -> None:
    """One forkserver for the job processes of every service a test process starts in-process, started
    from the main thread: started from a TestClient's thread it would die with that client, and each
    test's service would pay the job types' import again (app.jobs.executor.start_forkserver)."""
    start_forkserver()


@pytest.fixture(params=BACKENDS)
def database_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'catalog.db'}"
        return
    assert PG_URL is not None
    schema = f"t_{uuid.uuid4().hex[:12]}"
    admin = create_engine(PG_URL)
    with admin.begin() as conn:
        conn.execute(text(f'CREATE SCHEMA "{schema}"'))
    url = make_url(PG_URL).update_query_dict({"options": f"-csearch_path={schema}"})
    try:
        yield url.render_as_string(hide_password=False)
    finally:
        with admin.begin() as conn:
            conn.execute(text(f'DROP SCHEMA IF EXISTS "{schema}" CASCADE'))
        admin.dispose()


@pytest.fixture
def settings(tmp_path: Path, database_url: str) -> Settings:
    # tests make many failed authentications from one address on purpose: throttled only where tested
    return Settings(data_dir=tmp_path / "data", database_url=database_url, bootstrap_token=ADMIN_TOKEN, max_jobs=2,
                    auth_failures_per_minute=100_000, max_jobs_per_key=2)  # per-key slots: where tested


@pytest.fixture
def client(settings: Settings) -> Iterator[TestClient]:
    with TestClient(create_app(settings)) as c:
        c.headers["Authorization"] = f"Bearer {ADMIN_TOKEN}"
        yield c


FIRST = ("tests/app/test_crash_safety.py", "tests/app/test_dask_executor.py", "tests/app/test_schemathesis.py",
         "tests/web/test_ui.py", "tests/app/test_reports.py", "tests/storage/test_concurrent_ingest.py",
         "tests/app/test_schedules.py", "tests/app/test_hostile_corpus.py", "tests/app/test_client.py",
         "tests/app/test_cli.py", "tests/app/test_report_rerun.py")
"""Files that mostly wait (real server processes, clusters, browsers) or build large worlds: scheduled first,
so that under ``--dist loadfile`` they do not end the run alone on one worker while the other idles."""


def pytest_collection_modifyitems(session: pytest.Session, config: pytest.Config, items: list[pytest.Item]) -> None:
    rank = {path: i for i, path in enumerate(FIRST)}
    root = Path(str(config.rootpath))

    def key(item: pytest.Item) -> int:
        try:
            rel = Path(str(item.path)).relative_to(root).as_posix()
        except ValueError:
            return len(FIRST)
        return rank.get(rel, len(FIRST))

    items.sort(key=key)  # stable: the order within a file and among the others is kept
    # ``@pytest.mark.sqlite_only``: the PostgreSQL variant of such a test is deselected
    pg_only_copies = [item for item in items if item.get_closest_marker("sqlite_only") is not None
                      and getattr(item, "callspec", None) is not None
                      and item.callspec.params.get("database_url") == "postgresql"]
    if pg_only_copies:
        config.hook.pytest_deselected(items=pg_only_copies)
        drop = set(map(id, pg_only_copies))
        items[:] = [item for item in items if id(item) not in drop]
