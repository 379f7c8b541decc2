"""The web UI in a real browser (headless Chromium): every page type, figures, links, upload, live jobs.

One server and one browser for the module (tests/web/conftest.py); the tests run in file order and
build on each other only through the data they leave (an upload, a job).
"""

from __future__ import annotations

import csv
import json
import re
import urllib.parse
from typing import Any

import numpy as np
import pytest

from tests.app.report_world import SPACECRAFT, all_type_names, png_ink_fraction
from tests.web.conftest import UPLOAD_TARGET, UPLOADED_IN_BROWSER, screenshot

pytest.importorskip("selenium")
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.support.ui import Select, WebDriverWait  # noqa: E402

WAIT_S = 60


def wait_for(driver: Any, condition: Any, timeout_s: float = WAIT_S) -> Any:
    return WebDriverWait(driver, timeout_s, poll_frequency=0.1).until(condition)


def sign_in(driver: Any, service: Any, role: str, next_path: str = "/ui/") -> None:
    driver.delete_all_cookies()
    driver.get(service.base + next_path)
    wait_for(driver, lambda d: "/ui/login" in d.current_url)
    field = driver.find_element(By.ID, "api_key")
    field.clear()
    field.send_keys(service.admin if role == "admin" else service.keys[role])
    driver.find_element(By.CSS_SELECTOR, "form button[type=submit]").click()
    wait_for(driver, lambda d: "/ui/login" not in d.current_url)


def images(driver: Any) -> list[dict[str, Any]]:
    """Every <img> with whether it decoded and its natural size."""
    return driver.execute_script(
        "return Array.from(document.images).map(i => ({alt: i.alt, complete: i.complete, "
        "w: i.naturalWidth, h: i.naturalHeight, shown: i.getBoundingClientRect().width}))")


def fetch(driver: Any, url: str) -> dict[str, Any]:
    """GET ``url`` from the page (the session cookie goes along): status, type, disposition, first bytes."""
    return driver.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "fetch(arguments[0], {credentials: 'same-origin'}).then(async r => {"
        " const b = new Uint8Array(await r.arrayBuffer());"
        " done({status: r.status, type: r.headers.get('content-type'),"
        "       disposition: r.headers.get('content-disposition'), size: b.length,"
        "       head: String.fromCharCode(...b.slice(0, 8)), text: new TextDecoder().decode(b.slice(0, 4000))});"
        "}).catch(e => done({status: -1, error: String(e)}));", url)


def test_sign_in_is_required_and_bad_keys_are_refused(browser, service):
    browser.delete_all_cookies()
    browser.get(service.base + "/")
    wait_for(browser, lambda d: "/ui/login" in d.current_url)
    assert browser.find_element(By.CSS_SELECTOR, "label[for=api_key]").text == "API key"
    browser.find_element(By.ID, "api_key").send_keys("att_not_a_key")
    browser.find_element(By.CSS_SELECTOR, "form button[type=submit]").click()
    alert = wait_for(browser, lambda d: d.find_element(By.ID, "login-error"))
    assert "not valid" in alert.text
    screenshot(browser, "01_login_refused")
    cookies = {c["name"]: c for c in browser.get_cookies()}
    assert "attitude_session" not in cookies
    sign_in(browser, service, "operator")
    cookie = {c["name"]: c for c in browser.get_cookies()}["attitude_session"]
    assert cookie["httpOnly"] is True and cookie["sameSite"] == "Lax" and cookie["path"] == "/ui"
    assert browser.execute_script("return document.cookie") == ""  # not readable by scripts


