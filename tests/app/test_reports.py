"""Reports of every registered job type, from simulated seed-003 telemetry: HTML, PDF, JSON, reruns.

One service (module scope) gets the simulated spacecraft and runs every job type once
(tests/app/report_world.py); new job types are covered as soon as they are registered. PDF pages are
rendered to PNG with pdftoppm (Debian poppler-utils, installed when missing) and must not be blank;
the PNGs, HTML and PDF files are kept under var/test-output/reports/ for people to look at.
"""

from __future__ import annotations

import base64
import html as htmllib
import json
import math
import re
import subprocess
import time
import types
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.jobs.registry import registry
from app.jobs.runner import stream_names
from app.main import create_app
from app.reports import job_report, sections, specs, summary, trends
from app.settings import Settings
from tests.app.figure_geometry import problems as figure_problems
from tests.app.report_world import (
    SPECIFICATIONS,
    all_type_names,
    missing_tools,
    output_dir,
    png_ink_fraction,
    report_world,
)

ADMIN = "reports-admin-token-0123456789"
TIMINGS: dict[str, dict[str, float]] = {}
BLANK = 2e-5  # share of inked pixels at or below which a page counts as blank (one line of text: ~1e-4)


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory):
    shared = report_world(tmp_path_factory, "reports")
    settings = Settings(data_dir=shared.data_dir, database_url=f"sqlite:///{shared.data_dir / 'catalog.db'}",
                        bootstrap_token=ADMIN, max_jobs=2)
    with TestClient(create_app(settings)) as client:
        client.headers["Authorization"] = f"Bearer {ADMIN}"
        yield types.SimpleNamespace(client=client, jobs=shared.jobs, skipped=shared.skipped, sim=shared.sim,
                                    where=shared.where, settings=settings, worlds=shared.worlds)
    lines = [f"{k:<28} " + "  ".join(f"{m} {v:6.2f} s" for m, v in sorted(t.items()))
             for k, t in sorted(TIMINGS.items())]
    (output_dir("reports") / "timings.txt").write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def pdf_tools() -> None:
    reason = missing_tools({"chromium": "chromium", "pdftoppm": "poppler-utils", "pdftotext": "poppler-utils"})
    if reason:
        pytest.skip(reason)


def finished(world, job_type: str) -> dict:
    if job_type in world.skipped:
        pytest.skip(world.skipped[job_type])
    job = world.jobs[job_type]
    assert job["status"] == "succeeded", f"{job_type} {job['status']}: {job['error']}"
    return job


def figure_artifacts(client: TestClient, job_id: str) -> list[dict]:
    return [a for a in client.get(f"/api/v1/jobs/{job_id}/artifacts").json() if a["kind"] == "figure"]


def rerun_request_in(html: str) -> dict:
    m = re.search(r'<pre id="rerun-request">(.*?)</pre>', html, re.S)
    assert m, "the report shows no rerun request"
    return json.loads(htmllib.unescape(m.group(1)))


def expected_rerun(job: dict) -> dict:
    """The request that reruns ``job``: same type, window (when it reads telemetry), parameters, reference."""
    jt = registry()[job["type"]]
    body = {"type": job["type"], "spacecraft": job["spacecraft"], "start": job["start"], "end": job["end"],
            "time_scale": "utc", "params": job["params"]}
    if not stream_names(jt):
        del body["start"], body["end"]
    if jt.reference:
        body["reference"] = {k: job["reference"].get(k, "none") for k in jt.reference}
    return body


def pdf_pages(pdf: bytes, stem: str) -> list[Path]:
    out = output_dir("reports")
    for old in out.glob(f"{stem}-*.png"):
        old.unlink()
    (out / f"{stem}.pdf").write_bytes(pdf)
    subprocess.run(["pdftoppm", "-r", "50", "-png", str(out / f"{stem}.pdf"), str(out / stem)], check=True,
                   timeout=120)
    return sorted(out.glob(f"{stem}-*.png"))


