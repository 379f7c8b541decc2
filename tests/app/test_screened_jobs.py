"""screened=true: a job uses only the samples a data_screening job accepted, and says which."""

from __future__ import annotations

import pytest

from processing.formats.rinex_nav import parse_rinex_nav_reference
from processing.simulate.seed002 import simulate_seed002
from tests.app.helpers import SQLITE_ONLY
from tests.app.test_jobs_api import upload_columns, wait
from tests.real_data import GNSS_NAV

pytestmark = SQLITE_ONLY

NAV = GNSS_NAV / "brdc2800.15n"


@pytest.mark.slow
def test_vector_attitude_on_screened_data(client):
    nav = parse_rinex_nav_reference(NAV.read_bytes())
    sc = simulate_seed002(nav=nav.columns, seed=5, duration_s=900.0)
    client.post("/api/v1/spacecraft", json={"name": "small", "config": sc.config})
    for stream, columns in sc.streams.items():
        upload_columns(client, "small", stream, columns)
    r = client.post("/api/v1/reference/rinex_nav", content=NAV.read_bytes(), params={"filename": NAV.name})
    assert r.status_code == 201, r.text
    r = client.post("/api/v1/jobs", json={"type": "vector_attitude", "spacecraft": "small", "screened": True})
    assert r.status_code == 422 and "run one first" in r.json()["detail"]
    screening = wait(client, client.post("/api/v1/jobs", json={"type": "data_screening",
                                                               "spacecraft": "small"}).json()["id"], 240)
    assert screening["status"] == "succeeded", screening["error"]
    mag_rejected = max(c["n_rejected"] for c in screening["result"]["streams"]["magnetometer"].values())
    job = wait(client, client.post("/api/v1/jobs", json={"type": "vector_attitude", "spacecraft": "small",
                                                         "screened": True}).json()["id"], 240)
    assert job["status"] == "succeeded", job["error"]
    assert job["reference"]["screening"] == screening["id"]
    assert any(screening["id"] in n for n in job["notes"]), job["notes"]
    if mag_rejected:
        raw = wait(client, client.post("/api/v1/jobs", json={"type": "vector_attitude",
                                                             "spacecraft": "small"}).json()["id"], 240)
        assert sum(raw["inputs"]["magnetometer"].values()) > sum(job["inputs"]["magnetometer"].values())