def test_spacecraft_list_and_coverage_timeline(browser, service):
    sign_in(browser, service, "viewer")
    assert browser.find_element(By.TAG_NAME, "h1").text == "Spacecraft"
    names = [a.text for a in browser.find_elements(By.CSS_SELECTOR, "main table a[href^='/ui/spacecraft/']")]
    assert names == service.spacecraft
    screenshot(browser, "02_spacecraft_list")
    browser.find_element(By.LINK_TEXT, SPACECRAFT).click()
    wait_for(browser, lambda d: d.find_element(By.ID, "coverage-timeline"))
    svg = browser.find_element(By.ID, "coverage-timeline")
    assert svg.size["width"] > 800 and svg.size["height"] > 60
    spans = browser.find_elements(By.CSS_SELECTOR, "#coverage-timeline rect.tl-span")
    gaps = browser.find_elements(By.CSS_SELECTOR, "#coverage-timeline rect.tl-gap")
    streams = list(service.sim.streams)
    assert len(spans) >= len(streams) and all(r.size["width"] > 0 for r in spans)
    truth_gaps = len(service.sim.truth.st_gap_intervals_tai_ns)
    assert len(gaps) >= truth_gaps > 0  # gaps inside the upload, from the coverage job
    rows = browser.find_elements(By.CSS_SELECTOR, "#coverage-table tr")[1:]
    assert sorted(r.find_elements(By.TAG_NAME, "td")[0].text for r in rows) == sorted(streams)
    assert not browser.find_elements(By.ID, "upload-form")  # viewers do not get the upload form
    screenshot(browser, "03_spacecraft_timeline")


def _gnss_csv(service: Any, path: Any) -> int:
    cols = service.sim.streams[UPLOADED_IN_BROWSER]
    times = iso_array(cols["time_tai_ns"])
    names = [c for c in cols if c not in ("time_tai_ns", "sensor")]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time", *names])
        for i, t in enumerate(times):
            w.writerow([t, *(repr(float(cols[c][i])) for c in names)])
    return len(times)


def iso_array(tai_ns: Any) -> list[str]:
    from processing.time import timescales

    return [str(s) for s in timescales.tai_ns_to_iso(np.asarray(tai_ns, dtype=np.int64))]


def test_upload_through_the_form(browser, service, tmp_path):
    sign_in(browser, service, "operator", f"/ui/spacecraft/{UPLOAD_TARGET}")
    assert browser.find_element(By.CSS_SELECTOR, "#coverage-h + form + p").text == "No telemetry."
    bad = tmp_path / "bad_gnss.csv"
    bad.write_text("time,x,y,z,vx,vy,vz\n2023-06-01T00:00:00Z,1,2,3,4,5\n")
    Select(browser.find_element(By.ID, "up-stream")).select_by_value(UPLOADED_IN_BROWSER)
    browser.find_element(By.ID, "up-file").send_keys(str(bad))
    browser.find_element(By.CSS_SELECTOR, "#upload-form button[type=submit]").click()
    error = wait_for(browser, lambda d: d.find_element(By.ID, "upload-error"))
    assert "nothing stored" in error.text
    assert browser.find_elements(By.CSS_SELECTOR, "table.wide tr td")  # the rows that failed
    screenshot(browser, "04_upload_rejected")
    browser.find_element(By.PARTIAL_LINK_TEXT, "Back to").click()

    good = tmp_path / "gnss_pass.csv"
    n = _gnss_csv(service, good)
    wait_for(browser, lambda d: d.find_element(By.ID, "up-stream"))
    Select(browser.find_element(By.ID, "up-stream")).select_by_value(UPLOADED_IN_BROWSER)
    browser.find_element(By.ID, "up-file").send_keys(str(good))
    browser.find_element(By.CSS_SELECTOR, "#upload-form button[type=submit]").click()
    ok = wait_for(browser, lambda d: d.find_element(By.ID, "upload-ok"))
    assert f"{n} rows, {n} new, 0 already stored" in ok.text and "gnss_pass.csv" in ok.text
    labels = [t.text for t in browser.find_elements(By.CSS_SELECTOR, "#coverage-timeline text.tl-label")]
    assert f"{UPLOADED_IN_BROWSER} / {UPLOADED_IN_BROWSER}" in labels
    screenshot(browser, "05_uploaded")
    stored = service.api.get(f"/api/v1/spacecraft/{UPLOAD_TARGET}/ingests", params={"stream": UPLOADED_IN_BROWSER})
    assert [(i["rows"], i["filename"]) for i in stored] == [(n, "gnss_pass.csv")]