@pytest.mark.parametrize("job_type", all_type_names())
def test_html_report_of_every_job_type(world, job_type):
    job = finished(world, job_type)
    client = world.client
    t0 = time.perf_counter()
    r = client.get(f"/api/v1/jobs/{job['id']}/report")
    TIMINGS.setdefault(job_type, {})["html"] = time.perf_counter() - t0
    assert r.status_code == 200
    assert r.headers["content-type"].startswith("text/html")
    assert r.headers["content-disposition"] == f'inline; filename="{job_type}_{job["id"]}.html"'
    html = r.text
    (output_dir("reports") / f"{job_type}.html").write_text(html)
    for text in (registry()[job_type].title, job["spacecraft"], job["start"], job["end"], job["software_version"],
                 "What was processed", "Configuration (calibration) version"):
        assert htmllib.escape(text) in html, text
    for stream in job["inputs"] or {}:
        assert f"<td>{stream}</td>" in html
    for art in figure_artifacts(client, job["id"]):  # every figure inline, byte for byte
        png = client.get(art["url"]).content
        assert base64.b64encode(png).decode() in html, art["name"]
    assert rerun_request_in(html) == expected_rerun(job)


@pytest.mark.parametrize("job_type", all_type_names())
def test_pdf_report_pages_are_not_blank(world, pdf_tools, job_type):
    job = finished(world, job_type)
    t0 = time.perf_counter()
    r = world.client.get(f"/api/v1/jobs/{job['id']}/report", params={"format": "pdf"})
    TIMINGS.setdefault(job_type, {})["pdf"] = time.perf_counter() - t0
    assert r.status_code == 200
    assert r.headers["content-type"] == "application/pdf"
    assert r.headers["content-disposition"] == f'attachment; filename="{job_type}_{job["id"]}.pdf"'
    pdf = r.content
    assert pdf.startswith(b"%PDF-")
    assert b"/Producer (Skia/PDF" in pdf, "not printed by Chromium"
    assert pdf.count(b"/Subtype /Image") >= len(figure_artifacts(world.client, job["id"]))
    pages = pdf_pages(pdf, job_type)
    assert pages
    for page in pages:
        assert png_ink_fraction(page) > BLANK, f"{page.name} is blank"
    # page 1 holds the headline table: the job's answers, before anything else
    pdf_path = output_dir("reports") / f"{job_type}.pdf"
    first = subprocess.run(["pdftotext", "-f", "1", "-l", "1", "-layout", str(pdf_path), "-"], check=True,
                           capture_output=True, text=True, timeout=60).stdout
    rep = world.client.get(f"/api/v1/jobs/{job['id']}/report", params={"format": "json"}).json()
    rows = rep["headline"]["rows"] + [r for st in rep["headline"]["stages"] for r in st["rows"]]
    assert rows, "no headline"
    assert "Result" in first and "Value ± 1σ" in first
    for row in rows:
        assert row["text"] in first, (row, first)


def test_pdf_without_chromium_is_drawn_by_matplotlib(world, monkeypatch):
    reason = missing_tools({"pdftoppm": "poppler-utils"})
    if reason:
        pytest.skip(reason)
    job = finished(world, "telemetry_coverage")
    monkeypatch.setenv("ATTITUDE_CHROMIUM", "/nonexistent/chromium")
    r = world.client.get(f"/api/v1/jobs/{job['id']}/report", params={"format": "pdf"})
    assert r.status_code == 200 and r.content.startswith(b"%PDF-")
    assert b"Matplotlib" in r.content
    pages = pdf_pages(r.content, "fallback_telemetry_coverage")
    assert len(pages) >= 1 + len(figure_artifacts(world.client, job["id"]))
    assert all(png_ink_fraction(p) > BLANK for p in pages)


