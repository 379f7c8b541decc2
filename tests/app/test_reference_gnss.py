"""Reference kinds rinex_nav and reference_orbit: upload the shared RINEX files through the API."""

from __future__ import annotations

import io

import numpy as np
import pyarrow.parquet as pq

from processing.formats.ccsds_odm import oem_segment, write_oem
from processing.orbits.gnss_ephemeris import satellite_positions_E
from processing.time import timescales
from tests.app.helpers import SQLITE_ONLY
from tests.real_data import GNSS_NAV

pytestmark = SQLITE_ONLY

NAV_DIR = GNSS_NAV


def test_kinds_are_listed(client) -> None:
    kinds = {k["kind"] for k in client.get("/api/v1/reference/kinds").json()}
    assert {"rinex_nav", "reference_orbit"} <= kinds


def test_upload_rinex_files_and_use_the_stored_columns(client) -> None:
    raw2 = (NAV_DIR / "brdc2800.15n").read_bytes()
    r = client.post("/api/v1/reference/rinex_nav", content=raw2, params={"filename": "brdc2800.15n"})
    assert r.status_code == 201, r.text
    d = r.json()
    assert d["rows"] == 420 and d["details"]["systems"] == ["G"] and d["details"]["n_satellites"] == 32
    assert d["start"] == "2015-10-06T21:59:43Z" and d["details"]["version"] == 2.0  # first toe - 2 h
    raw3 = (NAV_DIR / "BRDM00DLR_R_20130010000_01D_MN.rnx").read_bytes()
    r3 = client.post("/api/v1/reference/rinex_nav", content=raw3, params={"filename": "BRDM.rnx"})
    assert r3.status_code == 201, r3.text
    assert r3.json()["rows"] == 10 and r3.json()["details"]["systems"] == ["G", "J", "R"]
    # the stored columns (what a job receives) evaluate like the parsed file
    data = client.get(f"/api/v1/reference/rinex_nav/{r3.json()['id']}/data", params={"format": "parquet"})
    assert data.status_code == 200
    cols = {c: col.to_numpy(zero_copy_only=False) for c, col in zip(
        *(lambda t: (t.column_names, t.columns))(pq.read_table(io.BytesIO(data.content))), strict=True)}
    t = timescales.iso_to_tai_ns(["2013-01-01T00:30:00"])
    pos = satellite_positions_E(cols, t)
    assert pos.sats.tolist() == ["G01", "G02", "J01", "R01", "R02"]
    assert pos.valid[0].tolist() == [True, True, False, True, True]
    assert client.get(f"/api/v1/reference/rinex_nav/{d['id']}/data", params={"format": "raw"}).content == raw2


def test_bad_navigation_file_is_422(client) -> None:
    text = (NAV_DIR / "BRDM00DLR_R_20130010000_01D_MN.rnx").read_text().splitlines()
    r = client.post("/api/v1/reference/rinex_nav", content="\n".join(text[:16]).encode())
    assert r.status_code == 422 and "truncated" in r.json()["detail"]
    r = client.post("/api/v1/reference/rinex_nav", content=b"not a rinex file\n")
    assert r.status_code == 422 and "RINEX header" in r.json()["detail"]
    assert client.get("/api/v1/reference", params={"kind": "rinex_nav"}).json() == []


def test_reference_orbit_csv_and_oem(client) -> None:
    t = timescales.iso_to_tai_ns(["2015-10-07T06:00:00", "2015-10-07T06:01:00", "2015-10-07T06:02:00",
                                  "2015-10-07T06:03:00"])
    r = np.array([[6.9e6, 0.0, 0.0], [6.9e6, 4.5e5, 0.0], [6.88e6, 9.0e5, 0.0], [6.84e6, 1.35e6, 0.0]])
    v = np.tile([0.0, 7.6e3, 0.0], (4, 1))
    iso = timescales.tai_ns_to_iso(t)
    csv = "# frame: GCRF\ntime,x,y,z,vx,vy,vz\n" + "".join(
        f"{s},{a[0]},{a[1]},{a[2]},{b[0]},{b[1]},{b[2]}\n" for s, a, b in zip(iso, r, v, strict=True))
    res = client.post("/api/v1/reference/reference_orbit", content=csv.encode())
    assert res.status_code == 201, res.text
    assert res.json()["details"] == {"frame": "GCRF", "earth_fixed": False, "source": "CSV", "n_states": 4,
                                     "sha256": res.json()["details"]["sha256"]}
    oem = write_oem([oem_segment(t, r, v, object_name="SAT", object_id="2015-000A", ref_frame="ITRF")],
                    originator="TEST")
    res = client.post("/api/v1/reference/reference_orbit", content=oem.encode())
    assert res.status_code == 201, res.text
    assert res.json()["details"]["earth_fixed"] is True and res.json()["rows"] == 4
    rows = client.get(f"/api/v1/reference/reference_orbit/{res.json()['id']}/data", params={"format": "json"}).json()
    assert rows[0]["x"] == 6.9e6 and rows[1]["vy"] == 7.6e3
    bad = client.post("/api/v1/reference/reference_orbit", content=b"time,x,y\n2015-10-07T00:00:00Z,1,2\n")
    assert bad.status_code == 422 and "missing" in bad.json()["detail"]
    km = "time,x,y,z,vx,vy,vz\n" + "".join(
        f"{s},{a[0] / 1e3},{a[1] / 1e3},{a[2] / 1e3},{b[0]},{b[1]},{b[2]}\n" for s, a, b in zip(iso, r, v, strict=True))
    res = client.post("/api/v1/reference/reference_orbit", content=km.encode())
    assert res.status_code == 422 and "metres" in res.json()["detail"]