def test_run_a_job_from_the_form_and_watch_it_finish(browser, service):
    sign_in(browser, service, "operator", "/ui/jobs/new")
    Select(browser.find_element(By.ID, "j-type")).select_by_value("executor_check")
    Select(browser.find_element(By.ID, "j-sc")).select_by_value(SPACECRAFT)
    params = browser.find_element(By.ID, "j-params")
    params.clear()
    params.send_keys('{"duration_s": 6}')
    browser.find_element(By.CSS_SELECTOR, "#job-form button[type=submit]").click()
    wait_for(browser, lambda d: re.search(r"/ui/jobs/[0-9a-f]{32}$", d.current_url))
    job_id = browser.current_url.rsplit("/", 1)[1]
    # live updates without reloading: the status turns to running and the bar moves
    wait_for(browser, lambda d: d.find_element(By.CSS_SELECTOR, ".js-status").text == "running"
             and float(d.find_element(By.CSS_SELECTOR, ".js-progress").get_attribute("value")) > 0)
    screenshot(browser, "06_job_running", full_page=False)
    link = wait_for(browser, lambda d: d.find_elements(By.ID, "report-link"), timeout_s=120)[0]
    assert browser.find_element(By.CSS_SELECTOR, ".js-status").text == "succeeded"
    screenshot(browser, "07_job_succeeded")
    link.click()
    wait_for(browser, lambda d: d.current_url.endswith(f"/ui/jobs/{job_id}/report"))
    assert "Executor check" in browser.find_element(By.TAG_NAME, "h1").text


def test_jobs_list_shows_status_and_links(browser, service):
    sign_in(browser, service, "viewer", f"/ui/jobs?spacecraft={SPACECRAFT}")
    rows = browser.find_elements(By.CSS_SELECTOR, "tr[data-job]")
    own = [j for j in service.jobs.values() if j["spacecraft"] == SPACECRAFT]
    assert len(rows) >= len(own)
    statuses = {r.get_attribute("data-job"): r.find_element(By.CSS_SELECTOR, ".js-status").text for r in rows}
    for job in own:
        assert statuses[job["id"]] == job["status"] == "succeeded"
    Select(browser.find_element(By.ID, "f-type")).select_by_value("telemetry_coverage")
    browser.find_element(By.CSS_SELECTOR, "form[aria-label='Filter jobs'] button").click()
    wait_for(browser, lambda d: "type=telemetry_coverage" in d.current_url)
    shown = {r.find_element(By.CSS_SELECTOR, "td:nth-child(2) a").text
             for r in browser.find_elements(By.CSS_SELECTOR, "tr[data-job]")}
    assert shown == {"telemetry_coverage"}
    assert {r.find_element(By.CSS_SELECTOR, "td:nth-child(3)").text
            for r in browser.find_elements(By.CSS_SELECTOR, "tr[data-job]")} == {SPACECRAFT}
    screenshot(browser, "08_jobs")


