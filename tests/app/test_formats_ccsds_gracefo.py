"""Uploads in the named formats ccsds-aem, ccsds-oem and gracefo-l1b, and EOP reference data, through
the API (app/ingest/decoders/ccsds.py, gracefo.py; app/reference/kinds/eop.py)."""

import datetime as dt

import numpy as np
import pytest

from processing.attitude import rotations
from processing.formats.ccsds_adm import aem_segment, write_aem
from processing.formats.ccsds_odm import oem_segment, write_oem
from processing.frames.earth_orientation import gcrs_to_inertial_mat, gcrs_to_itrs_state
from processing.orbits.two_body import circular_orbit_state
from processing.time import timescales
from processing.units import R_EARTH_M
from tests.app.helpers import SQLITE_ONLY, make_spacecraft, upload
from tests.real_data import GRACEFO, REFERENCE

pytestmark = SQLITE_ONLY

TEXT = {"Content-Type": "text/plain"}
CREATED = dt.datetime(2023, 6, 1, tzinfo=dt.UTC)
GRACE = GRACEFO
EOP_FILE = REFERENCE / "finals2000A_2017-01-01_04.txt"
T0 = int(timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])
NS = 1_000_000_000


def _q(n: int = 5) -> np.ndarray:
    rng = np.random.default_rng(7)
    return rotations.quat_canonical(rotations.quat_normalize(rng.standard_normal((n, 4))))


def _aem(q_AB, frame_a="GCRF", frame_b="ST1") -> str:
    t = T0 + np.arange(len(q_AB)) * NS
    return write_aem([aem_segment(t, q_AB, object_name="SAT", object_id="2023-001A", ref_frame_a=frame_a,
                                  ref_frame_b=frame_b)], originator="TEST", creation_date=CREATED)


def _stored_quaternions(client, stream="star_tracker", sc="sat1"):
    rows = client.get(f"/api/v1/spacecraft/{sc}/telemetry/{stream}", params={"format": "json"}).json()
    return rows, np.array([[r[f"q{i}"] for i in range(4)] for r in rows])


def test_aem_upload_inertial_to_sensor_and_back(client):
    make_spacecraft(client)
    q = _q()
    r = upload(client, "star_tracker", _aem(q), TEXT, format="ccsds-aem")
    assert r.status_code == 201, r.text
    assert r.json()["rows"] == 5 and r.json()["sensor"] == "st1" and r.json()["start"] == "2023-06-01T00:00:00Z"
    rows, stored = _stored_quaternions(client)
    np.testing.assert_allclose(stored, q, atol=1e-15)  # REF_FRAME_A = GCRF: the quaternion is q_IS


def test_aem_with_sensor_first_and_frame_of_date_is_converted(client):
    make_spacecraft(client)
    q_IS_gcrf = _q()
    t = T0 + np.arange(5) * NS
    # The same attitude expressed as q_{S,MOD} (REF_FRAME_A = sensor, REF_FRAME_B = MOD): conjugate of q_{MOD,S}.
    q_mod_s = rotations.quat_multiply(rotations.dcm_to_quat(gcrs_to_inertial_mat("MOD", t)), q_IS_gcrf)
    text = _aem(rotations.quat_conjugate(q_mod_s), frame_a="STAR_TRACKER_1", frame_b="MOD")
    r = upload(client, "star_tracker", text, TEXT, format="ccsds-aem")
    assert r.status_code == 201, r.text
    _, stored = _stored_quaternions(client)
    np.testing.assert_allclose(np.abs(np.sum(stored * q_IS_gcrf, axis=1)), 1.0, atol=1e-14)