def test_json_report_says_what_was_processed_and_judges_the_specification(world):
    job = finished(world, "telemetry_coverage")
    r = world.client.get(f"/api/v1/jobs/{job['id']}/report", params={"format": "json"})
    assert r.headers["content-type"] == "application/json"
    assert r.headers["content-disposition"] == f'inline; filename="telemetry_coverage_{job["id"]}.json"'
    rep = r.json()
    truth_gaps = len(world.sim.truth.st_gap_intervals_tai_ns)
    st = rep["input_coverage"]["streams"]["star_tracker"]["st1"]
    assert rep["input_coverage"]["source"] in ("job", "store")
    assert st["n_gaps"] == truth_gaps and st["period_s"] == pytest.approx(3.0)
    assert st["n_samples"] == len(world.sim.streams["star_tracker"]["time_tai_ns"])
    spec = rep["specifications"]
    assert spec["verdict"] == "fail" and spec["configuration_version"] == 1
    assert spec["checks"] == [{"label": "gaps in the window", "key": "n_gaps", "unit": "", "components": [""],
                               "values": [float(truth_gaps)], "limit": "value ≤ 0", "passed": [False], "ok": False}]
    assert rep["window"]["start"] == job["start"] and rep["parameters"] == job["params"]
    html = world.client.get(f"/api/v1/jobs/{job['id']}/report").text
    assert 'id="verdict">FAIL<' in html and "gaps in the window" in html


@pytest.mark.parametrize("job_type", all_type_names())
def test_headline_first_with_units_frames_and_verdicts(world, job_type):
    job = finished(world, job_type)
    rep = world.client.get(f"/api/v1/jobs/{job['id']}/report", params={"format": "json"}).json()
    headline = rep["headline"]
    rows = headline["rows"] + [r for st in headline["stages"] for r in st["rows"]]
    assert rows
    for r in rows:
        assert set(r) >= {"quantity", "component", "value", "sigma", "unit", "frame", "verdict", "text"}
        assert r["verdict"] in ("PASS", "FAIL", "UNDETERMINED", "")
        if r["component"] in ("x", "y", "z", "x1", "x2", "x3"):  # a vector: its frame is named
            assert r["frame"], r
    assert headline["verdict"] == rep["specifications"]["verdict"]
    html = world.client.get(f"/api/v1/jobs/{job['id']}/report").text
    order = [html.find(marker) for marker in ('id="headline"', 'id="figures"', '<h2 id="processed">',
                                              '<h2 id="parameters">', '<h2 id="summary">')]
    present = [i for i in order if i >= 0]
    assert order[0] >= 0 and present == sorted(present), order  # answers, figures, then the collapsed rest
    assert '<details class="section"><summary><h2 id="processed">' in html  # collapsed in the HTML
    if job_type == "gyro_bias_fit":
        bias = [r for r in rows if r["key"] == "gyro_bias_rad_s"]
        assert [r["component"] for r in bias] == ["x", "y", "z"] and {r["unit"] for r in bias} == {"deg/h"}
        assert all(r["sigma"] > 0 and r["frame"] == "body (B)" and r["verdict"] == "PASS" for r in bias)
        truth = rep["summary"]["gyro_bias_rad_s"]
        assert [r["value"] for r in bias] == pytest.approx([v * 180 / math.pi * 3600 for v in truth])
    if job_type == "star_tracker_accuracy":
        assert [(r["component"], r["verdict"]) for r in rows] == [("x1", "PASS"), ("x2", "PASS"), ("x3", "PASS")]
        assert rows[0]["frame"] == "star tracker st1 (S)"
    if job_type == "telemetry_coverage":
        assert rows[0]["key"] == "n_gaps" and rows[0]["verdict"] == "FAIL"
    if job_type == "reconstruction":
        stages = {st["stage"]: st for st in headline["stages"]}
        assert set(stages) >= {"data_screening", "star_tracker_accuracy", "gyro_bias_fit", "orbital_attitude"}
        assert stages["star_tracker_accuracy"]["verdict"] == "pass" and headline["verdict"] != "none"
        assert any(c["key"] == "stages.gyro_bias_fit.summary.gyro_bias_rad_s"
                   for c in rep["specifications"]["checks"])


def test_unknown_report_format_is_refused(world):
    job = finished(world, "telemetry_coverage")
    assert world.client.get(f"/api/v1/jobs/{job['id']}/report", params={"format": "docx"}).status_code == 422