@pytest.mark.parametrize("job_type", [t for t in all_type_names() if t != "executor_check"])
def test_report_page_of_every_job_type(browser, service, job_type):
    if job_type not in service.jobs:
        pytest.skip(f"{job_type} needs streams the simulation does not provide")
    job = service.jobs[job_type]
    assert job["status"] == "succeeded", job["error"]
    sign_in(browser, service, "viewer", f"/ui/jobs/{job['id']}")
    browser.find_element(By.ID, "report-link").click()
    wait_for(browser, lambda d: d.current_url.endswith("/report"))
    n_figures = len([a for a in service.api.get(f"/api/v1/jobs/{job['id']}/artifacts") if a["kind"] == "figure"])
    imgs = images(browser)
    assert len(imgs) >= n_figures
    assert all(i["complete"] and i["w"] > 0 and i["h"] > 0 and i["shown"] > 0 for i in imgs), imgs
    path = screenshot(browser, f"10_report_{job_type}")
    assert png_ink_fraction(path) > 0.01
    downloads = [a.get_attribute("href") for a in browser.find_elements(By.CSS_SELECTOR, "#tables ~ div a")]
    rerun = browser.find_element(By.ID, "rerun-link").get_attribute("href")
    browser.find_element(By.LINK_TEXT, "← Job").click()  # the report's own CSP allows no fetch(): go back
    wait_for(browser, lambda d: d.current_url.endswith(f"/ui/jobs/{job['id']}"))
    if job_type == "star_tracker_accuracy":  # the download with the session; every type's PDF: test_reports
        pdf = fetch(browser, f"/ui/jobs/{job['id']}/report.pdf")
        assert pdf["status"] == 200 and pdf["type"] == "application/pdf" and pdf["head"].startswith("%PDF-")
        assert pdf["size"] > 10_000
    for href in downloads[:2]:  # table downloads work with the session
        got = fetch(browser, href)
        assert got["status"] == 200 and got["disposition"].startswith("attachment"), got
    # the report links back to its exact window and parameters: the run form comes prefilled
    browser.get(rerun)
    wait_for(browser, lambda d: "/ui/jobs/new" in d.current_url)
    sign_in(browser, service, "operator", urllib.parse.urlsplit(browser.current_url).path + "?"
            + urllib.parse.urlsplit(browser.current_url).query)
    assert Select(browser.find_element(By.ID, "j-type")).first_selected_option.get_attribute("value") == job_type
    assert browser.find_element(By.ID, "j-start").get_attribute("value") == job["start"]
    assert browser.find_element(By.ID, "j-end").get_attribute("value") == job["end"]
    assert json.loads(browser.find_element(By.ID, "j-params").get_attribute("value")) == job["params"]


def test_input_window_link_zooms_the_timeline(browser, service):
    job = service.jobs["telemetry_coverage"]
    sign_in(browser, service, "viewer", f"/ui/jobs/{job['id']}")
    browser.find_element(By.LINK_TEXT, "Input window on the coverage timeline").click()
    wait_for(browser, lambda d: d.find_element(By.ID, "coverage-timeline"))
    assert browser.find_element(By.ID, "view-start").get_attribute("value") == job["start"]
    assert browser.find_element(By.ID, "view-end").get_attribute("value") == job["end"]
    desc = browser.find_element(By.ID, "tl-desc").get_attribute("textContent")
    assert f"From {job['start']} to {job['end']}" in desc


def test_trends_page(browser, service):
    sign_in(browser, service, "viewer", f"/ui/spacecraft/{SPACECRAFT}/trends")
    Select(browser.find_element(By.ID, "t-type")).select_by_value("telemetry_coverage")
    browser.find_element(By.CSS_SELECTOR, "form[aria-label='Choose trends'] button").click()
    wait_for(browser, lambda d: "type=telemetry_coverage" in d.current_url)
    imgs = images(browser)
    assert imgs and all(i["complete"] and i["w"] > 0 for i in imgs)
    assert any("n_gaps" in i["alt"] for i in imgs)
    screenshot(browser, "11_trends_coverage")
    got = fetch(browser, browser.find_element(By.LINK_TEXT, "CSV").get_attribute("href"))
    assert got["status"] == 200 and got["text"].startswith("job_id,job_type,series,window_start")
    browser.get(service.base + f"/ui/spacecraft/{SPACECRAFT}/trends")  # key metrics
    if {"star_tracker_accuracy", "gyro_bias_fit"} & set(service.jobs):
        assert all(i["complete"] and i["w"] > 0 for i in images(browser)) and images(browser)
    else:
        assert browser.find_element(By.ID, "no-trends")
    screenshot(browser, "12_trends_key_metrics")


