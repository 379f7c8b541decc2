"""Figures on request (issue 24): not drawn by the job, drawn from the stored artifacts on first request, stored,
then served as stored; listed before they exist; embedded in reports; the eager setting; pixel-equal to the
figures drawn from the in-memory result."""

from __future__ import annotations

import dataclasses
import io
import json
import threading
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from fastapi.testclient import TestClient
from matplotlib import image as mpimg
from sqlalchemy import delete, select

from app.jobs import figures as lazy
from app.jobs.outputs import figure_png, jsonable, write_outputs
from app.jobs.registry import registry
from app.jobs.types import reconstruction
from app.main import create_app
from app.services import figures as figure_service
from app.settings import Settings
from storage.jobs import ArtifactStore
from storage.models import Artifact, Job
from tests.app.helpers import make_spacecraft
from tests.app.test_jobs_api import upload_columns, wait
from tests.conftest import ADMIN_TOKEN


@pytest.fixture(scope="module")
def scenario():
    from processing.simulate.seed003 import simulate_seed003
    from tests.app.test_jobs_api import START

    return simulate_seed003(start_tai_ns=START, duration_s=600.0, seed=11)


def coverage_job(client: TestClient, scenario, name: str = "meteor") -> dict:
    make_spacecraft(client, name, scenario.config)
    for stream, columns in scenario.streams.items():
        upload_columns(client, name, stream, columns)
    r = client.post("/api/v1/jobs", json={"type": "telemetry_coverage", "spacecraft": name})
    assert r.status_code == 202, r.text
    job = wait(client, r.json()["id"])
    assert job["status"] == "succeeded", job["error"]
    return job


def figure_rows(client: TestClient, job_id: str) -> list[Artifact]:
    with client.app.state.sessions() as session:
        return list(session.scalars(select(Artifact).where(Artifact.job_id == job_id, Artifact.kind == "figure")))


def count_draws(monkeypatch) -> list[set[str] | None]:
    calls: list[set[str] | None] = []
    real = figure_service.draw

    def counted(job_type, result, params, wanted):
        calls.append(wanted)
        return real(job_type, result, params, wanted)

    monkeypatch.setattr(figure_service, "draw", counted)
    return calls


def test_figures_are_drawn_on_first_request_stored_then_served_as_stored(client, settings, scenario, monkeypatch):
    job = coverage_job(client, scenario)
    png_path = settings.artifacts_dir / job["id"] / "coverage.png"
    assert figure_rows(client, job["id"]) == [] and not png_path.exists()  # the job drew nothing
    listed = {a["name"]: a for a in client.get(f"/api/v1/jobs/{job['id']}/artifacts").json()}
    entry = listed["coverage.png"]
    assert entry["on_request"] is True and entry["kind"] == "figure" and entry["size_bytes"] is None
    assert "made on request" in entry["description"]
    assert listed["summary.json"]["on_request"] is False and listed["summary.json"]["size_bytes"] > 0

    draws = count_draws(monkeypatch)
    first = client.get(entry["url"])
    assert first.status_code == 200, first.text
    assert first.headers["content-type"] == "image/png" and first.content[:8] == b"\x89PNG\r\n\x1a\n"
    assert draws == [{"coverage"}]
    rows = figure_rows(client, job["id"])
    assert [r.name for r in rows] == ["coverage.png"] and rows[0].size_bytes == len(first.content)
    assert rows[0].description == "Telemetry coverage and gaps"  # the figure's own title, as an eager job stores
    assert png_path.read_bytes() == first.content
    mtime = png_path.stat().st_mtime_ns

    second = client.get(entry["url"])
    assert second.content == first.content and draws == [{"coverage"}]  # served as stored: not drawn again
    assert png_path.stat().st_mtime_ns == mtime
    after = {a["name"]: a for a in client.get(f"/api/v1/jobs/{job['id']}/artifacts").json()}["coverage.png"]
    assert after["on_request"] is False and after["size_bytes"] == len(first.content)


def test_reports_embed_the_figures_made_on_request(client, scenario):
    job = coverage_job(client, scenario)
    data = client.get(f"/api/v1/jobs/{job['id']}/report?format=json").json()
    assert [a["name"] for a in data["artifacts"] if a["on_request"]] == ["coverage.png"]  # JSON: listed, not drawn
    assert figure_rows(client, job["id"]) == []
    html = client.get(f"/api/v1/jobs/{job['id']}/report")
    assert html.status_code == 200
    rows = figure_rows(client, job["id"])
    assert [r.name for r in rows] == ["coverage.png"]  # drawn and stored when the report was built
    png = client.get(f"/api/v1/jobs/{job['id']}/artifacts/coverage.png").content
    import base64

    assert base64.b64encode(png).decode() in html.text and 'id="figures"' in html.text
    assert "made on request" not in html.text  # its Downloads list shows the stored figure