def test_invalid_specifications_are_refused(world):
    bad = {"star_tracker_sigma_arcsec": [1.0, 2.0]}
    r = world.client.post("/api/v1/spacecraft", json={"name": "bad-spec", "config": {"specifications": bad}})
    assert r.status_code == 422 and "star_tracker_sigma_arcsec" in r.text
    r = world.client.post("/api/v1/spacecraft", json={"name": "bad-spec", "config": {"specifications": {
        "limits": [{"job_type": "x", "key": "y"}]}}})
    assert r.status_code == 422 and "min, max or both" in r.text


def test_contributed_sections_render_in_html_and_failures_do_not_break_the_report(world, monkeypatch):
    job = finished(world, "telemetry_coverage")
    real = registry()["telemetry_coverage"]
    drawn = []

    def report_sections(ctx: sections.ReportContext) -> list[sections.ReportSection]:
        from matplotlib.figure import Figure

        table = ctx.table("coverage")
        assert table is not None and "stream" in table
        fig = Figure(figsize=(4, 2), label="Samples per stream (drawn at report time)")
        fig.add_subplot().bar(table["stream"].astype(str), table["n_samples"])
        drawn.append(ctx.params.gap_factor)
        return [sections.ReportSection(
            title="Paper section 9.9 <check>", paragraphs=("Text <em>escaped</em>.",),
            tables=(sections.ReportTable(columns=("axis", "value"), rows=(("x", 1.5), ("y", None)),
                                         title="Per axis"),),
            figure_names=("coverage",), figures={"samples": fig})]

    with_hook = types.SimpleNamespace(**{**{f: getattr(real, f) for f in real.__dataclass_fields__},
                                         "report_sections": report_sections})
    monkeypatch.setattr(job_report, "registry", lambda: {"telemetry_coverage": with_hook})
    html = world.client.get(f"/api/v1/jobs/{job['id']}/report").text
    assert drawn == [1.5]
    assert "Paper section 9.9 &lt;check&gt;" in html and "Text &lt;em&gt;escaped&lt;/em&gt;." in html
    assert "<td class=\"num\">1.5</td>" in html and "<td class=\"num\">—</td>" in html
    assert "Samples per stream (drawn at report time)" in html
    section, rest = html.split("Paper section 9.9", 1)[1].split('<h2 id="summary">', 1)
    assert "Telemetry coverage and gaps" in section  # the stored figure moved into the section ...
    assert 'id="figures"' not in rest  # ... so the generic figure list is empty

    def broken(ctx):
        raise RuntimeError("boom")

    with_hook.report_sections = broken
    html = world.client.get(f"/api/v1/jobs/{job['id']}/report").text
    assert "could not be drawn: RuntimeError: boom" in html and 'id="figures"' in html


# --- units: specification checks, summary layout, trends -------------------------------------------