@pytest.mark.parametrize("body, message", [
    ("this is not an AEM", "starts with CCSDS_AEM_VERS"),
    ("@ITRF", "exactly one of them must be an inertial frame"),
    ("@BOTH", "exactly one of them must be an inertial frame"),
])
def test_bad_aem_uploads_are_422(client, body, message):
    make_spacecraft(client)
    if body == "@ITRF":
        body = _aem(_q(), frame_a="ITRF", frame_b="ST1")
    elif body == "@BOTH":
        body = _aem(_q(), frame_a="GCRF", frame_b="EME2000")
    r = upload(client, "star_tracker", body, TEXT, format="ccsds-aem")
    assert r.status_code == 422, r.text
    assert message in r.json()["errors"][0]["message"]
    assert upload(client, "gnss", _aem(_q()), TEXT, format="ccsds-aem").status_code == 422  # feeds star_tracker


def _orbit(n=5):
    t = T0 + np.arange(n) * 10 * NS
    r_I, v_I = circular_orbit_state(np.arange(n) * 10.0, R_EARTH_M + 500e3, 1.7, 0.5, 0.2)
    return t, r_I, v_I


def test_oem_upload_itrf_and_inertial(client):
    make_spacecraft(client)
    t, r_I, v_I = _orbit()
    r_E, v_E = gcrs_to_itrs_state(r_I, v_I, t)
    itrf = write_oem([oem_segment(t, r_E, v_E, object_name="SAT", object_id="X", ref_frame="ITRF2014")],
                     originator="TEST", version="2.0", creation_date=CREATED)
    r = upload(client, "gnss", itrf, TEXT, format="ccsds-oem")
    assert r.status_code == 201, r.text
    rows = client.get("/api/v1/spacecraft/sat1/telemetry/gnss", params={"format": "json"}).json()
    np.testing.assert_allclose([[x["x"], x["y"], x["z"]] for x in rows], r_E, rtol=1e-15)
    np.testing.assert_allclose([[x["vx"], x["vy"], x["vz"]] for x in rows], v_E, rtol=1e-14)
    # The same states in GCRF are converted to ITRF with zero EOP, i.e. to the same states (to rounding).
    make_spacecraft(client, "sat2")
    gcrf = write_oem([oem_segment(t, r_I, v_I, object_name="SAT", object_id="X", ref_frame="GCRF")],
                     originator="TEST", creation_date=CREATED)
    r = upload(client, "gnss", gcrf, TEXT, sc="sat2", format="ccsds-oem")
    assert r.status_code == 201, r.text
    rows = client.get("/api/v1/spacecraft/sat2/telemetry/gnss", params={"format": "json"}).json()
    np.testing.assert_allclose([[x["x"], x["y"], x["z"]] for x in rows], r_E, rtol=0, atol=1e-6)
    np.testing.assert_allclose([[x["vx"], x["vy"], x["vz"]] for x in rows], v_E, rtol=0, atol=1e-9)


@pytest.mark.parametrize("change, message", [
    (("CENTER_NAME = EARTH", "CENTER_NAME = MARS BARYCENTER"), "CENTER_NAME must be EARTH"),
    (("REF_FRAME = ITRF", "REF_FRAME = RTN"), "neither an ITRF nor a supported inertial frame"),
    (("TIME_SYSTEM = UTC", "TIME_SYSTEM = TDB"), "TIME_SYSTEM 'TDB' is not supported"),
    (("CCSDS_OEM_VERS", "CCSDS_OPM_VERS"), "starts with CCSDS_OEM_VERS"),
])
def test_bad_oem_uploads_are_422(client, change, message):
    make_spacecraft(client)
    t, r_I, v_I = _orbit()
    text = write_oem([oem_segment(t, r_I, v_I, object_name="SAT", object_id="X", ref_frame="ITRF")],
                     originator="TEST", creation_date=CREATED).replace(*change)
    r = upload(client, "gnss", text, TEXT, format="ccsds-oem")
    assert r.status_code == 422, r.text
    assert message in r.json()["errors"][0]["message"]


GRACE_CONFIG = {"star_trackers": {"sca": {"q_BS": [1, 0, 0, 0]}}, "gyro": {"q_BG": [1, 0, 0, 0]}}


