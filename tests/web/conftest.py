"""Browser tests: the real service in a child process, driven by Debian's headless Chromium via Selenium.

Debian's ``chromium`` and ``chromium-driver`` must be installed (`.ci/run` installs them); without them
the tests skip with the install command. Nothing is downloaded by Selenium: it
is pointed at /usr/bin/chromium and /usr/bin/chromedriver. Screenshots are kept under
var/test-output/web/ (or $ATTITUDE_TEST_OUTPUT/web/).
"""

from __future__ import annotations

import secrets
import shutil
import tempfile
import types
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from app.client import ApiClient
from app.devserver import running_server
from tests.app.report_world import (
    DURATION_S,
    SPACECRAFT,
    START,
    missing_tools,
    output_dir,
    report_world,
)

CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--disable-dev-shm-usage", "--window-size=1366,860")
UPLOADED_IN_BROWSER = "gnss"  # the stream the upload test sends through the form ...
UPLOAD_TARGET = "other-sat"  # ... to a spacecraft of its own (the simulated one has all its streams)


@pytest.fixture(scope="session")
def browser_tools() -> None:
    reason = missing_tools({"chromium": "chromium", "chromedriver": "chromium-driver"})
    if reason:
        pytest.skip(reason)
    pytest.importorskip("selenium", reason="selenium is a dev dependency: pip install -e '.[dev]'")


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory, browser_tools: None) -> Iterator[types.SimpleNamespace]:
    """One server for the module: a simulated spacecraft with every job type run once, keys of each role."""
    shared = report_world(tmp_path_factory, "web")
    root = shared.data_dir.parent
    token = "web-admin-" + secrets.token_urlsafe(12)
    env = {"ATTITUDE_DATA_DIR": str(shared.data_dir), "ATTITUDE_BOOTSTRAP_TOKEN": token,
           "ATTITUDE_DATABASE_URL": "", "ATTITUDE_MAX_JOBS": "2", "ATTITUDE_SCHEDULER": "0",
           "ATTITUDE_MAX_JOBS_PER_KEY": "2"}  # the browser tests share one admin key
    with running_server(env, log_path=root / "server.log") as base:
        api = ApiClient(base, token)
        api.post("/api/v1/spacecraft", {"name": UPLOAD_TARGET, "config": {}})
        thirds = [START + int(i * DURATION_S / 3 * 1e9) for i in range(4)]
        trend_jobs = [api.post("/api/v1/jobs", {"type": "telemetry_coverage", "spacecraft": SPACECRAFT,
                                                "start": a / 1e9, "end": b / 1e9, "time_scale": "tai"})["id"]
                      for a, b in zip(thirds, thirds[1:], strict=False)]
        finished = shared.jobs
        for job_id in trend_jobs:
            assert api.wait_for_job(job_id, timeout_s=300)["status"] == "succeeded"
        keys = {role: api.post("/api/v1/keys", {"name": f"web-{role}", "role": role})["secret"]
                for role in ("viewer", "operator")}
        yield types.SimpleNamespace(base=base, api=api, admin=token, keys=keys, jobs=finished,
                                    sim=shared.sim, spacecraft=sorted([*shared.worlds, UPLOAD_TARGET]), root=root)


@pytest.fixture(scope="module")
def browser(service: types.SimpleNamespace) -> Iterator[Any]:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    profile = tempfile.mkdtemp(prefix="attitude-web-profile-")
    options.add_argument(f"--user-data-dir={profile}")
    driver = webdriver.Chrome(options=options,
                              service=Service(shutil.which("chromedriver") or "/usr/bin/chromedriver"))
    driver.set_page_load_timeout(60)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def screenshot(driver: Any, name: str, full_page: bool = True) -> Path:
    """Save a PNG of the page (the whole page height when ``full_page``) under the test output dir."""
    path = output_dir("web") / f"{name}.png"
    size = driver.get_window_size()
    if full_page:
        height = int(driver.execute_script("return document.documentElement.scrollHeight"))
        driver.set_window_size(size["width"], min(max(height + 120, size["height"]), 9000))
    driver.save_screenshot(str(path))
    if full_page:
        driver.set_window_size(size["width"], size["height"])
    return path
