"""Upload API: all-or-nothing validation, idempotence, conflicts, formats, read-back."""

from __future__ import annotations

import io
import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from scipy.spatial.transform import Rotation

from tests.app.helpers import (
    ARROW,
    CSV,
    PARQUET,
    arrow_bytes,
    make_spacecraft,
    parquet_bytes,
    stored_files,
    upload,
)

GYRO_CSV = (
    "time,wx,wy,wz\n"
    "2023-06-01T00:00:00Z,0.001,0.002,0.003\n"
    "2023-06-01T00:00:00.1Z,0.001,0.002,0.003\n"
    "2023-06-01T00:00:00.2Z,0.001,0.002,0.003\n"
)


def assert_nothing_stored(client, settings, stream="gyro"):
    r = client.get(f"/api/v1/spacecraft/sat1/telemetry/{stream}?format=json")
    assert r.status_code == 200 and r.json() == []
    assert stored_files(settings) == []
    assert client.get("/api/v1/spacecraft/sat1/ingests").json() == []


def test_upload_csv_and_read_back(client):
    make_spacecraft(client)
    r = upload(client, "gyro", GYRO_CSV)
    assert r.status_code == 201, r.text
    body = r.json()
    assert (body["rows"], body["inserted"], body["duplicates"]) == (3, 3, 0)
    assert body["start"] == "2023-06-01T00:00:00Z" and body["end"] == "2023-06-01T00:00:00.200Z"
    rows = client.get("/api/v1/spacecraft/sat1/telemetry/gyro?format=json").json()
    assert [r["time"] for r in rows] == ["2023-06-01T00:00:00.000Z", "2023-06-01T00:00:00.100Z",
                                         "2023-06-01T00:00:00.200Z"]
    assert rows[0]["sensor"] == "gyro" and rows[0]["wz"] == 0.003


@pytest.mark.parametrize(
    ("csv", "row", "column", "fragment"),
    [
        ("time,wx,wy\n2023-06-01T00:00:00Z,1,2\n", None, "wz", "missing required column"),
        ("time,wx,wy,wz,temp\n2023-06-01T00:00:00Z,1,2,3,4\n", None, "temp", "unexpected column"),
        ("time,wx,wy,wzz\n2023-06-01T00:00:00Z,1,2,3\n", None, "wzz", "did you mean 'wz'"),
        ("time,wx,wy,wz\n2023-06-01T00:00:00Z,1,2,3\n2023-06-01T00:00:01Z,nan,2,3\n", 1, "wx", "finite"),
        ("time,wx,wy,wz\n2023-06-01T00:00:00Z,1,inf,3\n", 0, "wy", "finite"),
        ("time,wx,wy,wz\n2023-06-01T00:00:00Z,1,abc,3\n", 0, "wy", "not a number"),
        ("time,wx,wy,wz\n2023-06-01T00:00:00Z,1,,3\n", 0, "wy", "not a number"),
        ("time,wx,wy,wz\nyesterday,1,2,3\n", 0, "time", ""),
        ("time,wx,wy,wz\n2023-06-01T00:00:01Z,1,2,3\n2023-06-01T00:00:00Z,1,2,3\n", 1, "time", "backwards"),
        ("time,wx,wy,wz\n2023-06-01T00:00:01Z,1,2,3\n2023-06-01T00:00:01Z,1,2,3\n", 1, "time", "same time"),
        ("time,wx,wy,wz\n2017-06-30T23:59:60Z,1,2,3\n", 0, "time", ""),
    ],
)
def test_bad_rows_rejected_with_row_and_column(client, settings, csv, row, column, fragment):
    make_spacecraft(client)
    r = upload(client, "gyro", csv)
    assert r.status_code == 422, r.text
    errors = r.json()["errors"]
    assert any(e["row"] == row and e["column"] == column and fragment in e["message"] for e in errors), errors
    assert_nothing_stored(client, settings)


def test_one_bad_row_rejects_the_whole_batch(client, settings):
    make_spacecraft(client)
    lines = [f"2023-06-01T00:00:{i:02d}Z,1,2,3" for i in range(50)]
    lines[37] = "2023-06-01T00:00:37Z,1,2,NaN"
    r = upload(client, "gyro", "time,wx,wy,wz\n" + "\n".join(lines) + "\n")
    assert r.status_code == 422
    assert r.json()["errors"] == [{"row": 37, "column": "wz", "message": "value must be finite (got nan)"}]
    assert_nothing_stored(client, settings)