def test_specification_checks_by_hand():
    s = specs.Specifications.model_validate(SPECIFICATIONS | {"misalignment_max_arcsec": 30,
                                                             "scale_factor_error_max_ppm": 100})
    st = specs.evaluate("star_tracker_accuracy", {"sigma_arcsec": [3.0, 12.0, None]}, s)
    assert [(c.values, c.passed, c.ok) for c in st] == [((3.0, 12.0, None), (True, False, None), False)]
    # correlated residuals: sigma is a lower bound; under the limit proves nothing, over it still fails
    (low,) = specs.evaluate("star_tracker_accuracy", {"sigma_arcsec": [3.0, 12.0, 1.0], "residuals_white": False}, s)
    assert low.passed == (None, False, None) and "lower bound" in low.limit
    bias = 10.0 * math.pi / 180 / 3600  # 10 deg/h in rad/s
    (b,) = specs.evaluate("gyro_bias_fit", {"gyro_bias_rad_s": [bias, -bias, -2.5 * bias]}, s)
    assert b.unit == "deg/h" and b.values == pytest.approx((10.0, -10.0, -25.0)) and b.passed == (True, True, False)
    orbital = specs.evaluate("orbital_attitude", {"pitch_deg": {"min": -0.5, "max": 0.4, "mean": 0, "std": 0.1},
                                                  "yaw_deg": {"min": 0.9, "max": 3.5}}, s)
    assert [(c.key, c.passed) for c in orbital] == [("pitch_deg.min", (True,)), ("pitch_deg.max", (True,)),
                                                    ("yaw_deg.min", (True,)), ("yaw_deg.max", (False,))]
    arcsec = math.pi / 180 / 3600
    align = specs.evaluate("alignment_calibration", {"misalignment_rad": [30 * arcsec, 40 * arcsec, 0.0],
                                                     "scale_factor_error": [50e-6, -150e-6, 0.0]}, s)
    assert align[0].values == pytest.approx((50.0,)) and align[0].ok is False  # |(30, 40, 0)| = 50 arcsec
    assert align[1].passed == (True, False, True)
    assert specs.evaluate("telemetry_coverage", {"n_gaps": 0}, s)[0].ok is True
    assert specs.evaluate("star_tracker_accuracy", {"sigma_arcsec": [1, 1, 1]}, None) == []
    assert specs.verdict([]) == "none"
    # A limited quantity that the data did not determine (null) is UNDETERMINED, never a PASS.
    (und,) = specs.evaluate("alignment_calibration", {"misalignment_rad": [1e-5, None, 0.0]}, s)[:1]
    assert und.passed == (None,) and und.ok is None
    assert specs.verdict([und]) == "undetermined"
    assert specs.verdict([und, align[0]]) == "fail"
    assert specs.verdict(specs.evaluate("telemetry_coverage", {"n_gaps": 0}, s)) == "pass"


def test_summary_layout_groups_vectors_statistics_and_tables():
    arcsec = math.pi / 180 / 3600
    lay = summary.layout({
        "n_samples": 10, "converged": True, "sensor": "st1", "first_tai_ns": 1_686_000_037_000_000_000,
        "misalignment_rad": [arcsec, 2 * arcsec, 0.0],
        "pitch_deg": {"mean": 0.1, "std": 0.2, "min": -0.3, "max": 0.4},
        "screening": {"norm": {"n_total": 5, "n_rejected": 1}, "jump": {"n_total": 5, "n_rejected": 0}},
        "streams": [{"stream": "gyro", "n_gaps": 0, "gaps": []}],
        "quaternion": [1.0, 0.0, 0.0, 0.0], "nested": {"bias_rad_s": 1e-5},
    })
    assert ("n_samples", "10") in lay.scalars and ("converged", "true") in lay.scalars
    assert ("first (UTC)", "2023-06-05T21:20:00Z") in lay.scalars
    assert lay.vectors == [("misalignment_rad", ["4.84814e-06", "9.69627e-06", "0"]),
                           ("misalignment [arcsec]", ["1", "2", "0"])]
    assert lay.stats == [("pitch_deg", {"mean": "0.1", "std": "0.2", "min": "-0.3", "max": "0.4"})]
    assert [t["name"] for t in lay.tables] == ["screening", "streams"]
    assert lay.tables[0]["rows"] == [["norm", "5", "1"], ["jump", "5", "0"]]
    assert ("quaternion", "[1, 0, 0, 0]") in lay.scalars
    assert ("nested.bias [deg/h]", "2.06265") in lay.scalars


def _fake_job(job_id, job_type, start_s, summary_, params=None):
    t0 = 1_686_000_000_000_000_000 + int(start_s * 1e9)
    return types.SimpleNamespace(id=job_id, type=job_type, start_tai_ns=t0, end_tai_ns=t0 + 600 * 10**9,
                                 result={"summary": summary_}, params=params or {}, created_at=start_s)