@pytest.mark.parametrize("product, stream, rows", [
    # IMU1B: 34 gyro-1 epochs, 32 inside the spans of gyros 2 and 3 -> 30 central-difference rates, 31 increments
    ("SCA1B", "star_tracker", 100), ("GNV1B", "gnss", 100), ("IMU1B", "gyro", 30),
    ("IMU1B", "gyro_increments", 31), ("MAG1B", "magnetometer", 100),
])
def test_gracefo_products_ingest(client, product, stream, rows):
    make_spacecraft(client, "gracefo-c", GRACE_CONFIG)
    body = (GRACE / f"{product}_2023-06-01_C_04.txt").read_bytes()
    r = upload(client, stream, body, TEXT, sc="gracefo-c", format="gracefo-l1b")
    assert r.status_code == 201, r.text
    assert r.json()["rows"] == rows
    assert r.json()["start"].startswith("2023-05-31T23:59:42")  # GPS 2023-06-01T00:00:00 = UTC - 18 s
    if product == "SCA1B":
        _, stored = _stored_quaternions(client, sc="gracefo-c")
        # first row 0.07816222822585139 0.1642723922577685 -0.004109730449778668 0.9833048140804912 (q0 >= 0)
        np.testing.assert_allclose(stored[0], [0.07816222822585139, 0.1642723922577685, -0.004109730449778668,
                                               0.9833048140804912], rtol=1e-10)  # renormalised (3e-11)
    if product == "MAG1B":
        first = client.get("/api/v1/spacecraft/gracefo-c/telemetry/magnetometer", params={"format": "json"}).json()[0]
        assert first["bx"] == pytest.approx(12328.33957672119) and first["time"] == "2023-05-31T23:59:42.083329Z"


def test_gracefo_product_to_the_wrong_stream_or_garbage_is_422(client):
    make_spacecraft(client, "gracefo-c", GRACE_CONFIG)
    body = (GRACE / "SCA1B_2023-06-01_C_04.txt").read_bytes()
    r = upload(client, "gnss", body, TEXT, sc="gracefo-c", format="gracefo-l1b")
    assert r.status_code == 422 and "feeds the star_tracker stream, not gnss" in r.json()["errors"][0]["message"]
    r = upload(client, "gnss", b"header:\n  x: 1\n# End of YAML header\n1 2 3\n", TEXT, sc="gracefo-c",
               format="gracefo-l1b")
    assert r.status_code == 422 and "variables" in r.json()["errors"][0]["message"]
    r = upload(client, "star_tracker", b"not a GRACE-FO file\n", TEXT, sc="gracefo-c", format="gracefo-l1b")
    assert r.status_code == 422 and "End of YAML header" in r.json()["errors"][0]["message"]


def test_formats_are_listed(client):
    names = {f["format"]: f["streams"] for f in client.get("/api/v1/formats").json()}
    assert names["ccsds-aem"] == ["star_tracker"] and names["ccsds-oem"] == ["gnss"]
    assert set(names["gracefo-l1b"]) == {"star_tracker", "gnss", "gyro", "gyro_increments", "magnetometer"}


def test_eop_reference_upload(client):
    raw = EOP_FILE.read_bytes()
    r = client.post("/api/v1/reference/eop_finals2000a", content=raw,
                    params={"name": "finals2000A 2017-01", "filename": EOP_FILE.name})
    assert r.status_code == 201, r.text
    d = r.json()
    assert d["rows"] == 4 and d["start"] == "2017-01-01T00:00:00Z" and d["end"] == "2017-01-04T00:00:00Z"
    assert d["details"]["bulletin_b_rows"] == 4 and d["details"]["predicted_rows"] == 0
    data = client.get(f"/api/v1/reference/eop_finals2000a/{d['id']}/data", params={"format": "json"}).json()
    assert data[0]["dut1_s"] == 0.5912975 and data[0]["pm_source"] == "B"
    r = client.post("/api/v1/reference/eop_finals2000a", content=b"17 1 1 garbage\n")
    assert r.status_code == 422
