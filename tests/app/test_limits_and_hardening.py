"""Limits (body size, inflated size, rows, rate), pagination, security headers, CORS, hostile uploads."""

from __future__ import annotations

import datetime as dt
import gzip
import io
from dataclasses import replace

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from tests.app.helpers import CSV, PARQUET, make_spacecraft, stored_files, upload

GYRO = "time,wx,wy,wz\n" + "".join(f"2023-06-01T00:00:{i:02d}Z,1,2,3\n" for i in range(60))


@pytest.fixture
def limited(settings):
    def make(**changes):
        app = create_app(replace(settings, **changes))
        client = TestClient(app)
        client.__enter__()
        client.headers["Authorization"] = f"Bearer {settings.bootstrap_token}"
        make_spacecraft(client)
        made.append(client)
        return client

    made: list[TestClient] = []
    yield make
    for c in made:
        c.__exit__(None, None, None)


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_body_limit_on_every_route(limited, settings):
    client = limited(max_upload_bytes=1000)
    r = upload(client, "gyro", GYRO)  # ~1.6 kB
    assert r.status_code == 413 and "limit of 1000 bytes" in r.json()["detail"]

    def chunks():  # no Content-Length: the limit applies while streaming
        for _ in range(20):
            yield b"x" * 100

    r = client.post("/api/v1/spacecraft/sat1/telemetry/gyro", content=chunks(), headers=CSV)
    assert r.status_code == 413
    r = client.post("/api/v1/spacecraft", content=b"{" + b" " * 2000 + b"}",
                    headers={"Content-Type": "application/json"})
    assert r.status_code == 413
    assert stored_files(settings) == []


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_gzip_uploads_and_bombs(limited, settings):
    client = limited(max_upload_bytes=100_000)
    r = upload(client, "gyro", gzip.compress(GYRO.encode()), {**CSV, "Content-Encoding": "gzip"})
    assert r.status_code == 201 and r.json()["rows"] == 60
    bomb = gzip.compress(b"0" * 50_000_000)  # 50 MB of zeros in ~50 kB
    assert len(bomb) < 100_000
    r = upload(client, "gyro", bomb, {**CSV, "Content-Encoding": "gzip"})
    assert r.status_code == 413 and "inflated" in r.json()["detail"]
    r = upload(client, "gyro", b"\x1f\x8b\x08garbage", {**CSV, "Content-Encoding": "gzip"})
    assert r.status_code == 422
    r = upload(client, "gyro", gzip.compress(GYRO.encode())[:30], {**CSV, "Content-Encoding": "gzip"})
    assert r.status_code == 422 and "truncated" in r.json()["detail"]
    r = upload(client, "gyro", GYRO, {**CSV, "Content-Encoding": "br"})
    assert r.status_code == 415


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_gzip_members_are_all_stored_and_trailing_bytes_refused(limited, settings):
    # The red team's case: two gzip members answered 201 rows=1000 of 2000 (the second was dropped).
    client = limited(max_upload_bytes=100_000)
    head, rest = GYRO.split("\n", 1)
    first, second = rest[: len(rest) // 2], rest[len(rest) // 2:]
    two_members = gzip.compress((head + "\n" + first).encode()) + gzip.compress(second.encode())
    r = upload(client, "gyro", two_members, {**CSV, "Content-Encoding": "gzip"})
    assert r.status_code == 201 and r.json()["rows"] == 60 and r.json()["inserted"] == 60
    for trailing in (b"\x00\x00", b"garbage", b"\x1f"):
        r = upload(client, "gyro", gzip.compress(GYRO.encode()) + trailing, {**CSV, "Content-Encoding": "gzip"})
        assert r.status_code == 422, trailing
        assert "trailing" in r.json()["detail"] or "truncated" in r.json()["detail"]
    assert len(stored_files(settings)) == 1  # only the first, whole upload


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_row_limit(limited):
    client = limited(max_upload_rows=10)
    r = upload(client, "gyro", GYRO)
    assert r.status_code == 413 and "10 rows per upload" in r.json()["detail"]


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_rate_limit_per_key(limited):
    client = limited(rate_limit_per_minute=5)  # make_spacecraft used one request
    statuses = [client.get("/api/v1/spacecraft").status_code for _ in range(6)]
    assert statuses[:4] == [200] * 4 and statuses[-1] == 429
    r = client.get("/api/v1/spacecraft")
    assert r.status_code == 429 and int(r.headers["retry-after"]) >= 1


def test_pagination_of_jobs(client):
    make_spacecraft(client)
    ids = {client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1"}).json()["id"]
           for _ in range(5)}
    seen, cursor, pages = [], None, 0
    while True:
        r = client.get("/api/v1/jobs", params={"limit": 2, **({"cursor": cursor} if cursor else {})})
        assert r.status_code == 200
        seen += [j["id"] for j in r.json()]
        pages += 1
        cursor = r.headers.get("x-next-cursor")
        if not cursor:
            break
        assert 'rel="next"' in r.headers["link"]
    assert pages == 3 and len(seen) == 5 and set(seen) == ids
    assert client.get("/api/v1/jobs", params={"cursor": "!!!"}).status_code == 422
    assert client.get("/api/v1/jobs", params={"limit": 10_000}).status_code == 422


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_security_headers_and_no_cors_by_default(client):
    r = client.get("/api/v1/spacecraft")
    assert r.headers["x-content-type-options"] == "nosniff" and r.headers["x-frame-options"] == "DENY"
    assert r.headers["cache-control"] == "no-store" and r.headers["referrer-policy"] == "no-referrer"
    pre = client.options("/api/v1/spacecraft", headers={"Origin": "https://evil.example",
                                                         "Access-Control-Request-Method": "GET"})
    assert "access-control-allow-origin" not in pre.headers


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_cors_when_configured(limited):
    client = limited(cors_origins=("https://ops.example",))
    r = client.get("/api/v1/spacecraft", headers={"Origin": "https://ops.example"})
    assert r.headers["access-control-allow-origin"] == "https://ops.example"
    r = client.get("/api/v1/spacecraft", headers={"Origin": "https://evil.example"})
    assert "access-control-allow-origin" not in r.headers


def _parquet(**cols):
    buf = io.BytesIO()
    pq.write_table(pa.table(cols), buf)
    return buf.getvalue()


HOSTILE = [
    ("non-UTF-8 CSV", b"time,wx,wy,wz\n2023-06-01T00:00:00Z,\xff\xfe,2,3\n", CSV, {}, 422),
    ("binary garbage as CSV", bytes(range(256)) * 4, CSV, {}, 422),
    ("ragged CSV", b"time,wx,wy,wz\n2023-06-01T00:00:00Z,1,2,3,4,5\n", CSV, {}, 422),
    ("quote soup", b'time,wx,wy,wz\n"2023-06-01T00:00:00Z,1,2,3\n', CSV, {}, 422),
    ("huge numbers", b"time,wx,wy,wz\n2023-06-01T00:00:00Z,1e400,2,3\n", CSV, {}, 422),
    ("huge time", b"time,wx,wy,wz\n1e300,1,2,3\n", CSV, {}, 422),
    ("year 99999", b"time,wx,wy,wz\n99999-06-01T00:00:00Z,1,2,3\n", CSV, {}, 422),
    ("very long string", ("time,wx,wy,wz\n" + "9" * 100_000 + "-06-01T00:00:00Z,1,2,3\n").encode(), CSV, {}, 422),
    ("long sensor", b"time,wx,wy,wz\n2023-06-01T00:00:00Z,1,2,3\n", CSV, {"sensor": "s" * 5000}, 422),
    ("path-like sensor", b"time,wx,wy,wz\n2023-06-01T00:00:00Z,1,2,3\n", CSV, {"sensor": "../../etc"}, 422),
    ("string Parquet column", _parquet(time=["2023-06-01T00:00:00Z"], wx=["x"], wy=[1.0], wz=[1.0]), PARQUET, {}, 422),
    ("nested Parquet column", _parquet(time=[1.7e9], wx=[[1.0]], wy=[1.0], wz=[1.0]), PARQUET, {}, 422),
    ("null Parquet values", _parquet(time=[1.7e9], wx=pa.array([None], pa.float64()), wy=[1.0], wz=[1.0]),
     PARQUET, {}, 422),
    ("NaN time", _parquet(time=[np.nan], wx=[1.0], wy=[1.0], wz=[1.0]), PARQUET, {}, 422),
    ("JSON with nested objects", b'[{"time": {"a": 1}, "wx": 1, "wy": 2, "wz": 3}]',
     {"Content-Type": "application/json"}, {}, 422),
    ("JSON scalar", b"42", {"Content-Type": "application/json"}, {}, 422),
    ("deeply nested JSON", b"[" * 100_000 + b"]" * 100_000, {"Content-Type": "application/json"}, {}, 422),
]


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
@pytest.mark.parametrize(("what", "body", "headers", "params", "status"), HOSTILE, ids=[h[0] for h in HOSTILE])
def test_hostile_uploads(client, settings, what, body, headers, params, status):
    make_spacecraft(client)
    r = upload(client, "gyro", body, headers, **params)
    assert r.status_code == status, (what, r.status_code, r.text[:300])
    assert stored_files(settings) == []


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_path_like_names_stay_metadata(client, settings):
    make_spacecraft(client)
    r = upload(client, "gyro", GYRO, filename="../../../../etc/passwd")
    assert r.status_code == 201
    assert client.get("/api/v1/spacecraft/sat1/ingests").json()[0]["filename"] == "../../../../etc/passwd"
    assert all(settings.telemetry_dir in p.parents for p in stored_files(settings))
    assert client.post("/api/v1/spacecraft", json={"name": "../x"}).status_code == 422
    assert client.get("/api/v1/spacecraft/sat1/telemetry/..%2F..%2Fetc").status_code == 404


def _b64(text: str) -> str:
    import base64

    return base64.urlsafe_b64encode(text.encode()).decode()


@pytest.mark.parametrize("cursor", [_b64("2999-01-01T00:00:00|zz"), _b64("2023-06-01T00:00:00+00:00|"),
                                    _b64("2023-06-01T00:00:00+00:00|" + "a" * 500), _b64("garbage"),
                                    _b64("2023-06-01T00:00:00+00:00|'; DROP TABLE job;--"), "A" * 5000, "!!!"])
def test_crafted_cursors_are_422_on_every_listing(client, cursor):
    # The red team's case: a cursor holding a naive date gave 500 on /jobs, /keys, /reference, /ingests.
    make_spacecraft(client)
    for path in ("/api/v1/jobs", "/api/v1/keys", "/api/v1/reference", "/api/v1/spacecraft/sat1/ingests"):
        r = client.get(path, params={"cursor": cursor})
        assert r.status_code == 422 and "cursor" in r.json()["detail"], (path, r.status_code, r.text[:200])


def test_a_cursor_with_another_time_zone_still_pages(client):
    make_spacecraft(client)
    for _ in range(3):
        client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1"})
    r = client.get("/api/v1/jobs", params={"limit": 1})
    import base64

    raw = base64.urlsafe_b64decode(r.headers["x-next-cursor"] + "==").decode()
    when, item = raw.split("|")
    shifted = dt.datetime.fromisoformat(when).astimezone(dt.timezone(dt.timedelta(hours=5)))
    same = client.get("/api/v1/jobs", params={"limit": 1, "cursor": _b64(f"{shifted.isoformat()}|{item}")})
    following = client.get("/api/v1/jobs", params={"limit": 1, "cursor": r.headers["x-next-cursor"]})
    assert same.status_code == 200 and len(same.json()) == 1
    assert [j["id"] for j in same.json()] == [j["id"] for j in following.json()]  # (statuses move meanwhile)


def test_job_windows_outside_the_supported_years_are_422(client):
    make_spacecraft(client)
    assert upload(client, "gyro", GYRO).status_code == 201
    for start, end, scale in [("1900-01-01T00:00:00", "2200-01-01T00:00:00", "tai"),  # the red team's 300 years
                              ("2023-06-01T00:00:00Z", "2200-01-01T00:00:00Z", "utc"),
                              (-1e9, 1.7e9, "utc"), (1.7e9, 9e9, "gps")]:
        r = client.post("/api/v1/jobs", json={"type": "telemetry_coverage", "spacecraft": "sat1", "start": start,
                                              "end": end, "time_scale": scale})
        assert r.status_code == 422 and "1972" in str(r.json()["detail"]), (start, end, r.text)
        r = client.get("/api/v1/spacecraft/sat1/telemetry/gyro", params={"start": start, "end": end,
                                                                         "time_scale": scale})
        assert r.status_code == 422, (start, end, r.text)
    assert client.get("/api/v1/jobs").json() == []


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_job_params_bounded_in_depth_items_and_strings(client):
    make_spacecraft(client)
    assert upload(client, "gyro", GYRO).status_code == 201
    deep: dict = {"a": 1}
    for _ in range(900):
        deep = {"x": deep}
    cases = [("telemetry_coverage", {"gap_factor": deep}, "nested 90"),  # the API gate: body too deep
             ("reconstruction", {"stage_params": {"gyro_bias_fit": {"sensor": [[[[["g"]]]]]}}}, "nested deeper"),
             ("gyro_bias_fit", {"subintervals": [64] * 5000}, "5000 items"),
             ("gyro_bias_fit", {"subintervals": [2] * 9}, "subintervals"),  # the field's own bound
             ("gyro_bias_fit", {"sensor": ["g"] * 65}, "65 items"),
             ("gyro_bias_fit", {"sensor": "g" * 5000}, "5000 characters"),
             ("reconstruction", {"stage_params": {f"s{i}": {} for i in range(100)}}, "100 items")]
    for job_type, params, fragment in cases:
        r = client.post("/api/v1/jobs", json={"type": job_type, "spacecraft": "sat1", "params": params})
        assert r.status_code == 422 and fragment in r.text, (job_type, r.status_code, r.text[:300])
    assert client.get("/api/v1/jobs").json() == []


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_every_job_types_list_params_are_bounded(client):
    """Generic over the registry: any list-valued parameter of any job type refuses 65 items at submission."""
    from app.jobs.registry import registry

    make_spacecraft(client)
    assert upload(client, "gyro", GYRO).status_code == 201
    checked = 0
    for jt in registry().values():
        for name, field in jt.params.model_fields.items():
            if "list" not in str(field.annotation).lower():
                continue
            r = client.post("/api/v1/jobs", json={"type": jt.name, "spacecraft": "sat1", "params": {name: [1] * 65}})
            assert r.status_code == 422, (jt.name, name, r.text[:200])
            checked += 1
    assert checked >= 5 and client.get("/api/v1/jobs").json() == []


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_reconstruction_stage_params_validated_at_submission(client):
    make_spacecraft(client)
    assert upload(client, "gyro", GYRO).status_code == 201
    for stage_params, fragment in [({"gyro_bias_fit": {"bogus": 1}}, "bogus"),
                                   ({"gyro_bias_fit": {"max_iterations": -3}}, "max_iterations"),
                                   ({"no_such_stage": {}}, "no_such_stage")]:
        r = client.post("/api/v1/jobs", json={"type": "reconstruction", "spacecraft": "sat1",
                                              "params": {"stage_params": stage_params}})
        assert r.status_code == 422 and fragment in r.text, (stage_params, r.text[:300])
    assert client.get("/api/v1/jobs").json() == []
    r = client.post("/api/v1/jobs", json={"type": "reconstruction", "spacecraft": "sat1",
                                          "params": {"stage_params": {"gyro_bias_fit": {"max_iterations": 7}}}})
    assert r.status_code == 202
    stored = client.get(f"/api/v1/jobs/{r.json()['id']}").json()["params"]["stage_params"]["gyro_bias_fit"]
    assert stored["max_iterations"] == 7 and "subintervals" in stored  # stored as the stage's validated values


@pytest.mark.parametrize(("cron", "ok"), [("* * * * * *", False), ("* * * * * */30", False),  # seconds last
                                          ("* * * * * 0,1", False), ("0 * * * * *", False), ("* * * * * 0", True),
                                          ("* * * * *", True),
                                          ("@hourly", True), ("x" * 300, False)])
@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_cron_period_floor(client, cron, ok):
    make_spacecraft(client)
    r = client.post("/api/v1/schedules", json={"name": "s", "cron": cron, "type": "telemetry_coverage",
                                               "spacecraft": "sat1"})
    assert r.status_code == (201 if ok else 422), r.text[:300]


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_cron_floor_is_a_setting(limited):
    client = limited(min_schedule_period_s=1)
    r = client.post("/api/v1/schedules", json={"name": "s", "cron": "* * * * * *", "type": "telemetry_coverage",
                                               "spacecraft": "sat1"})
    assert r.status_code == 201


def _depth_by_parsing(value) -> int:
    if isinstance(value, dict):
        return 1 + max((_depth_by_parsing(v) for v in value.values()), default=0)
    if isinstance(value, list):
        return 1 + max((_depth_by_parsing(v) for v in value), default=0)
    return 0


@pytest.mark.sqlite_only
def test_json_depth_scan_agrees_with_a_parser():
    import json

    from app.api.gate import json_depth

    rng = np.random.default_rng(7)
    tricky = ['a"b', "[[[", "}}]", "\\", '\\"[', "\\\\", '{"x": ["\\\\\\"]"]}']
    for _ in range(300):
        value: object = str(rng.choice(tricky))
        for _ in range(int(rng.integers(0, 12))):
            value = [value, "]"] if rng.random() < 0.5 else {str(rng.choice(tricky)): value}
        text = json.dumps(value, indent=int(rng.integers(0, 2)) or None)
        assert json_depth(text.encode()) == _depth_by_parsing(value), text
    assert json_depth(b"") == 0 and json_depth(b"[" * 100_000) == 100_000


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_json_bodies_and_query_strings_are_bounded(client):
    make_spacecraft(client)
    big = {"type": "executor_check", "spacecraft": "sat1", "params": {}, "reference": {"k": "x" * (2 << 20)}}
    r = client.post("/api/v1/jobs", json=big)
    assert r.status_code == 413 and "limit" in r.json()["detail"]
    r = client.get("/api/v1/jobs", params={"type": "x" * 10_000})
    assert r.status_code == 414 and "query string" in r.json()["detail"]
    r = client.put("/api/v1/spacecraft/sat1/config", content=b"[" * 40 + b"]" * 40,
                   headers={"Content-Type": "application/json"})
    assert r.status_code == 422 and "nested" in r.json()["detail"]
    assert client.get("/api/v1/jobs").json() == []


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_json_records_with_many_distinct_keys_are_refused_fast(client, settings):
    # The red team's case: 6,000 records of distinct keys (83 kB) took 10 s and 838 MB (records x keys).
    import json
    import time

    make_spacecraft(client)
    records = [{"time": "2023-06-01T00:00:00Z", f"k{i}": 1} for i in range(6000)]
    t0 = time.perf_counter()
    r = upload(client, "gyro", json.dumps(records), {"Content-Type": "application/json"})
    assert r.status_code == 422 and "distinct keys" in r.text, r.text[:300]
    assert time.perf_counter() - t0 < 5  # linear in the body (about 0.1 s unloaded)
    assert stored_files(settings) == []


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_parquet_rows_and_decoded_size_checked_from_the_footer(limited, settings, monkeypatch):
    client = limited(max_upload_rows=1000)
    many = pa.table({"time": pa.array(np.full(200_000, 1.7e9)), "wx": np.zeros(200_000), "wy": np.zeros(200_000),
                     "wz": np.zeros(200_000)})
    body = _parquet(**{n: many.column(n) for n in many.column_names})
    assert len(body) < 50_000  # constant columns: a small file of many rows

    def no_decoding(*args, **kwargs):
        raise AssertionError("the rows were decoded")

    monkeypatch.setattr(pq.ParquetFile, "read", no_decoding)
    monkeypatch.setattr(pq, "read_table", no_decoding)
    r = upload(client, "gyro", body, PARQUET)
    assert r.status_code == 413 and "200000 rows exceed the limit of 1000" in r.json()["detail"]
    monkeypatch.undo()
    arrow = pa.ipc.new_stream  # Arrow streams: read batch by batch, refused at the first batch too many
    sink = io.BytesIO()
    with arrow(sink, many.schema) as writer:
        for batch in many.to_batches(max_chunksize=600):
            writer.write_batch(batch)
    r = upload(client, "gyro", sink.getvalue(), {"Content-Type": "application/vnd.apache.arrow.stream"})
    assert r.status_code == 413 and "at least 1200 rows" in r.json()["detail"]
    r = upload(client, "gyro", "time,wx,wy,wz\n" + "2023-06-01T00:00:00Z,1,2,3\n" * 1001)
    assert r.status_code == 413 and "1001 rows" in r.json()["detail"]
    assert stored_files(settings) == []


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_an_upload_spread_over_too_many_days_is_refused_before_writing(client, settings):
    # The red team's case: 20,000 rows on 20,000 days took 192 s and wrote 22,300 files.
    import time

    make_spacecraft(client)
    days = 1.5e9 + 86400.0 * np.arange(20_000)
    body = "time,wx,wy,wz\n" + "".join(f"{t:.0f},1,2,3\n" for t in days)
    t0 = time.perf_counter()
    r = upload(client, "gyro", body)
    assert r.status_code == 413 and "20000 different days" in r.json()["detail"], r.text[:300]
    assert time.perf_counter() - t0 < 10
    assert stored_files(settings) == []


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
def test_the_day_cap_is_a_setting(limited, settings):
    client = limited(max_upload_days=3)
    days = 1.5e9 + 86400.0 * np.arange(4)
    assert upload(client, "gyro", "time,wx,wy,wz\n" + "".join(f"{t:.0f},1,2,3\n" for t in days)).status_code == 413
    r = upload(client, "gyro", "time,wx,wy,wz\n" + "".join(f"{t:.0f},1,2,3\n" for t in days[:3]))
    assert r.status_code == 201 and len(stored_files(settings)) == 3  # the limit itself is allowed


def test_reads_beyond_the_row_cap_are_413_and_narrower_windows_work(limited):
    client = limited(max_read_rows=50)
    assert upload(client, "gyro", GYRO).status_code == 201  # 60 rows in one file
    r = client.get("/api/v1/spacecraft/sat1/telemetry/gyro")
    assert r.status_code == 413 and "narrower" in r.json()["detail"]
    r = client.get("/api/v1/spacecraft/sat1/telemetry/gyro", params={"format": "json", "end": "2023-06-01T00:00:10Z"})
    assert r.status_code == 413  # the file overlapping the window counts whole (known before reading)
    r = client.get("/api/v1/spacecraft/sat1/telemetry/gyro", params={"start": "2023-06-02T00:00:00Z"})
    assert r.status_code == 200


def _wait_status(client, job_id, wanted, timeout_s=60.0):
    import time

    deadline = time.monotonic() + timeout_s
    while (status := client.get(f"/api/v1/jobs/{job_id}").json()["status"]) not in wanted:
        assert time.monotonic() < deadline, f"job {job_id} still {status}"
        time.sleep(0.05)
    return status


def test_one_key_cannot_take_every_job_slot(limited):
    """max_jobs 2, one job per key at once: the second key's job runs while the first key's wait."""
    client = limited(max_jobs=2, max_jobs_per_key=1, max_queued_jobs_per_key=2)
    other = {"Authorization": "Bearer " + client.post("/api/v1/keys", json={"name": "o", "role": "operator"}
                                                      ).json()["secret"]}
    long = {"type": "executor_check", "spacecraft": "sat1", "params": {"duration_s": 60}}
    first = client.post("/api/v1/jobs", json=long).json()["id"]
    _wait_status(client, first, ("running",))
    mine = [client.post("/api/v1/jobs", json=long).json()["id"] for _ in range(2)]
    r = client.post("/api/v1/jobs", json=long)  # a third waiting job of this key
    assert r.status_code == 429 and "queued jobs" in r.json()["detail"]
    theirs = client.post("/api/v1/jobs", json=long, headers=other).json()["id"]
    _wait_status(client, theirs, ("running",))  # the free slot goes to the other key
    assert [client.get(f"/api/v1/jobs/{j}").json()["status"] for j in mine] == ["queued", "queued"]
    for j in (first, theirs, *mine):
        client.post(f"/api/v1/jobs/{j}/cancel")
    for j in (first, theirs):
        _wait_status(client, j, ("cancelled", "failed"), timeout_s=30)


@pytest.mark.sqlite_only
def test_fair_queued_ids_shares_slots_between_keys(tmp_path):
    from storage import jobs as jobstore
    from storage.db import make_engine, session_factory, upgrade
    from storage.models import Job, Spacecraft

    engine = make_engine(f"sqlite:///{tmp_path / 'c.db'}")
    upgrade(engine)
    sessions = session_factory(engine)
    base = dt.datetime(2026, 1, 1, tzinfo=dt.UTC)
    from storage.keys import create_key

    with sessions.begin() as s:
        s.add(Spacecraft(id=1, name="x"))
        ids = {name: create_key(s, name=name, role="operator")[0].id for name in "abc"}
        jobs = [("a", "running"), ("a", "queued"), ("a", "queued"), ("a", "queued"), ("b", "queued"),
                ("c", "queued"), ("b", "queued"), (None, "queued")]
        for i, (key, status) in enumerate(jobs):
            s.add(Job(id=f"j{i}", type="executor_check", spacecraft_id=1, config_version=1, start_tai_ns=0,
                      end_tai_ns=1, params={}, status=status, progress=0.0, stage="", software_version="t",
                      api_key_id=ids.get(key), cancel_requested=False, reference={},
                      created_at=base + dt.timedelta(seconds=i)))
    with sessions() as s:
        assert jobstore.fair_queued_ids(s, 3, per_key=2) == ["j4", "j5", "j7"]  # b, c, no key: none running
        assert jobstore.fair_queued_ids(s, 5, per_key=2) == ["j4", "j5", "j7", "j1", "j6"]  # then a (1 running)
        assert jobstore.fair_queued_ids(s, 10, per_key=1) == ["j4", "j5", "j7"]  # a has its one running
        assert jobstore.fair_queued_ids(s, 0, per_key=5) == []
    engine.dispose()


@pytest.mark.sqlite_only  # HTTP-level limit: the catalog's backend plays no part
@pytest.mark.parametrize("name", [".", "..", "...", "a\n", "a\r", "a\t", "\x00", "a b", "é"])
def test_names_are_refused_everywhere(client, name):
    make_spacecraft(client, "sat1", {})
    assert client.post("/api/v1/spacecraft", json={"name": name, "config": {}}).status_code == 422
    bad_config = {"star_trackers": {name: {"q_BS": [1, 0, 0, 0]}}}
    assert client.put("/api/v1/spacecraft/sat1/config", json=bad_config).status_code == 422
    r = upload(client, "gyro", "time,wx,wy,wz\n2023-06-01T00:00:00Z,1,2,3\n", sensor=name)
    assert r.status_code == 422 and "sensor" in r.text
    r = client.post("/api/v1/schedules", json={"name": name, "cron": "0 2 * * *", "type": "telemetry_coverage",
                                               "spacecraft": "sat1"})
    assert r.status_code == 422
    if name.strip() and not name.isprintable():
        assert client.post("/api/v1/keys", json={"name": name, "role": "viewer"}).status_code == 422
    assert [s["name"] for s in client.get("/api/v1/spacecraft").json()] == ["sat1"]
    assert client.get("/api/v1/spacecraft/sat1/ingests").json() == []


@pytest.mark.sqlite_only
def test_sliding_windows_of_gyro_bias_fit_are_bounded_before_fitting():
    import time

    from processing.tasks import TaskError
    from tests.app.test_job_gyro_bias_fit import run, scenario

    sc = scenario(duration_s=300.0, gyro_period_s=1.0)
    t0 = time.perf_counter()
    with pytest.raises(TaskError, match="at most 2000"):
        run(sc, sliding_window_s=10.0, sliding_step_s=0.01)  # ~29,000 fits over the 300 s segment
    assert time.perf_counter() - t0 < 5  # refused before the whole-segment fit
