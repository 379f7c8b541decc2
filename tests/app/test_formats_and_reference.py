"""The plug-in points: upload decoders (named file formats) and reference data sets used by jobs."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from app.ingest.formats import Decoded, Decoder
from app.reference.registry import ReferenceKind
from processing.tasks import ParsedReference
from processing.time import timescales
from tests.app.helpers import make_spacecraft, upload


def _decode_lines(body: bytes, stream: str) -> Decoded:
    """'<tai seconds> wx wy wz' lines, a stand-in for a mission file format."""
    rows = [line.split() for line in body.decode().splitlines() if line.strip() and not line.startswith("#")]
    if any(len(r) != 4 for r in rows):
        raise ValueError("every line needs 4 fields")
    cols = list(zip(*rows, strict=True))
    return Decoded(pa.table({"time": [float(x) for x in cols[0]], "wx": [float(x) for x in cols[1]],
                             "wy": [float(x) for x in cols[2]], "wz": [float(x) for x in cols[3]]}),
                   time_scale="tai", sensor="gyro-b")


def _parse_table(raw: bytes) -> ParsedReference:
    lines = [x.split() for x in raw.decode().splitlines() if x.strip()]
    if not lines or any(len(x) != 2 for x in lines):
        raise ValueError("expected lines of '<ISO time> <value>'")
    t = timescales.iso_to_tai_ns([x[0] for x in lines])
    return ParsedReference({"time_tai_ns": t, "value": np.array([float(x[1]) for x in lines])},
                           int(t.min()), int(t.max()), {"source": "test"})


@pytest.fixture
def plugins(monkeypatch):
    monkeypatch.setattr("app.services.telemetry.decoders",
                        lambda: {"lines": Decoder("lines", ("gyro",), _decode_lines, "test format")})
    kinds = {"toy": ReferenceKind("toy", _parse_table, "test kind")}
    monkeypatch.setattr("app.services.reference.reference_kinds", lambda: kinds)


def test_named_format_upload(client, plugins):
    make_spacecraft(client)
    body = "# comment\n1685577637 0.1 0.2 0.3\n1685577638 0.1 0.2 0.4\n"
    r = upload(client, "gyro", body, {"Content-Type": "text/plain"}, format="lines")
    assert r.status_code == 201, r.text
    assert r.json()["sensor"] == "gyro-b" and r.json()["start"] == "2023-06-01T00:00:00Z"
    assert upload(client, "gyro", "1 2 3\n", {"Content-Type": "text/plain"}, format="lines").status_code == 422
    r = upload(client, "gyro", body, {"Content-Type": "text/plain"}, format="nosuch")
    assert r.status_code == 422 and "unknown format" in r.json()["errors"][0]["message"]
    r = upload(client, "star_tracker", body, {"Content-Type": "text/plain"}, format="lines")
    assert r.status_code == 422 and "feeds gyro" in r.json()["errors"][0]["message"]
    r = upload(client, "gyro", body, {"Content-Type": "text/plain"}, format="lines", sensor="other")
    assert r.status_code == 422 and r.json()["errors"][0]["column"] == "sensor"


def test_reference_upload_list_read_delete(client, plugins, settings):
    body = b"2023-06-01T00:00:00Z 1.5\n2023-06-02T00:00:00Z 2.5\n"
    r = client.post("/api/v1/reference/toy", content=body, params={"name": "toy v1", "filename": "toy.txt"})
    assert r.status_code == 201, r.text
    d = r.json()
    assert d["rows"] == 2 and d["start"] == "2023-06-01T00:00:00Z" and d["details"]["source"] == "test"
    assert [x["id"] for x in client.get("/api/v1/reference?kind=toy").json()] == [d["id"]]
    data = client.get(f"/api/v1/reference/toy/{d['id']}/data?format=json").json()
    assert data == [{"time": "2023-06-01T00:00:00Z", "value": 1.5}, {"time": "2023-06-02T00:00:00Z", "value": 2.5}]
    assert client.get(f"/api/v1/reference/toy/{d['id']}/data?format=raw").content == body
    assert client.post("/api/v1/reference/toy", content=b"garbage").status_code == 422
    assert client.post("/api/v1/reference/nosuch", content=body).status_code == 404
    assert len(client.get("/api/v1/reference").json()) == 1  # the bad upload stored nothing
    assert client.delete(f"/api/v1/reference/toy/{d['id']}").status_code == 200
    assert client.get(f"/api/v1/reference/toy/{d['id']}").status_code == 404
    assert not (settings.data_dir / "reference" / d["id"]).exists()


def test_jobs_pin_their_reference_data(client, plugins, monkeypatch):
    """A job that declares a reference kind gets the newest covering data set (or the one named)."""
    from dataclasses import replace

    from app.jobs import registry as reg

    base = reg.registry()
    toy_job = replace(base["executor_check"], reference=("toy",))
    monkeypatch.setattr("app.services.jobs.registry", lambda: {**base, "executor_check": toy_job})
    make_spacecraft(client)
    old = client.post("/api/v1/reference/toy", content=b"2000-01-01T00:00:00Z 1\n").json()
    new = client.post("/api/v1/reference/toy", content=b"2020-01-01T00:00:00Z 1\n2030-01-01T00:00:00Z 2\n").json()
    r = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1"})
    assert client.get(f"/api/v1/jobs/{r.json()['id']}").json()["reference"] == {"toy": new["id"]}
    r = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1",
                                          "reference": {"toy": old["id"]}})
    assert client.get(f"/api/v1/jobs/{r.json()['id']}").json()["reference"] == {"toy": old["id"]}
    r = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1", "reference": {"toy": "none"}})
    assert client.get(f"/api/v1/jobs/{r.json()['id']}").json()["reference"] == {}
    r = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1", "reference": {"toy": "x"}})
    assert r.status_code == 422
    r = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1", "reference": {"eop": "x"}})
    assert r.status_code == 422 and "uses no reference data of kind eop" in r.json()["detail"]
