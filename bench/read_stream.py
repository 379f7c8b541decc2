"""Streamed telemetry reads (issue 24): the service's memory while it answers a GET of a whole large stream, in
every format, beside the size of the same rows read into memory by plain pyarrow in the same run.

N gyro rows (10 Hz) are uploaded as Parquet in uploads of one million rows; then the whole stream is read
once per format with no window. For each read: wall time, bytes sent, and the growth of the server process's
peak RSS during the read (VmHWM reset through /proc/<pid>/clear_refs before it, so each read is measured on
its own). The reference is ``pyarrow.parquet.read_table`` of the stored files (the memory any whole read
would need at least: the Arrow table's size) and its time.

Run: ``.venv/bin/python bench/read_stream.py [--rows N]`` (default 10,000,000; a minute or two here).
Target: the peak growth is bounded by a few chunks (``ATTITUDE_STREAM_READ_ROWS``, 1e6 rows by default),
independent of N: well under the table's in-memory size.
"""

from __future__ import annotations

import argparse
import http.client
import io
import json
import tempfile
import time
import urllib.parse
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from app.devserver import running_server, serving_pid

TOKEN = "bench-read-admin-token"
UPLOAD_ROWS = 1_000_000


def _status_kib(pid: int, field: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise KeyError(field)


def _request(base: str, method: str, path: str, body: bytes | None = None,
             content_type: str = "application/json") -> tuple[int, int, bytes]:
    """(status, bytes received, the first 64 kB) - the body is read in pieces and dropped."""
    url = urllib.parse.urlsplit(base)
    conn = http.client.HTTPConnection(url.hostname, url.port, timeout=1200)
    conn.request(method, path, body=body, headers={"Content-Type": content_type, "Authorization": f"Bearer {TOKEN}"})
    resp = conn.getresponse()
    head, total = b"", 0
    while piece := resp.read(1 << 20):
        total += len(piece)
        if len(head) < 65536:
            head += piece[:65536]
    conn.close()
    return resp.status, total, head


def _gyro(n: int, t0_ns: int, seed: int) -> bytes:
    rng = np.random.default_rng(seed)
    t = t0_ns + np.arange(n, dtype=np.int64) * 100_000_000
    table = pa.table({"time": pa.array(t, pa.timestamp("ns", tz="UTC")), "wx": rng.normal(0, 1e-3, n),
                      "wy": rng.normal(0, 1e-3, n), "wz": rng.normal(0, 1e-3, n)})
    buf = io.BytesIO()
    pq.write_table(table, buf)
    return buf.getvalue()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", type=int, default=10_000_000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "data"
        env = {"ATTITUDE_DATA_DIR": str(data), "ATTITUDE_BOOTSTRAP_TOKEN": TOKEN, "ATTITUDE_DATABASE_URL": ""}
        with running_server(env) as base:
            pid = serving_pid(base)
            assert _request(base, "POST", "/api/v1/spacecraft", json.dumps({"name": "bench"}).encode())[0] == 201
            t0_ns, done, k = 1_700_000_000 * 10**9, 0, 0
            while done < args.rows:
                n = min(UPLOAD_ROWS, args.rows - done)
                status, _, head = _request(base, "POST", "/api/v1/spacecraft/bench/telemetry/gyro",
                                           _gyro(n, t0_ns + done * 100_000_000, k), "application/vnd.apache.parquet")
                assert status == 201, head[:500]
                done, k = done + n, k + 1
            files = sorted((data / "telemetry").rglob("*.parquet")) if (data / "telemetry").exists() \
                else sorted(data.rglob("sc=*/stream=gyro/**/*.parquet"))
            t = time.perf_counter()
            table = pq.read_table(files)
            plain_s = time.perf_counter() - t
            plain_mb = table.nbytes / 2**20
            assert table.num_rows == args.rows, (table.num_rows, len(files))
            del table
            print(f"rows {args.rows:,} in {len(files)} files; plain pyarrow read_table: {plain_s:.2f} s, "
                  f"the table in memory {plain_mb:.0f} MiB")
            print(f"{'format':8} {'seconds':>8} {'MB sent':>9} {'peak RSS growth MiB':>20} {'of the table':>13}")
            for fmt in ("parquet", "arrow", "csv", "json"):
                Path(f"/proc/{pid}/clear_refs").write_text("5")  # reset VmHWM to the current RSS
                before = _status_kib(pid, "VmRSS")
                t = time.perf_counter()
                status, sent, head = _request(base, "GET", f"/api/v1/spacecraft/bench/telemetry/gyro?format={fmt}")
                wall = time.perf_counter() - t
                assert status == 200, head[:500]
                growth = (_status_kib(pid, "VmHWM") - before) / 1024
                print(f"{fmt:8} {wall:8.2f} {sent / 1e6:9.1f} {growth:20.0f} {growth / plain_mb:13.2f}")


if __name__ == "__main__":
    main()