def test_trends_convert_units_split_sensors_and_draw_limits(tmp_path):
    rad_s = math.pi / 180 / 3600  # 1 deg/h
    jobs = [_fake_job("a", "gyro_bias_fit", 0, {"gyro_bias_rad_s": [rad_s, 2 * rad_s, 3 * rad_s]}),
            _fake_job("b", "gyro_bias_fit", 86400, {"gyro_bias_rad_s": [2 * rad_s, 2 * rad_s, None]}),
            _fake_job("c", "star_tracker_accuracy", 0, {"sigma_arcsec": [2.0, 5.0, 15.0], "sensor": "st1"}),
            _fake_job("d", "star_tracker_accuracy", 0, {"sigma_arcsec": [3.0, 5.0, 16.0]}, {"sensor": "st2"})]
    s = specs.Specifications.model_validate(SPECIFICATIONS)
    got = {t.metric.key: t for t in trends.trends(jobs, trends.KEY_METRICS, s)}
    assert set(got) == {"gyro_bias_rad_s", "sigma_arcsec"}
    bias = got["gyro_bias_rad_s"]
    assert [p.values for p in bias.points][0] == pytest.approx((1.0, 2.0, 3.0))
    assert bias.points[1].values[2] is None and bias.limits == [(-20.0, 20.0)] * 3
    assert [p.series for p in got["sigma_arcsec"].points] == ["st1", "st2"]
    rows = trends.rows(list(got.values()))
    assert len(rows) == 12 and {r["unit"] for r in rows} == {"deg/h", "arcsec"}
    for t in got.values():
        fig = trends.figure(t)
        fig.savefig(tmp_path / f"{t.metric.key}.png")
        assert png_ink_fraction(tmp_path / f"{t.metric.key}.png") > 0.01
    generic = trends.generic_metrics("gyro_bias_fit", jobs)
    assert [(m.key, m.unit, m.components) for m in generic] == [("gyro_bias_rad_s", "deg/h", ("x", "y", "z"))]
    coverage = trends.generic_metrics("telemetry_coverage", [_fake_job("e", "telemetry_coverage", 0, {"n_gaps": 3})])
    assert coverage[0].limits(s) == [(None, 0.0)]  # the generic limit of SPECIFICATIONS


def test_input_description_counts_gaps_per_sensor():
    from app.reports.inputs import describe_inputs

    t = np.array([0, 1, 2, 5, 6, 0, 10], dtype=np.int64) * 10**9
    out = describe_inputs({"gyro": {"time_tai_ns": t, "sensor": np.array(["a"] * 5 + ["b"] * 2, dtype=object)}},
                          0, 10 * 10**9)
    a, b = out["gyro"]["a"], out["gyro"]["b"]
    assert (a["n_samples"], a["period_s"], a["n_gaps"], a["missing_samples"], a["gap_total_s"]) == (5, 1.0, 1, 2, 3.0)
    assert a["largest_gaps"] == [{"before_tai_ns": 2 * 10**9, "after_tai_ns": 5 * 10**9, "duration_s": 3.0,
                                  "missing": 2}]
    assert a["trailing_s"] == 4.0 and b["n_gaps"] == 0 and b["period_s"] == 10.0


@pytest.mark.parametrize("order", ["sorted", "shuffled"])
def test_input_description_counts_shared_times_once_in_any_order(order):
    from app.reports.inputs import describe_inputs

    rng = np.random.default_rng(3)
    t = np.repeat(np.array([0, 1, 2, 2, 4, 5], dtype=np.int64) * 10**9, 3)  # three panels per time, one duplicate
    if order == "shuffled":
        t = rng.permutation(t)
    out = describe_inputs({"panels": {"time_tai_ns": t, "sensor": np.array(["p"] * t.size, dtype=object)}},
                          0, 5 * 10**9)["panels"]["p"]
    assert (out["n_samples"], out["period_s"], out["n_gaps"], out["missing_samples"]) == (18, 1.0, 1, 1)
    assert (out["first_tai_ns"], out["last_tai_ns"]) == (0, 5 * 10**9)


# --- figures: drawn in-process on the same simulated data, their geometry checked --------------------

def _run_in_process(world, job_type: str):
    """(TaskResult, params) of ``job_type`` run directly on the simulated streams of its spacecraft."""
    from tests.app.report_world import run_in_process

    if job_type in world.skipped:
        pytest.skip(world.skipped[job_type])
    jt = registry()[job_type]
    sim = world.worlds[world.where[job_type]]
    return run_in_process(jt, sim)