def test_error_list_is_capped_at_100(client, settings):
    make_spacecraft(client)
    lines = [f"2023-06-01T00:{i // 60:02d}:{i % 60:02d}Z,x,2,3" for i in range(300)]
    r = upload(client, "gyro", "time,wx,wy,wz\n" + "\n".join(lines) + "\n")
    assert r.status_code == 422
    assert r.json()["error_count"] == 300 and len(r.json()["errors"]) == 100


@pytest.mark.parametrize(
    ("body", "headers", "status"),
    [
        (b"", CSV, 422),
        (b"time,wx,wy,wz\n", CSV, 422),
        (b"PAR1garbage", PARQUET, 422),
        (b"[1, 2, 3]", {"Content-Type": "application/json"}, 422),
        (b"{not json", {"Content-Type": "application/json"}, 422),
        (b"time,wx,wy,wz\n2023-06-01T00:00:00Z,1,2,3\n", {"Content-Type": "application/xml"}, 415),
        (b"time,wx,wy,wz\n2023-06-01T00:00:00Z,1,2\n", CSV, 422),
    ],
)
def test_unreadable_bodies(client, settings, body, headers, status):
    make_spacecraft(client)
    r = upload(client, "gyro", body, headers)
    assert r.status_code == status, r.text
    assert_nothing_stored(client, settings)