def test_viewers_cannot_upload_or_run_jobs(browser, service):
    sign_in(browser, service, "viewer", "/ui/jobs/new")
    assert "Not allowed" in browser.find_element(By.TAG_NAME, "h1").text
    assert "operator" in browser.find_element(By.CSS_SELECTOR, "[role=alert]").text
    assert not browser.find_elements(By.LINK_TEXT, "Run a job")
    screenshot(browser, "13_viewer_forbidden", full_page=False)


def test_sign_out(browser, service):
    sign_in(browser, service, "operator")
    browser.find_element(By.CSS_SELECTOR, "header form button").click()
    wait_for(browser, lambda d: "/ui/login" in d.current_url)
    browser.get(service.base + "/ui/jobs")
    wait_for(browser, lambda d: "/ui/login" in d.current_url)


# --- issue 20: headline, viewer, retraction, spacecraft and schedules, run form --------------------------

DAY_SAT = "day-sat"
DAY_SAMPLES = 864_000  # a day of 10 Hz
FIRST_PLOT_BUDGET_MS = 2000.0


def viewer_ready(driver: Any, fetches: int = 1, timeout_s: float = WAIT_S) -> dict[str, Any]:
    wait_for(driver, lambda d: int(d.find_element(By.ID, "viewer").get_attribute("data-ready") or 0) >= fetches,
             timeout_s)
    return driver.execute_script("return window.__viewer")


@pytest.fixture(scope="module")
def day_of_10hz(service: Any) -> dict[str, Any]:
    """A spacecraft with a day of 10 Hz gyro rates (864,000 samples, one spike)."""
    from tests.app.report_world import START

    service.api.post("/api/v1/spacecraft", {"name": DAY_SAT, "config": {"gyro": {"q_BG": [1, 0, 0, 0]}}})
    t = START + np.arange(DAY_SAMPLES, dtype=np.int64) * 100_000_000
    phase = np.arange(DAY_SAMPLES) * 2 * np.pi / 54_000.0  # one period per orbit of 90 min
    rng = np.random.default_rng(20)
    w = np.stack([1e-3 * np.sin(phase), 1e-3 * np.cos(phase), 5e-4 * np.sin(3 * phase)], 1)
    w += rng.normal(0.0, 2e-5, w.shape)
    w[400_000, 1] += 0.02
    rec = service.api.upload_columns(DAY_SAT, "gyro", {"time_tai_ns": t, "wx": w[:, 0], "wy": w[:, 1], "wz": w[:, 2]})
    assert rec["inserted"] == DAY_SAMPLES
    return {"start": iso_array(t[:1])[0], "end": iso_array(t[-1:])[0]}


