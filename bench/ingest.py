"""Ingest benchmark (issues 2, 24): gyro rows as Parquet through the running HTTP server, against a plain
``pyarrow.parquet.write_table`` of the same table in the same run, and the server's peak memory.

Run: ``make bench`` (or ``.venv/bin/python bench/ingest.py [--rows N] [--repeat K] [--format csv] [--py-spy OUT]``).
``--format csv`` uploads the same table as CSV: the baseline stays the plain Parquet write of the table, and the
CSV is also read and written by pandas (``read_csv`` + ``to_parquet``, the issue's CSV baseline) in the same run.
Targets: >= 500,000 rows/s end to end and >= 0.3 of the plain pyarrow write (issue 24: 1e7 rows within
3x of the plain write, i.e. ratio >= 0.33); the server's peak RSS (VmHWM of the server process, read
from /proc after the uploads; Linux) under 2x the body size. ``--py-spy OUT`` records a py-spy profile
of the server (speedscope JSON) over the uploads when py-spy is installed.
"""

from __future__ import annotations

import argparse
import http.client
import io
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.parse
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from app.devserver import running_server

TOKEN = "bench-admin-token"
MEDIA = {"parquet": "application/vnd.apache.parquet", "csv": "text/csv"}


def gyro_table(n: int, t0_s: float, seed: int = 0) -> pa.Table:
    rng = np.random.default_rng(seed)
    t_ns = (np.int64(int(t0_s * 1e9)) + np.arange(n, dtype=np.int64) * 100_000_000)
    return pa.table({
        "time": pa.array(t_ns, pa.timestamp("ns", tz="UTC")),
        "wx": rng.normal(0, 1e-3, n), "wy": rng.normal(0, 1e-3, n), "wz": rng.normal(0, 1e-3, n),
    })


def server_pid() -> int:
    """The pid of the server: the one child of this process (app.devserver.running_server starts it)."""
    me = os.getpid()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == me:
                return int(entry.name)
    raise RuntimeError("server process not found")


def memory_mb(pid: int, field: str) -> float:
    """VmRSS / VmHWM (peak resident set) of a process in MB, from /proc/<pid>/status."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"{field} not in /proc/{pid}/status")


def post(base: str, path: str, body: bytes, content_type: str) -> tuple[int, dict]:
    url = urllib.parse.urlsplit(base)
    conn = http.client.HTTPConnection(url.hostname, url.port, timeout=600)
    conn.request("POST", path, body=body, headers={"Content-Type": content_type,
                                                   "Authorization": f"Bearer {TOKEN}"})
    resp = conn.getresponse()
    data = json.loads(resp.read())
    conn.close()
    return resp.status, data


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--format", choices=sorted(MEDIA), default="parquet", help="upload body format")
    ap.add_argument("--py-spy", dest="py_spy", metavar="OUT", help="record a py-spy profile of the server")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        env = {"ATTITUDE_DATA_DIR": str(Path(tmp) / "data"), "ATTITUDE_BOOTSTRAP_TOKEN": TOKEN,
               "ATTITUDE_DATABASE_URL": ""}
        with running_server(env) as base:
            status, body = post(base, "/api/v1/spacecraft", json.dumps({"name": "bench"}).encode(),
                                "application/json")
            assert status == 201, body
            pid = server_pid()
            rss_before = memory_mb(pid, "VmRSS")
            spy = None
            spy_exe = shutil.which("py-spy", path=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
            if args.py_spy and spy_exe:
                spy = subprocess.Popen([spy_exe, "record", "--pid", str(pid), "--format", "speedscope",
                                        "--output", args.py_spy, "--rate", "50", "--nonblocking"])
                time.sleep(1.0)
            service, plain, pandas_s = [], [], []
            for k in range(args.repeat):
                # a fresh time range each round so every row is new (no duplicate short-cut)
                table = gyro_table(args.rows, 1.7e9 + k * args.rows * 0.1 + k * 86_400, seed=k)
                buf = io.BytesIO()
                if args.format == "csv":  # times as seconds since 1970 (UTC), the values in full precision
                    seconds = table.column("time").cast(pa.int64()).to_numpy() / 1e9
                    pacsv.write_csv(table.set_column(0, "time", pa.array(seconds)), buf)
                else:
                    pq.write_table(table, buf)
                payload = buf.getvalue()

                t = time.perf_counter()
                pq.write_table(table, Path(tmp) / f"plain{k}.parquet")
                plain.append(time.perf_counter() - t)

                if args.format == "csv":
                    t = time.perf_counter()
                    pd.read_csv(io.BytesIO(payload)).to_parquet(Path(tmp) / f"pandas{k}.parquet")
                    pandas_s.append(time.perf_counter() - t)

                t = time.perf_counter()
                status, body = post(base, "/api/v1/spacecraft/bench/telemetry/gyro", payload, MEDIA[args.format])
                service.append(time.perf_counter() - t)
                assert status == 201 and body["inserted"] == args.rows, body
            peak = memory_mb(pid, "VmHWM")
            if spy is not None:
                spy.send_signal(2)  # SIGINT: py-spy writes its profile and exits
                spy.wait(timeout=120)
            best_s, best_p = min(service), min(plain)
            print(f"rows per upload: {args.rows:,}  payload ({args.format}): {len(payload) / 1e6:.1f} MB  "
                  f"rounds: {args.repeat}")
            print(f"service end-to-end (HTTP upload, validate, de-duplicate, write, commit): "
                  f"best {best_s:.3f} s = {args.rows / best_s:,.0f} rows/s (median {np.median(service):.3f} s)")
            print(f"plain pyarrow.parquet.write_table of the same table:                     "
                  f"best {best_p:.3f} s = {args.rows / best_p:,.0f} rows/s (median {np.median(plain):.3f} s)")
            print(f"ratio service/plain (throughput): {best_p / best_s:.2f}  (target >= 0.30)")
            if pandas_s:
                best_pd = min(pandas_s)
                print(f"pandas read_csv + to_parquet of the same CSV:                             "
                      f"best {best_pd:.3f} s = {args.rows / best_pd:,.0f} rows/s (median {np.median(pandas_s):.3f} s)")
                print(f"ratio service/pandas (time): {best_s / best_pd:.2f}  (the issue measured 3-4 before streaming)")
            print(f"target 500,000 rows/s end to end: {'met' if args.rows / best_s >= 5e5 else 'NOT met'}")
            body_mb = len(payload) / 1e6
            print(f"server RSS before the uploads {rss_before:.0f} MB, peak (VmHWM) {peak:.0f} MB: "
                  f"peak/body {peak * 1.048576 / body_mb:.2f}, (peak - before)/body "
                  f"{(peak - rss_before) * 1.048576 / body_mb:.2f}  (target peak < 2x body)")


if __name__ == "__main__":
    main()