def test_concurrent_first_requests_store_one_whole_figure(client, settings, scenario):
    job = coverage_job(client, scenario)
    url = f"/api/v1/jobs/{job['id']}/artifacts/coverage.png"
    got: list[bytes] = []
    barrier = threading.Barrier(3)

    def fetch() -> None:
        barrier.wait()
        r = client.get(url)
        assert r.status_code == 200, r.text
        got.append(r.content)

    threads = [threading.Thread(target=fetch) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(got) == 3 and len(set(got)) == 1
    rows = figure_rows(client, job["id"])
    assert len(rows) == 1 and rows[0].size_bytes == len(got[0])
    folder = settings.artifacts_dir / job["id"]
    assert (folder / "coverage.png").read_bytes() == got[0]
    assert not [p for p in folder.iterdir() if p.name.startswith(".tmp-")]  # no temporary file left


def test_missing_data_and_unknown_figures_are_clear_4xx(client, scenario):
    job = coverage_job(client, scenario)
    nope = client.get(f"/api/v1/jobs/{job['id']}/artifacts/nope.png")
    assert nope.status_code == 404 and "nope.png" in nope.text
    # the stored summary no longer says which streams there were: the figure cannot be drawn (409 with the reason)
    with client.app.state.sessions.begin() as session:
        row = session.get(Job, job["id"])
        assert row is not None
        result = dict(row.result)
        result["summary"] = {k: v for k, v in result["summary"].items() if k != "streams"}
        row.result = result
    r = client.get(f"/api/v1/jobs/{job['id']}/artifacts/coverage.png")
    assert r.status_code == 409 and "cannot be drawn" in r.text and "streams" in r.text


def test_a_figure_whose_table_was_not_stored_is_a_409_naming_it(client, scenario):
    make_spacecraft(client, "sat-gb", scenario.config)
    for stream, columns in scenario.streams.items():
        upload_columns(client, "sat-gb", stream, columns)
    r = client.post("/api/v1/jobs", json={"type": "gyro_bias_fit", "spacecraft": "sat-gb"})
    job = wait(client, r.json()["id"], timeout_s=300)
    assert job["status"] == "succeeded", job["error"]
    with client.app.state.sessions.begin() as session:
        session.execute(delete(Artifact).where(Artifact.job_id == job["id"], Artifact.name == "rates.parquet"))
    r = client.get(f"/api/v1/jobs/{job['id']}/artifacts/rates.png")
    assert r.status_code == 409 and "'rates'" in r.text, r.text
    html = client.get(f"/api/v1/jobs/{job['id']}/report")
    assert html.status_code == 200 and "did not store the table or file &#39;rates&#39;" in html.text


def test_eager_setting_draws_and_stores_the_figures_at_job_end(settings, scenario):
    eager = dataclasses.replace(settings, figures="eager")
    with TestClient(create_app(eager)) as client:
        client.headers["Authorization"] = f"Bearer {ADMIN_TOKEN}"
        job = coverage_job(client, scenario)
        assert [r.name for r in figure_rows(client, job["id"])] == ["coverage.png"]
        listed = client.get(f"/api/v1/jobs/{job['id']}/artifacts").json()
        assert not [a for a in listed if a["on_request"]]
        assert (eager.artifacts_dir / job["id"] / "coverage.png").is_file()


def test_figures_setting_from_the_environment(tmp_path):
    assert Settings.from_env({"ATTITUDE_DATA_DIR": str(tmp_path)}).figures == "lazy"
    assert Settings.from_env({"ATTITUDE_DATA_DIR": str(tmp_path), "ATTITUDE_FIGURES": "Eager"}).figures == "eager"
    with pytest.raises(ValueError, match="ATTITUDE_FIGURES must be lazy or eager, got 'later'"):
        Settings.from_env({"ATTITUDE_DATA_DIR": str(tmp_path), "ATTITUDE_FIGURES": "later"})


# --- drawn from the stored artifacts = drawn from the in-memory result, pixel for pixel ------------------------

def _in_process(job_type: str):
    """(job type, TaskResult, params) of ``job_type`` run on the report world's simulated streams (a small job)."""
    from tests.app.report_world import assign, run_in_process, scenarios

    worlds = _worlds(scenarios)
    where, skipped = assign(registry().values(), worlds)
    if job_type in skipped:
        pytest.skip(skipped[job_type])
    jt = registry()[job_type]
    sim = worlds[where[job_type]]
    return (jt, *run_in_process(jt, sim))


_WORLDS: dict = {}


def _worlds(build):
    if not _WORLDS:
        _WORLDS.update(build())
    return _WORLDS


def pixels(png: bytes) -> np.ndarray:
    return np.asarray(mpimg.imread(io.BytesIO(png), format="png"))


@pytest.mark.parametrize("job_type", sorted(registry()))
def test_figures_from_stored_artifacts_match_the_in_memory_ones(job_type, tmp_path: Path):
    jt, result, params = _in_process(job_type)
    in_memory = jt.figures(result, params)
    names = lazy.figure_names(jt, result.summary, lazy.table_rows(result.tables))
    assert names == list(in_memory)  # the names recorded at job end are those figures() draws
    compared = list(in_memory)
    if job_type == "reconstruction":
        # its figures are its stages' figures, each compared pixel for pixel in its own job type's case above:
        # here the first of every stage (the stage prefixes and the stage results read back under them)
        compared = list({name.split(reconstruction.SEPARATOR)[0]: name for name in reversed(compared)}.values())
        assert len(compared) >= 4
    eager = {name: figure_png(in_memory[name]) for name in compared}

    store = ArtifactStore(tmp_path / "artifacts")
    summary = jsonable({"warnings": [w.as_dict() for w in result.warnings], **result.summary})
    stored = write_outputs(store, "job", result, {}, summary)
    tables = {a.name[: -len(".parquet")]: (lambda a=a: pq.read_table(store.file_path(a.path)))
              for a in stored if a.kind == "table" and a.name.endswith(".parquet")}
    files = {a.name: ((lambda a=a: store.read_bytes(a.path)), a.media_type) for a in stored if a.kind == "file"}
    read_back = lazy.stored_result(json.loads(json.dumps(summary)), tables, files)
    drawn, drawn_names = lazy.draw(jt, read_back, params, set(compared))
    assert drawn_names == list(in_memory)
    for name, png in eager.items():
        a, b = pixels(png), pixels(drawn[name][0])
        assert a.shape == b.shape, (name, a.shape, b.shape)
        diff = float(np.max(np.abs(a - b))) if a.size else 0.0
        assert diff == 0.0, f"{job_type} {name}: max abs pixel difference {diff}"
        assert drawn[name][1] == str(in_memory[name].get_label() or name)


def test_read_back_tables_have_the_job_columns():
    import pyarrow as pa

    from app.jobs.outputs import table_to_arrow

    cols = {"time_tai_ns": np.array([10**18, 10**18 + 10**9], dtype=np.int64), "sensor": np.array(["a", "b"]),
            "n": np.array([1, 2]), "x": np.array([0.5, np.nan]), "ok": np.array([True, False])}
    buf = io.BytesIO()
    pq.write_table(table_to_arrow(cols), buf)
    back = lazy.columns_from_arrow(pq.read_table(pa.BufferReader(buf.getvalue())))
    assert list(back) == list(cols)  # the display column "time" is gone
    assert back["sensor"].dtype == object and back["sensor"].tolist() == ["a", "b"]
    assert back["n"].dtype == np.int64 and back["ok"].dtype == bool
    np.testing.assert_array_equal(back["time_tai_ns"], cols["time_tai_ns"])
    np.testing.assert_array_equal(back["x"], cols["x"])


def test_figure_names_of_a_job_type_without_figures_or_without_declared_names():
    from app.jobs.registry import JobType
    from app.jobs.types.executor_check import Params

    plain = JobType(name="plain", title="", paper="", params=Params, run=lambda i, p, g: None)  # type: ignore[arg-type]
    assert lazy.figure_names(plain, {}, {}) == []
    drawing = dataclasses.replace(plain, figures=lambda result, params: {})
    assert lazy.figure_names(drawing, {}, {}) is None  # listed once drawn
    declared = dataclasses.replace(drawing, figure_names=lambda summary, rows: ["a"] if rows.get("t") else [])
    assert lazy.figure_names(declared, {}, {"t": 3}) == ["a"] and lazy.figure_names(declared, {}, {}) == []