def test_truncated_parquet_is_422(client, settings):
    make_spacecraft(client)
    table = pa.table({"time": [1.6e9, 1.6e9 + 1], "wx": [1.0, 2.0], "wy": [1.0, 2.0], "wz": [1.0, 2.0]})
    data = parquet_bytes(table)
    r = upload(client, "gyro", data[: len(data) // 2], PARQUET)
    assert r.status_code == 422 and "Parquet" in r.json()["errors"][0]["message"]
    assert_nothing_stored(client, settings)


def test_wrong_parquet_types(client, settings):
    make_spacecraft(client)
    table = pa.table({"time": [1.6e9], "wx": [True], "wy": [1.0], "wz": [1.0]})
    r = upload(client, "gyro", parquet_bytes(table), PARQUET)
    assert r.status_code == 422
    assert r.json()["errors"][0]["column"] == "wx"
    assert_nothing_stored(client, settings)


def test_unknown_spacecraft_and_stream(client):
    make_spacecraft(client)
    assert upload(client, "gyro", GYRO_CSV, sc="nosuch").status_code == 404
    r = upload(client, "gyroscope", GYRO_CSV)
    assert r.status_code == 404 and "unknown stream" in r.json()["detail"]


def test_identical_reupload_is_a_noop(client, settings):
    make_spacecraft(client)
    assert upload(client, "gyro", GYRO_CSV).status_code == 201
    files = stored_files(settings)
    r = upload(client, "gyro", GYRO_CSV)
    assert r.status_code == 201
    assert (r.json()["inserted"], r.json()["duplicates"], r.json()["status"]) == (0, 3, "duplicate")
    assert stored_files(settings) == files
    assert len(client.get("/api/v1/spacecraft/sat1/telemetry/gyro?format=json").json()) == 3


def test_partial_overlap_inserts_only_new_rows(client):
    make_spacecraft(client)
    upload(client, "gyro", GYRO_CSV)
    more = GYRO_CSV + "2023-06-01T00:00:00.3Z,0.001,0.002,0.003\n"
    r = upload(client, "gyro", more)
    assert (r.json()["inserted"], r.json()["duplicates"]) == (1, 3)
    assert len(client.get("/api/v1/spacecraft/sat1/telemetry/gyro?format=json").json()) == 4


def test_conflicting_reupload_is_409_and_stores_nothing(client, settings):
    make_spacecraft(client)
    upload(client, "gyro", GYRO_CSV)
    files = stored_files(settings)
    changed = GYRO_CSV.replace("00:00:00.2Z,0.001", "00:00:00.2Z,0.009") + "2023-06-01T00:00:00.3Z,1,1,1\n"
    r = upload(client, "gyro", changed)
    assert r.status_code == 409
    assert r.json()["conflicts"][0]["row"] == 2 and r.json()["conflicts"][0]["column"] == "wx"
    assert stored_files(settings) == files
    assert len(client.get("/api/v1/spacecraft/sat1/telemetry/gyro?format=json").json()) == 3
    assert len(client.get("/api/v1/spacecraft/sat1/ingests").json()) == 1


def test_star_tracker_quaternions(client, settings):
    make_spacecraft(client)
    rng = np.random.default_rng(1)
    q = Rotation.random(5, random_state=rng).as_quat(scalar_first=True)
    q[2] = -q[2]
    q[3] *= 1.0005  # within the default tolerance: normalised
    times = [f"2023-06-01T00:00:0{i}Z" for i in range(5)]
    records = [{"time": t, "qw": a, "qx": b, "qy": c, "qz": d} for t, (a, b, c, d) in zip(times, q, strict=True)]
    r = client.post("/api/v1/spacecraft/sat1/telemetry/star_tracker", json=records)
    assert r.status_code == 201, r.text
    back = client.get("/api/v1/spacecraft/sat1/telemetry/star_tracker?format=json").json()
    got = np.array([[b["q0"], b["q1"], b["q2"], b["q3"]] for b in back])
    expected = q / np.linalg.norm(q, axis=1, keepdims=True)
    expected *= np.sign(expected[:, :1])
    np.testing.assert_allclose(got, expected, atol=1e-15)
    assert all(b["sensor"] == "st1" for b in back)


def test_quaternion_norm_and_naming_errors(client, settings):
    make_spacecraft(client)
    r = upload(client, "star_tracker", "time,q0,q1,q2,q3\n2023-06-01T00:00:00Z,1,0,0,0.1\n")
    assert r.status_code == 422 and "norm" in r.json()["errors"][0]["message"]
    r = upload(client, "star_tracker", "time,q0,q1,q2,q3,qw\n2023-06-01T00:00:00Z,1,0,0,0,1\n")
    assert r.status_code == 422 and "not both" in r.json()["errors"][0]["message"]
    r = upload(client, "star_tracker", "time,qx,qy,qz,qs\n2023-06-01T00:00:00Z,0,0,0,1\n")
    assert r.status_code == 422
    r = upload(client, "star_tracker", "time,q0,q1,q2,q3\n2023-06-01T00:00:00Z,1,0,0,0\n", sensor="st9")
    assert r.status_code == 422 and "unknown sensor" in r.json()["errors"][0]["message"]
    assert_nothing_stored(client, settings, "star_tracker")


def test_quaternion_direction_inertial_to_sensor_is_conjugated(client):
    make_spacecraft(client)
    r = upload(client, "star_tracker", "time,q0,q1,q2,q3\n2023-06-01T00:00:00Z,0.6,0.8,0,0\n",
               quaternion_direction="inertial_to_sensor")
    assert r.status_code == 201
    back = client.get("/api/v1/spacecraft/sat1/telemetry/star_tracker?format=json").json()[0]
    assert [back[c] for c in ("q0", "q1", "q2", "q3")] == pytest.approx([0.6, -0.8, 0, 0])


def test_ambiguous_star_tracker_needs_sensor(client):
    make_spacecraft(client, config={"star_trackers": {"a": {"q_BS": [1, 0, 0, 0]}, "b": {"q_BS": [1, 0, 0, 0]}}})
    csv = "time,q0,q1,q2,q3\n2023-06-01T00:00:00Z,1,0,0,0\n"
    r = upload(client, "star_tracker", csv)
    assert r.status_code == 422 and "several star trackers" in r.json()["errors"][0]["message"]
    assert upload(client, "star_tracker", csv, sensor="b").status_code == 201
    # per-row sensor column, interleaved trackers with the same times
    csv2 = "time,sensor,q0,q1,q2,q3\n2023-06-01T00:00:01Z,a,1,0,0,0\n2023-06-01T00:00:01Z,b,1,0,0,0\n"
    assert upload(client, "star_tracker", csv2).status_code == 201
    assert len(client.get("/api/v1/spacecraft/sat1/telemetry/star_tracker?format=json&sensor=b").json()) == 2


def test_parquet_arrow_and_json_formats_agree(client):
    make_spacecraft(client)
    t = 1_685_577_600 + np.arange(10) * 0.125
    table = pa.table({"time": pa.array((t * 1e9).astype("int64"), pa.timestamp("ns", tz="UTC")),
                      "wx": np.linspace(0, 1, 10), "wy": np.zeros(10), "wz": np.ones(10)})
    assert upload(client, "gyro", parquet_bytes(table.slice(0, 4)), PARQUET).status_code == 201
    assert upload(client, "gyro", arrow_bytes(table.slice(4, 3)), ARROW).status_code == 201
    wx = table["wx"].to_numpy()
    records = [{"time": float(t[i]), "wx": float(wx[i]), "wy": 0.0, "wz": 1.0} for i in range(7, 10)]
    r = client.post("/api/v1/spacecraft/sat1/telemetry/gyro", json=records)
    assert r.status_code == 201, r.text
    # read back in every format
    as_json = client.get("/api/v1/spacecraft/sat1/telemetry/gyro?format=json&time_format=seconds").json()
    np.testing.assert_allclose([r["time"] for r in as_json], t, rtol=0, atol=1e-6)
    np.testing.assert_array_equal([r["wx"] for r in as_json], table["wx"].to_numpy())
    pq_resp = client.get("/api/v1/spacecraft/sat1/telemetry/gyro?format=parquet")
    assert pq_resp.headers["content-type"] == "application/vnd.apache.parquet"
    assert 'filename="sat1_gyro.parquet"' in pq_resp.headers["content-disposition"]
    assert pq.read_table(io.BytesIO(pq_resp.content)).num_rows == 10
    csv_resp = client.get("/api/v1/spacecraft/sat1/telemetry/gyro?format=csv")
    assert csv_resp.headers["content-type"].startswith("text/csv")
    assert csv_resp.text.count("\n") == 11


def test_downloaded_csv_uploads_again_as_duplicates(client):
    make_spacecraft(client)
    upload(client, "gyro", GYRO_CSV)
    csv = client.get("/api/v1/spacecraft/sat1/telemetry/gyro?format=csv").text
    r = upload(client, "gyro", csv)
    assert r.status_code == 201 and r.json()["duplicates"] == 3


@pytest.mark.parametrize("scale", ["tai", "gps", "tt"])
def test_numeric_times_on_other_scales(client, scale):
    make_spacecraft(client)
    r = upload(client, "gyro", "time,wx,wy,wz\n1483228837,1,2,3\n", time_scale=scale)
    assert r.status_code == 201
    back = client.get(f"/api/v1/spacecraft/sat1/telemetry/gyro?format=json&time_scale={scale}"
                      "&time_format=seconds").json()
    assert back[0]["time"] == pytest.approx(1483228837, abs=1e-6)


def test_leap_second_samples_are_distinct_and_windowed(client):
    make_spacecraft(client)
    csv = ("time,wx,wy,wz\n2016-12-31T23:59:59.5Z,1,1,1\n2016-12-31T23:59:60Z,2,2,2\n"
           "2016-12-31T23:59:60.5Z,3,3,3\n2017-01-01T00:00:00Z,4,4,4\n")
    assert upload(client, "gyro", csv).status_code == 201
    rows = client.get("/api/v1/spacecraft/sat1/telemetry/gyro", params={
        "format": "json", "start": "2016-12-31T23:59:60Z", "end": "2016-12-31T23:59:60.5Z"}).json()
    assert [r["time"] for r in rows] == ["2016-12-31T23:59:60.000Z", "2016-12-31T23:59:60.500Z"]
    tai = client.get("/api/v1/spacecraft/sat1/telemetry/gyro?format=json&time_scale=tai").json()
    assert tai[1]["time"] == "2017-01-01T00:00:36.000"


def test_panel_currents_and_visibility_keys(client):
    make_spacecraft(client)
    csv = ("time,panel,current_a\n2023-06-01T00:00:00Z,0,0.5\n2023-06-01T00:00:00Z,1,0.7\n"
           "2023-06-01T00:00:01Z,0,0.6\n")
    assert upload(client, "panel_currents", csv).status_code == 201
    bad = "time,panel,current_a\n2023-06-01T00:00:02Z,5,0.5\n"
    r = upload(client, "panel_currents", bad)
    assert r.status_code == 422 and r.json()["errors"][0]["column"] == "panel"
    vis = "time,system,prn,visible\n2023-06-01T00:00:00Z,G,1,true\n2023-06-01T00:00:00Z,R,1,0\n"
    assert upload(client, "gnss_visibility", vis).status_code == 201
    back = client.get("/api/v1/spacecraft/sat1/telemetry/gnss_visibility?format=json").json()
    assert {(b["system"], b["prn"], b["visible"]) for b in back} == {("G", 1, True), ("R", 1, False)}


def test_ingest_log(client):
    make_spacecraft(client)
    upload(client, "gyro", GYRO_CSV, filename="dump-001.csv")
    log = client.get("/api/v1/spacecraft/sat1/ingests").json()
    assert len(log) == 1 and log[0]["filename"] == "dump-001.csv" and log[0]["rows"] == 3
    assert len(log[0]["checksum_sha256"]) == 64


def test_json_records_wrapped(client):
    make_spacecraft(client)
    body = json.dumps({"records": [{"time": "2023-06-01T00:00:00Z", "wx": 1, "wy": 2, "wz": 3}]})
    r = client.post("/api/v1/spacecraft/sat1/telemetry/gyro", content=body,
                    headers={"Content-Type": "application/json"})
    assert r.status_code == 201


@pytest.mark.parametrize(("scale", "zoned"), [("tai", "2023-06-01T00:00:01Z"), ("gps", "2023-06-01T02:00:01+02:00"),
                                              ("tt", "2023-06-01T02:00:01.5+0200"), ("tai", "2023-05-31T19:00:01-05")])
def test_explicit_zone_with_another_time_scale_is_refused(client, settings, scale, zoned):
    """A 'Z' or '+HH:MM' makes a time UTC; reading it as a TAI/GPS/TT reading would move the row by 37/18/69 s."""
    make_spacecraft(client)
    csv = f"time,wx,wy,wz\n2023-06-01T00:00:00,1,2,3\n{zoned},1,2,3\n"
    r = upload(client, "gyro", csv, time_scale=scale)
    assert r.status_code == 422, r.text
    errors = r.json()["errors"]
    assert [(e["row"], e["column"]) for e in errors] == [(1, "time")]  # row 0 has no zone: a reading on the scale
    assert "explicit time zone" in errors[0]["message"] and f"time_scale={scale}" in errors[0]["message"]
    assert zoned in errors[0]["message"] and "time_scale=utc" in errors[0]["message"]
    assert_nothing_stored(client, settings)


def test_zoned_times_are_utc_and_naive_times_read_on_the_scale(client):
    make_spacecraft(client)
    assert upload(client, "gyro", "time,wx,wy,wz\n2023-06-01T02:00:00+02:00,1,2,3\n").status_code == 201  # utc
    assert upload(client, "gyro", "time,wx,wy,wz\n2023-06-01T00:00:37,1,2,3\n", time_scale="tai").status_code == 201
    rows = client.get("/api/v1/spacecraft/sat1/telemetry/gyro?format=json").json()
    # TAI - UTC = 37 s in 2023 (IERS Bulletin C): the TAI reading 00:00:37 is 00:00:00 UTC, the same instant,
    # so the second upload is a duplicate sample; before the fix a zoned time with time_scale=tai moved by 37 s
    assert [r["time"] for r in rows] == ["2023-06-01T00:00:00Z"]


def test_zoned_timestamps_with_another_time_scale_are_refused(client, settings):
    make_spacecraft(client)
    table = pa.table({"time": pa.array([1_685_577_600_000_000_000], pa.timestamp("ns", tz="UTC")),
                      "wx": [1.0], "wy": [2.0], "wz": [3.0]})
    r = upload(client, "gyro", parquet_bytes(table), PARQUET, time_scale="gps")
    assert r.status_code == 422, r.text
    (err,) = r.json()["errors"]
    assert err["row"] is None and err["column"] == "time"
    assert "time zone UTC" in err["message"] and "time_scale=gps" in err["message"] and "naive" in err["message"]
    assert_nothing_stored(client, settings)
    naive = table.set_column(0, "time", pa.array([1_685_577_600_000_000_000], pa.timestamp("ns")))
    assert upload(client, "gyro", parquet_bytes(naive), PARQUET, time_scale="gps").status_code == 201
