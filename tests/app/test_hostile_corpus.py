"""A corpus of hostile requests against a real server process (issue 22): every case answers its 4xx
with a JSON reason, nothing is stored, and the server's peak memory stays bounded.

The red team's findings are here one row each, plus neighbours. The server runs as ``attitude serve``
(uvicorn, the production protocol with its deadlines); its peak resident memory (``VmHWM`` in
/proc/<pid>/status) must stay within ``PEAK_GROWTH_BOUND_MB`` of what it held after start-up.
"""

from __future__ import annotations

import base64
import gzip
import io
import json
import os
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from app.devserver import free_port, stop

pytestmark = pytest.mark.sqlite_only

TOKEN = "corpus-admin-token-0123456789"
PEAK_GROWTH_BOUND_MB = 160
"""Bound on the growth of the server's peak RSS over the corpus: what a refused request may hold is the body
limit (ATTITUDE_MAX_UPLOAD_BYTES, 64 MiB here: a gzip bomb is inflated up to it, in 1 MiB steps) plus the
decoded batches up to the row limit (an Arrow stream, ~32 MB here) and slack; measured +107 MB."""
GYRO = "time,wx,wy,wz\n" + "".join(f"2023-06-01T00:00:{i:02d}Z,1,2,3\n" for i in range(10))
CSV, JSON_TYPE = "text/csv", "application/json"
PARQUET, ARROW = "application/vnd.apache.parquet", "application/vnd.apache.arrow.stream"


def request(base: str, method: str, path: str, body: bytes | None = None, headers: dict[str, str] | None = None,
            token: str | None = TOKEN, timeout: float = 60) -> tuple[int, bytes, Any]:
    h = {"Authorization": f"Bearer {token}"} if token is not None else {}
    h.update(headers or {})
    req = urllib.request.Request(base + path, data=body, method=method, headers=h)
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, r.read(), r.headers
    except urllib.error.HTTPError as e:
        return e.code, e.read(), e.headers


