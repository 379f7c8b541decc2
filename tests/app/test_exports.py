"""OEM export of stored GNSS windows (app/api/routes/exports.py).

The router is not yet included by app.main (the lead wires it); these tests include it themselves.
"""

from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.api.routes import exports
from app.main import create_app
from processing.formats.ccsds_odm import parse_oem
from processing.frames.earth_orientation import gcrs_to_itrs_state
from processing.orbits.two_body import circular_orbit_state
from processing.time import timescales
from processing.units import R_EARTH_M
from tests.app.helpers import SQLITE_ONLY, make_spacecraft, upload
from tests.conftest import ADMIN_TOKEN

pytestmark = SQLITE_ONLY

T0 = int(timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])
NS = 1_000_000_000


@pytest.fixture
def api(settings) -> Iterator[TestClient]:
    app = create_app(settings)
    if not any(getattr(r, "path", "").endswith("/export/oem") for r in app.routes):
        app.include_router(exports.router)
    with TestClient(app) as c:
        c.headers["Authorization"] = f"Bearer {ADMIN_TOKEN}"
        yield c


def _store_gnss(api, n=20):
    make_spacecraft(api)
    t = T0 + np.arange(n) * 10 * NS
    r_I, v_I = circular_orbit_state(np.arange(n) * 10.0, R_EARTH_M + 500e3, 1.7, 0.5, 0.2)
    r_E, v_E = gcrs_to_itrs_state(r_I, v_I, t)
    csv = "time,x,y,z,vx,vy,vz\n" + "".join(
        f"{iso},{','.join(repr(float(x)) for x in (*r, *v))}\n"
        for iso, r, v in zip(timescales.tai_ns_to_iso(t), r_E, v_E, strict=True))
    r = upload(api, "gnss", csv)
    assert r.status_code == 201, r.text
    return t, r_E, v_E, r_I, v_I


def test_export_window_as_oem_parses_back_to_the_stored_states(api):
    t, r_E, v_E, _, _ = _store_gnss(api)
    r = api.get("/api/v1/spacecraft/sat1/export/oem",
                params={"start": "2023-06-01T00:00:50Z", "end": "2023-06-01T00:02:00Z"})
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("text/plain")
    assert 'filename="sat1_gnss.oem"' in r.headers["content-disposition"]
    oem = parse_oem(r.content)
    seg = oem.segments[0]
    assert oem.version == "3.0" and seg.ref_frame == "ITRF" and seg.metadata["OBJECT_NAME"] == "sat1"
    assert seg.time_system == "UTC" and seg.metadata["CENTER_NAME"] == "EARTH"
    sel = slice(5, 13)
    np.testing.assert_array_equal(seg.time_tai_ns, t[sel])
    np.testing.assert_allclose(seg.position_m, r_E[sel], rtol=1e-15)
    np.testing.assert_allclose(seg.velocity_m_s, v_E[sel], rtol=1e-15)
    assert "exported by the attitude service" in seg.comments[0]


def test_export_in_gcrf_and_version_2(api):
    t, _, _, r_I, v_I = _store_gnss(api)
    r = api.get("/api/v1/spacecraft/sat1/export/oem",
                params={"frame": "GCRF", "version": "2.0", "time_system": "TAI"})
    assert r.status_code == 200, r.text
    oem = parse_oem(r.text)
    seg = oem.segments[0]
    assert oem.version == "2.0" and seg.ref_frame == "GCRF" and seg.time_system == "TAI"
    np.testing.assert_allclose(seg.position_m, r_I, rtol=0, atol=1e-6)  # zero EOP both ways
    np.testing.assert_allclose(seg.velocity_m_s, v_I, rtol=0, atol=1e-9)
    assert any("zero (no EOP supplied)" in c for c in seg.comments)


def test_export_errors(api):
    _store_gnss(api)
    assert api.get("/api/v1/spacecraft/sat1/export/oem", params={"start": "2024-01-01T00:00:00Z"}).status_code == 404
    assert api.get("/api/v1/spacecraft/nosuch/export/oem").status_code == 404
    assert api.get("/api/v1/spacecraft/sat1/export/oem", params={"start": "yesterday"}).status_code == 422
    r = api.get("/api/v1/spacecraft/sat1/export/oem",
                params={"start": "2023-06-01T00:01:00Z", "end": "2023-06-01T00:00:00Z"})
    assert r.status_code == 422 and "before start" in r.text
    assert api.get("/api/v1/spacecraft/sat1/export/oem", params={"frame": "TEME"}).status_code == 422
    assert api.get("/api/v1/spacecraft/sat1/export/oem", headers={"Authorization": ""}).status_code == 401


def test_csv_cells_that_start_like_formulas_are_neutralised():
    import csv
    import io

    import pyarrow as pa
    import pyarrow.csv as pacsv

    from app.jobs.outputs import csv_cell, csv_safe

    values = ["=HYPERLINK(\"x\")", "+1", "-2+3", "@SUM(A1)", "\tx", "\rx", "a=b", "", None, "ok", "'=x"]
    table = pa.table({"text": values, "number": [-1.5] * len(values),
                      "dict": pa.array(values).dictionary_encode()})
    buf = io.BytesIO()
    pacsv.write_csv(csv_safe(table), buf)
    rows = list(csv.reader(io.StringIO(buf.getvalue().decode(), newline="")))[1:]
    expected = ["'" + v if v and v[0] in "=+-@\t\r" else (v or "") for v in values]
    assert [r[0] for r in rows] == expected and [r[2] for r in rows] == expected
    assert {r[1] for r in rows} == {"-1.5"}  # numbers are not text: negative ones stay numbers
    assert [csv_cell(v) for v in values] == ["'" + v if v and v[0] in "=+-@\t\r" else v for v in values]
    assert csv_cell(-3) == -3


def test_telemetry_csv_download_neutralises_sensor_names(client):
    make_spacecraft(client, config={})
    r = upload(client, "gyro", "time,wx,wy,wz\n2023-06-01T00:00:00Z,1,2,3\n", sensor="-x")
    assert r.status_code == 201, r.text
    csv_text = client.get("/api/v1/spacecraft/sat1/telemetry/gyro").text
    assert "'-x" in csv_text.splitlines()[1]
    assert client.get("/api/v1/spacecraft/sat1/telemetry/gyro", params={"format": "json"}).json()[0]["sensor"] == "-x"