def test_viewer_plots_a_day_of_10_hz_fast_and_zooms(browser, service, day_of_10hz):
    sign_in(browser, service, "viewer", f"/ui/spacecraft/{DAY_SAT}")
    browser.find_element(By.ID, "viewer-link").click()  # default view: the last hour
    viewer_ready(browser)
    query = urllib.parse.urlencode({"stream": "gyro", "sensor": "gyro", "start": day_of_10hz["start"],
                                    "end": day_of_10hz["end"]})
    browser.get(service.base + f"/ui/spacecraft/{DAY_SAT}/viewer?{query}")
    timing = viewer_ready(browser)
    first_ms = timing["firstPlotMs"]  # from the start of the navigation to the first drawn plot
    (output_dir_web() / "viewer_timing.txt").write_text(
        f"first plot of a day of 10 Hz gyro ({DAY_SAMPLES} samples x 3 columns): {first_ms:.0f} ms after navigation "
        f"start; fetch {timing['fetchMs']:.0f} ms, server {timing['serverMs']:.0f} ms, {timing['nPlotted']} points\n")
    assert timing["nSamples"] == DAY_SAMPLES and 0 < timing["nPlotted"] <= 3 * 8000
    assert first_ms < FIRST_PLOT_BUDGET_MS, timing
    panels = browser.find_elements(By.CSS_SELECTOR, "#viewer canvas")
    assert [p.get_attribute("data-column") for p in panels] == ["wx", "wy", "wz"]
    screenshot(browser, "20_viewer_day_10hz")
    for _ in range(6):  # zoom in around the middle: the server sends the detail of the smaller window
        n = int(browser.find_element(By.ID, "viewer").get_attribute("data-ready"))
        browser.find_element(By.CSS_SELECTOR, "[data-act=zoom-in]").click()
        timing = viewer_ready(browser, n + 1)
    assert timing["nSamples"] < DAY_SAMPLES / 50
    from selenium.webdriver.common.action_chains import ActionChains

    n = int(browser.find_element(By.ID, "viewer").get_attribute("data-ready"))
    ActionChains(browser).move_to_element(panels[0]).click_and_hold().move_by_offset(-200, 0).release().perform()
    viewer_ready(browser, n + 1)  # panned: a new window fetched
    shown = browser.execute_script("return window.__viewer.nSamples")
    href = browser.find_element(By.ID, "dl-csv").get_attribute("href")
    got = fetch(browser, href)
    assert got["status"] == 200 and got["disposition"].startswith("attachment")
    assert next(csv.reader(got["text"].splitlines())) == ["time", "sensor", "wx", "wy", "wz", "rejected_by"]
    start, end = (urllib.parse.parse_qs(urllib.parse.urlsplit(href).query)[k][0] for k in ("start", "end"))
    csv_rows = service.api.get(f"/api/v1/spacecraft/{DAY_SAT}/telemetry/gyro", params={"start": start, "end": end})
    assert len(csv_rows.strip().splitlines()) - 1 == shown  # the download holds exactly the view
    screenshot(browser, "21_viewer_zoomed", full_page=False)


def output_dir_web() -> Any:
    from tests.app.report_world import output_dir

    return output_dir("web")


def test_viewer_marks_and_lists_the_rejected_samples(browser, service):
    job = service.jobs["data_screening"]
    sign_in(browser, service, "viewer", f"/ui/spacecraft/{job['spacecraft']}/viewer?"
            + urllib.parse.urlencode({"stream": "magnetometer", "start": job["start"], "end": job["end"],
                                      "screening": job["id"]}))
    viewer_ready(browser)
    summary = service.api.get(f"/api/v1/jobs/{job['id']}")["result"]["streams"]["magnetometer"]
    expected = sum(d["n_rejected"] for c, d in summary.items() if c != "any")
    rows = browser.find_elements(By.CSS_SELECTOR, "#rejected-table tbody tr")
    assert expected > 0 and len(rows) == expected
    criteria = {r.find_elements(By.TAG_NAME, "td")[2].text for r in rows}
    assert criteria == {c for c, d in summary.items() if c != "any" and d["n_rejected"]}
    assert all(r.find_elements(By.TAG_NAME, "td")[4].text != "—" for r in rows)  # every threshold shown
    assert len(browser.find_elements(By.CSS_SELECTOR, "#viewer canvas")) == 3  # bx, by, bz, the rejected marked
    screenshot(browser, "22_viewer_rejected_samples")


def test_retract_an_upload_from_the_ui(browser, service):
    sc = UPLOAD_TARGET
    rec = service.api.upload_columns(sc, "gyro", {"time_tai_ns": np.arange(20, dtype=np.int64) * 10**9
                                                  + int(1.7e18), "wx": np.ones(20), "wy": np.zeros(20),
                                                  "wz": np.zeros(20)})
    used = service.api.post("/api/v1/jobs", {"type": "telemetry_coverage", "spacecraft": sc})["id"]
    assert service.api.wait_for_job(used, timeout_s=120)["status"] == "succeeded"
    sign_in(browser, service, "operator", f"/ui/spacecraft/{sc}#uploads")
    row = browser.find_element(By.CSS_SELECTOR, f"tr[data-ingest='{rec['ingest_id']}']")
    row.find_element(By.TAG_NAME, "summary").click()
    row.find_element(By.NAME, "reason").send_keys("test upload, wrong spacecraft")
    row.find_element(By.CSS_SELECTOR, "button.danger").click()
    alert = wait_for(browser, lambda d: d.switch_to.alert)
    assert "Retract this upload" in alert.text
    alert.accept()
    ok = wait_for(browser, lambda d: d.find_element(By.ID, "retracted-ok"))
    assert "20 samples removed" in ok.text and "1 job marked" in ok.text
    log = browser.find_element(By.ID, "retractions-table").text
    assert "test upload, wrong spacecraft" in log and "web-operator" in log and used[:8] in log
    assert not browser.find_elements(By.CSS_SELECTOR, f"tr[data-ingest='{rec['ingest_id']}']")
    screenshot(browser, "23_retracted")
    assert service.api.get(f"/api/v1/spacecraft/{sc}/telemetry/gyro").strip().count(b"\n") == 0  # header only
    browser.get(service.base + f"/ui/jobs/{used}")
    assert "Based on retracted data" in browser.find_element(By.ID, "retracted").text
    browser.get(service.base + f"/ui/jobs?spacecraft={sc}")
    assert "retracted data" in browser.find_element(By.CSS_SELECTOR, f"tr[data-job='{used}'] td.result").text