def vm_kb(pid: int, field: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise AssertionError(f"no {field} for {pid}")


@pytest.fixture(scope="module")
def server(tmp_path_factory) -> Iterator[dict[str, Any]]:
    data = tmp_path_factory.mktemp("corpus")
    env = {"ATTITUDE_DATA_DIR": str(data), "ATTITUDE_DATABASE_URL": "", "ATTITUDE_BOOTSTRAP_TOKEN": TOKEN,
           "ATTITUDE_MAX_JOBS": "1", "ATTITUDE_SCHEDULER": "0", "ATTITUDE_MAX_READ_ROWS": "5",
           "ATTITUDE_HEADER_TIMEOUT_S": "2", "ATTITUDE_BODY_TIMEOUT_S": "2", "ATTITUDE_AUTH_FAILURES_PER_MINUTE": "20",
           "ATTITUDE_MAX_UPLOAD_BYTES": str(64 << 20), "ATTITUDE_MAX_UPLOAD_ROWS": "1000000"}
    port = free_port()
    log = open(data / "server.log", "ab")  # noqa: SIM115
    proc = subprocess.Popen([sys.executable, "-m", "app.cli", "serve", "--port", str(port), "--log-level",
                             "warning"], env={**os.environ, **env}, stdout=log, stderr=log)
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            assert proc.poll() is None, (data / "server.log").read_text()[-2000:]
            try:
                if request(base, "GET", "/healthz", timeout=2)[0] == 200:
                    break
            except OSError:
                pass
            assert time.monotonic() < deadline, "server did not start"
            time.sleep(0.05)
        assert request(base, "POST", "/api/v1/spacecraft", json.dumps({"name": "sat1"}).encode(),
                       {"Content-Type": JSON_TYPE})[0] == 201
        assert request(base, "POST", "/api/v1/spacecraft/sat1/telemetry/gyro", GYRO.encode(),
                       {"Content-Type": CSV})[0] == 201  # the baseline: 10 stored rows (more than a read may return)
        status, body, _ = request(base, "POST", "/api/v1/keys", json.dumps(
            {"name": "opA", "role": "operator", "spacecraft": ["sat1"]}).encode(), {"Content-Type": JSON_TYPE})
        assert status == 201
        assert request(base, "GET", "/api/v1/jobs/types")[0] == 200  # imports the job types (matplotlib, ...)
        yield {"base": base, "pid": proc.pid, "data": data, "operator": json.loads(body)["secret"],
               "rss_after_start_kb": vm_kb(proc.pid, "VmHWM")}
    finally:
        stop(proc)
        log.close()


def _parquet_of_constant_rows(n_rows: int, group: int = 2_000_000) -> bytes:
    """A small Parquet file of many constant rows (dictionary/RLE encoded: a few MB for 4e7 rows)."""
    chunk = pa.table({"time": pa.array(np.full(group, 1.7e9)), "wx": np.zeros(group), "wy": np.zeros(group),
                      "wz": np.zeros(group)})
    buf = io.BytesIO()
    with pq.ParquetWriter(buf, chunk.schema) as writer:
        for _ in range(n_rows // group):
            writer.write_table(chunk, row_group_size=group)
    return buf.getvalue()


def _arrow_stream(n_batches: int, rows: int) -> bytes:
    """Compressed record batches of constant rows: small on the wire, large decoded."""
    batch = pa.record_batch({"time": np.full(rows, 1.7e9), "wx": np.zeros(rows), "wy": np.zeros(rows),
                             "wz": np.zeros(rows)})
    sink = io.BytesIO()
    with pa.ipc.new_stream(sink, batch.schema, options=pa.ipc.IpcWriteOptions(compression="zstd")) as writer:
        for _ in range(n_batches):
            writer.write_batch(batch)
    return sink.getvalue()


def _deep(levels: int) -> dict:
    value: dict = {"a": 1}
    for _ in range(levels):
        value = {"x": value}
    return value


def _cursor(text: str) -> str:
    return base64.urlsafe_b64encode(text.encode()).decode()


def _job(**fields: Any) -> bytes:
    return json.dumps({"type": "telemetry_coverage", "spacecraft": "sat1", **fields}).encode()


UP = "/api/v1/spacecraft/sat1/telemetry/gyro"
NAIVE = _cursor("2999-01-01T00:00:00|zz")
TWO_MEMBERS_AND_GARBAGE = gzip.compress(GYRO.encode()[:100]) + gzip.compress(GYRO.encode()[100:]) + b"garbage"
# (what, method, path, body, headers, token ("ok", "operator" or a literal), expected status)
CORPUS: list[tuple[str, str, str, Any, dict[str, str], str, int]] = [
    *[(f"naive cursor {p}", "GET", f"{p}?cursor={NAIVE}", None, {}, "ok", 422)
      for p in ("/api/v1/jobs", "/api/v1/keys", "/api/v1/reference", "/api/v1/spacecraft/sat1/ingests")],
    ("garbage cursor", "GET", "/api/v1/jobs?cursor=" + "A" * 3000, None, {}, "ok", 422),
    ("params nested 900 deep", "POST", "/api/v1/jobs", _job(params=_deep(900)), {"Content-Type": JSON_TYPE}, "ok",
     422),
    ("params nested 7 deep", "POST", "/api/v1/jobs", _job(params={"gap_factor": _deep(7)}),
     {"Content-Type": JSON_TYPE}, "ok", 422),
    ("300-year TAI window", "POST", "/api/v1/jobs", _job(start="1900-01-01T00:00:00", end="2200-01-01T00:00:00",
                                                         time_scale="tai"), {"Content-Type": JSON_TYPE}, "ok", 422),
    ("subintervals [64]*5000", "POST", "/api/v1/jobs",
     json.dumps({"type": "gyro_bias_fit", "spacecraft": "sat1", "params": {"subintervals": [64] * 5000}}).encode(),
     {"Content-Type": JSON_TYPE}, "ok", 422),
    ("bad stage_params", "POST", "/api/v1/jobs",
     json.dumps({"type": "reconstruction", "spacecraft": "sat1",
                 "params": {"stage_params": {"gyro_bias_fit": {"max_iterations": "many"}}}}).encode(),
     {"Content-Type": JSON_TYPE}, "ok", 422),
    ("cron every second", "POST", "/api/v1/schedules",
     json.dumps({"name": "x", "cron": "* * * * * *", "type": "telemetry_coverage", "spacecraft": "sat1"}).encode(),
     {"Content-Type": JSON_TYPE}, "ok", 422),
    ("near-valid token, bad content type", "POST", UP, b"x", {"Content-Type": "text/plain"}, TOKEN[:-1], 401),
    ("doubled space in the scheme", "POST", UP, b"x", {"Content-Type": "text/plain"}, " " + TOKEN, 401),
    ("shared reference data by an operator", "POST", "/api/v1/reference/reference_orbit", b"x", {}, "operator", 403),
    ("6000 distinct JSON keys", "POST", UP,
     json.dumps([{"time": "2023-06-01T00:00:00Z", f"k{i}": 1} for i in range(6000)]).encode(),
     {"Content-Type": JSON_TYPE}, "ok", 422),
    ("4e7 constant Parquet rows", "POST", UP, "parquet", {"Content-Type": PARQUET}, "ok", 413),
    ("Arrow stream beyond the row limit", "POST", UP, "arrow", {"Content-Type": ARROW}, "ok", 413),
    ("20,000 rows on 20,000 days", "POST", UP,  # under the row limit, over the 1000 days
     ("time,wx,wy,wz\n" + "".join(f"{1.5e9 + 86400.0 * i:.0f},1,2,3\n" for i in range(20_000))).encode(),
     {"Content-Type": CSV}, "ok", 413),
    ("whole stream beyond the read cap", "GET", UP, None, {}, "ok", 413),
    ("spacecraft .", "POST", "/api/v1/spacecraft", b'{"name": "."}', {"Content-Type": JSON_TYPE}, "ok", 422),
    ("spacecraft ..", "POST", "/api/v1/spacecraft", b'{"name": ".."}', {"Content-Type": JSON_TYPE}, "ok", 422),
    ("spacecraft with a newline", "POST", "/api/v1/spacecraft", b'{"name": "a\\n"}', {"Content-Type": JSON_TYPE},
     "ok", 422),
    ("sensor with a newline", "POST", UP + "?sensor=g%0A", GYRO.encode(), {"Content-Type": CSV}, "ok", 422),
    ("gzip members with trailing garbage", "POST", UP, TWO_MEMBERS_AND_GARBAGE,
     {"Content-Type": CSV, "Content-Encoding": "gzip"}, "ok", 422),
    ("gzip bomb", "POST", UP, gzip.compress(b"0" * (200 << 20)), {"Content-Type": CSV, "Content-Encoding": "gzip"},
     "ok", 413),
    ("brotli", "POST", UP, GYRO.encode(), {"Content-Type": CSV, "Content-Encoding": "br"}, "ok", 415),
    ("JSON body nested 100000 deep", "POST", "/api/v1/jobs", b"[" * 100_000 + b"]" * 100_000,
     {"Content-Type": JSON_TYPE}, "ok", 422),
    ("JSON upload nested 100000 deep", "POST", UP, b"[" * 100_000 + b"]" * 100_000, {"Content-Type": JSON_TYPE},
     "ok", 422),
    ("2 MB JSON job body", "POST", "/api/v1/jobs", _job(reference={"k": "x" * (2 << 20)}),
     {"Content-Type": JSON_TYPE}, "ok", 413),
    ("10 kB query string", "GET", "/api/v1/jobs?type=" + "x" * 10_000, None, {}, "ok", 414),
    ("100,000 CSV columns", "POST", UP, (",".join(f"c{i}" for i in range(100_000)) + "\n").encode(),
     {"Content-Type": CSV}, "ok", 422),
    ("unknown query parameter", "GET", "/api/v1/jobs?strat=2023", None, {}, "ok", 422),
    ("traversal in the stream", "GET", "/api/v1/spacecraft/sat1/telemetry/..%2F..%2Fetc", None, {}, "ok", 404),
]


def test_hostile_corpus(server):
    base, pid = server["base"], server["pid"]
    # the server allows 1e6 rows per upload (ATTITUDE_MAX_UPLOAD_ROWS): 40x that in a Parquet file of a few MB
    bodies = {"parquet": _parquet_of_constant_rows(40_000_000), "arrow": _arrow_stream(200, 100_000)}
    assert len(bodies["parquet"]) < 8 << 20 and len(bodies["arrow"]) < 8 << 20  # ~1.3 GB and 640 MB decoded
    request(base, "GET", "/api/v1/jobs")  # warm
    failures = []
    for what, method, path, body, headers, who, expected in CORPUS:
        token = {"ok": TOKEN, "operator": server["operator"]}.get(who, who)
        payload = bodies.get(body, body) if isinstance(body, str) else body
        t0 = time.perf_counter()
        status, raw, _ = request(base, method, path, payload, headers, token=token)
        took = time.perf_counter() - t0
        try:
            reason = json.loads(raw)["detail"]
        except (ValueError, KeyError, TypeError):
            reason = None
        print(f"  {what}: {status} in {took * 1000:.0f} ms")
        if status != expected or not reason:
            failures.append(f"{what}: {status} (expected {expected}) {raw[:200]!r}")
        elif took > 10:
            failures.append(f"{what}: {took:.1f} s")
    assert not failures, "\n".join(failures)

    # nothing stored: the baseline (one spacecraft, its one upload, one file) is all there is
    def listing(path):
        status, raw, _ = request(base, "GET", path)
        assert status == 200, (path, raw[:200])
        return json.loads(raw)

    assert [s["name"] for s in listing("/api/v1/spacecraft")] == ["sat1"]
    assert len(listing("/api/v1/spacecraft/sat1/ingests")) == 1
    assert listing("/api/v1/jobs") == [] and listing("/api/v1/reference") == [] and listing("/api/v1/schedules") == []
    assert len(list((server["data"] / "telemetry").rglob("*.parquet"))) == 1

    peak_kb, start_kb = vm_kb(pid, "VmHWM"), server["rss_after_start_kb"]
    growth_mb = (peak_kb - start_kb) / 1024
    print(f"server peak RSS after start-up {start_kb / 1024:.0f} MB, over the corpus {peak_kb / 1024:.0f} MB "
          f"(+{growth_mb:.0f} MB; bound +{PEAK_GROWTH_BOUND_MB} MB)")
    assert growth_mb < PEAK_GROWTH_BOUND_MB


def test_slow_headers_are_cut_off(server):
    host, port = server["base"].removeprefix("http://").split(":")
    slow = [socket.create_connection((host, int(port))) for _ in range(50)]
    try:
        for s in slow:
            s.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n")  # never finishes its headers
        assert request(server["base"], "GET", "/healthz", token=None, timeout=5)[0] == 200  # others still served
        slow[0].settimeout(10)
        t0 = time.monotonic()
        answer = slow[0].recv(1000)
        assert answer.startswith(b"HTTP/1.1 408") and b"application/json" in answer
        assert time.monotonic() - t0 < 5  # ATTITUDE_HEADER_TIMEOUT_S=2 from the connection's first byte
        assert slow[0].recv(1000) == b""  # and closed
    finally:
        for s in slow:
            s.close()


def test_a_stalled_body_is_cut_off(server):
    host, port = server["base"].removeprefix("http://").split(":")
    with socket.create_connection((host, int(port))) as s:
        s.sendall(f"POST {UP} HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\nContent-Type: text/csv\r\n"
                  "Content-Length: 100000\r\n\r\ntime,wx".encode())  # then nothing more
        s.settimeout(15)
        t0 = time.monotonic()
        while s.recv(65536):  # whatever the service answers, the connection ends
            pass
        assert time.monotonic() - t0 < 10  # ATTITUDE_BODY_TIMEOUT_S=2
    status, raw, _ = request(server["base"], "GET", "/api/v1/spacecraft/sat1/ingests")
    assert status == 200 and len(json.loads(raw)) == 1  # nothing stored


def test_failed_authentications_are_throttled_last(server):
    """Last in this module: it locks the test's address out for a while."""
    statuses = [request(server["base"], "GET", "/api/v1/spacecraft", token=f"att_guess{i}")[0] for i in range(25)]
    assert 401 in statuses and statuses[-1] == 429
    status, raw, headers = request(server["base"], "GET", "/api/v1/spacecraft")
    assert status == 429 and int(headers["Retry-After"]) >= 1 and json.loads(raw)["detail"]