@pytest.mark.parametrize("job_type", all_type_names())
def test_figures_have_no_overlapping_text(world, job_type):
    result, params = _run_in_process(world, job_type)
    figures = registry()[job_type].figures(result, params)
    found = {name: figure_problems(fig) for name, fig in figures.items()}
    assert not {k: v for k, v in found.items() if v}, found


def test_screening_marks_exactly_the_rejected_samples(world):
    result, params = _run_in_process(world, "data_screening")
    fig = registry()["data_screening"].figures(result, params)["flags_timeline"]
    marks = {line.get_gid(): len(line.get_xdata()) for line in fig.axes[0].get_lines()}
    per_stream = {s: per["any"]["n_rejected"] for s, per in result.summary["streams"].items()
                  if per["any"]["n_rejected"]}
    n_rejected = result.summary["n_rejected"]
    assert 0 < n_rejected < result.summary["n_total"] // 10  # a few rejections, not the whole window
    assert sum(n for label, n in marks.items() if "any criterion" in label) == n_rejected
    assert {label.split(":")[0]: n for label, n in marks.items() if "any criterion" in label} == per_stream
    for s, per in result.summary["streams"].items():
        for c, d in per.items():
            if c != "any" and d["n_rejected"]:
                assert marks[f"{s} / {c} ({d['n_rejected']})"] == d["n_rejected"], (s, c)


def test_angle_statistics_never_straddle_180_degrees(world):
    result, _ = _run_in_process(world, "vector_attitude")
    roll = np.asarray(result.tables["attitude"]["roll_deg"], dtype=float)
    roll = roll[np.isfinite(roll)]
    stats = result.summary["roll_deg"]
    continuous = np.degrees(np.unwrap(np.deg2rad(roll)))
    assert np.abs(np.diff(continuous)).max() < 10.0  # the simulated roll is continuous ...
    assert np.ptp(roll) > 300.0  # ... and passes +-180 deg in this window
    assert stats["max"] - stats["min"] == pytest.approx(np.ptp(continuous))  # one range, not a 360 deg spread
    assert stats["std"] == pytest.approx(np.std(continuous, ddof=1))
    assert -180.0 < stats["mean"] <= 180.0


def test_trend_figures_have_error_bars_full_dates_and_continuous_angles():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.container import ErrorbarContainer

    rad_s = math.pi / 180 / 3600  # 1 deg/h
    jobs = [_fake_job(str(i), "gyro_bias_fit", i * 40 * 86400, {"gyro_bias_rad_s": [rad_s * (1 + i), 0.0, -rad_s],
                                                                 "gyro_bias_sigma_rad_s": [0.1 * rad_s] * 3})
            for i in range(3)]
    jobs += [_fake_job(f"o{i}", "orbital_attitude", i * 86400, {"roll_deg": {"min": r - 1, "mean": r, "max": r + 1}})
             for i, r in enumerate((178.0, 179.5, -179.5, -178.0))]
    got = {t.metric.key: t for t in trends.trends(jobs, trends.KEY_METRICS, None)}
    bias = got["gyro_bias_rad_s"]
    assert bias.points[0].sigmas == pytest.approx((0.1, 0.1, 0.1))
    assert [r["sigma"] for r in trends.rows([bias])] == pytest.approx([0.1] * 9)
    fig = trends.figure(bias)
    FigureCanvasAgg(fig).draw()
    ax = fig.axes[0]
    assert any(isinstance(c, ErrorbarContainer) for c in ax.containers)
    ticks = [t.get_text() for t in ax.get_xticklabels() if t.get_text()]
    assert ticks and all(re.match(r"\d{4}-\d{2}-\d{2}", t) for t in ticks), ticks  # year, month and day
    assert not figure_problems(fig)
    roll = trends.figure(got["roll_deg"])
    means = roll.axes[0].get_lines()[1].get_ydata()  # components min, mean, max: the mean line
    assert np.abs(np.diff(means)).max() < 5.0  # 179.5 -> -179.5 drawn as a 1 degree step, not 359