def test_create_a_spacecraft_and_edit_its_configuration(browser, service):
    sign_in(browser, service, "admin", "/ui/")
    browser.find_element(By.ID, "new-spacecraft").click()
    wait_for(browser, lambda d: d.find_element(By.ID, "sc-name"))
    browser.find_element(By.ID, "sc-name").send_keys("ui-sat")
    area = browser.find_element(By.ID, "sc-config")
    area.clear()
    area.send_keys('{"star_tracker": {"st1": {"q_BS": [1, 0, 0, 0]}}, "gyro": {"q_BG": [1, 0, 0, 0.5]}}')
    browser.find_element(By.ID, "config-save").click()
    errors = wait_for(browser, lambda d: d.find_element(By.ID, "field-errors")).text
    assert "config.star_tracker" in errors and "did you mean 'star_trackers'" in errors
    assert "config.gyro.q_BG" in errors and "norm" in errors
    screenshot(browser, "24_spacecraft_invalid_config")
    area = browser.find_element(By.ID, "sc-config")
    area.clear()
    area.send_keys('{"star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]}}, "gyro": {"q_BG": [1, 0, 0, 0]}}')
    browser.find_element(By.ID, "config-save").click()
    assert "created" in wait_for(browser, lambda d: d.find_element(By.ID, "created-ok")).text
    browser.find_element(By.ID, "config-link").click()
    area = wait_for(browser, lambda d: d.find_element(By.ID, "sc-config"))
    area.clear()
    area.send_keys('{"star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]}}, "sun_sensor": {"q_BS": [1, 0, 0, 0]}}')
    browser.find_element(By.ID, "config-save").click()
    assert "version 2" in wait_for(browser, lambda d: d.find_element(By.ID, "config-saved")).text
    assert service.api.get("/api/v1/spacecraft/ui-sat")["config_version"] == 2
    screenshot(browser, "25_spacecraft_created")


def test_schedules_list_create_and_delete(browser, service):
    sign_in(browser, service, "operator", "/ui/schedules")
    browser.find_element(By.ID, "s-name").send_keys("nightly-coverage")
    cron = browser.find_element(By.ID, "s-cron")
    cron.clear()
    cron.send_keys("0 3 * * *")
    Select(browser.find_element(By.ID, "s-type")).select_by_value("telemetry_coverage")
    Select(browser.find_element(By.ID, "s-sc")).select_by_value(SPACECRAFT)
    browser.find_element(By.ID, "s-params").clear()
    browser.find_element(By.ID, "s-params").send_keys('{"gap_factr": 2}')
    browser.find_element(By.CSS_SELECTOR, "#schedule-form button").click()
    error = wait_for(browser, lambda d: d.find_element(By.ID, "form-error")).text
    assert "gap_factr" in error and "did you mean 'gap_factor'" in error
    browser.find_element(By.ID, "s-params").clear()
    browser.find_element(By.ID, "s-params").send_keys('{"gap_factor": 2}')
    browser.find_element(By.CSS_SELECTOR, "#schedule-form button").click()
    wait_for(browser, lambda d: re.search(r"/ui/schedules/[0-9a-f]{32}$", d.current_url))
    assert "nightly-coverage" in browser.find_element(By.TAG_NAME, "h1").text
    assert browser.find_element(By.ID, "no-runs")
    screenshot(browser, "26_schedule")
    browser.get(service.base + "/ui/schedules")
    assert "nightly-coverage" in browser.find_element(By.ID, "schedules-table").text
    screenshot(browser, "27_schedules")
    browser.find_element(By.LINK_TEXT, "nightly-coverage").click()
    browser.find_element(By.CSS_SELECTOR, "#delete-schedule button").click()
    wait_for(browser, lambda d: d.switch_to.alert).accept()
    wait_for(browser, lambda d: d.find_element(By.ID, "schedule-deleted"))
    assert service.api.get("/api/v1/schedules") == []


def test_run_form_is_generated_from_the_parameter_schema(browser, service):
    sign_in(browser, service, "operator", "/ui/jobs/new?type=data_screening")
    k_energy = browser.find_element(By.ID, "p-data_screening-k_energy")
    assert k_energy.get_attribute("type") == "number" and k_energy.get_attribute("value") == "4.0"
    assert "k1 of eq. 15" in browser.find_element(By.ID, "p-data_screening-k_energy-help").text
    model = Select(browser.find_element(By.ID, "p-data_screening-energy_model"))
    assert [o.get_attribute("value") for o in model.options] == ["j2", "two_body"]
    model.select_by_value("two_body")
    assert json.loads(browser.find_element(By.ID, "j-params").get_attribute("value"))["energy_model"] == "two_body"
    screenshot(browser, "28_run_form")
    Select(browser.find_element(By.ID, "j-type")).select_by_value("executor_check")
    assert browser.find_element(By.ID, "p-executor_check-duration_s").is_displayed()
    assert not browser.find_element(By.ID, "p-data_screening-k_energy").is_displayed()
    params = browser.find_element(By.ID, "j-params")
    params.clear()
    params.send_keys('{"duraton_s": 1}')
    browser.find_element(By.CSS_SELECTOR, "#job-form button[type=submit]").click()
    error = wait_for(browser, lambda d: d.find_element(By.ID, "submit-error")).text
    assert "params.duraton_s" in error and "did you mean 'duration_s'" in error
    screenshot(browser, "29_run_form_did_you_mean", full_page=False)


def test_headline_first_on_the_job_page_and_in_the_report(browser, service):
    job = service.jobs["gyro_bias_fit"] if "gyro_bias_fit" in service.jobs else service.jobs["telemetry_coverage"]
    sign_in(browser, service, "viewer", f"/ui/jobs/{job['id']}")
    headline = browser.find_element(By.ID, "headline")
    assert "Value ± 1σ" in headline.text and "Frame" in headline.text
    browser.find_element(By.ID, "report-link").click()
    wait_for(browser, lambda d: d.current_url.endswith("/report"))
    first_h2 = browser.find_elements(By.TAG_NAME, "h2")[0]
    assert first_h2.get_attribute("id") == "headline-h"
    assert not browser.find_element(By.ID, "rerun-request").is_displayed()  # collapsed until opened
    screenshot(browser, "30_report_headline", full_page=False)
    browser.get(service.base + f"/ui/jobs?spacecraft={SPACECRAFT}")
    cells = [r.find_element(By.CSS_SELECTOR, "td.result").text for r in browser.find_elements(By.CSS_SELECTOR,
                                                                                              "tr[data-job]")]
    assert any("±" in c or ":" in c for c in cells)
    assert all(r.find_elements(By.TAG_NAME, "td")[-2].text.endswith(("s", "min")) for r in browser.find_elements(
        By.CSS_SELECTOR, "tr[data-status=succeeded]"))
    screenshot(browser, "31_jobs_with_results")
