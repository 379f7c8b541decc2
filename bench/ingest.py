"""Ingest benchmark (issue 2): 1,000,000 gyro rows as Parquet through the running HTTP server,
against a plain ``pyarrow.parquet.write_table`` of the same table in the same run.

Run: ``make bench`` (or ``.venv/bin/python bench/ingest.py [--rows N] [--repeat K]``).
Targets: >= 500,000 rows/s end to end and >= 0.3 of the plain pyarrow write.
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

from app.devserver import running_server

TOKEN = "bench-admin-token"


def gyro_table(n: int, t0_s: float, seed: int = 0) -> pa.Table:
    rng = np.random.default_rng(seed)
    t_ns = (np.int64(int(t0_s * 1e9)) + np.arange(n, dtype=np.int64) * 100_000_000)
    return pa.table({
        "time": pa.array(t_ns, pa.timestamp("ns", tz="UTC")),
        "wx": rng.normal(0, 1e-3, n), "wy": rng.normal(0, 1e-3, n), "wz": rng.normal(0, 1e-3, n),
    })


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
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        env = {"ATTITUDE_DATA_DIR": str(Path(tmp) / "data"), "ATTITUDE_BOOTSTRAP_TOKEN": TOKEN,
               "ATTITUDE_DATABASE_URL": ""}
        with running_server(env) as base:
            status, body = post(base, "/api/v1/spacecraft", json.dumps({"name": "bench"}).encode(),
                                "application/json")
            assert status == 201, body
            service, plain = [], []
            for k in range(args.repeat):
                # a fresh time range each round so every row is new (no duplicate short-cut)
                table = gyro_table(args.rows, 1.7e9 + k * args.rows * 0.1 + k * 86_400, seed=k)
                buf = io.BytesIO()
                pq.write_table(table, buf)
                payload = buf.getvalue()

                t = time.perf_counter()
                pq.write_table(table, Path(tmp) / f"plain{k}.parquet")
                plain.append(time.perf_counter() - t)

                t = time.perf_counter()
                status, body = post(base, "/api/v1/spacecraft/bench/telemetry/gyro", payload,
                                    "application/vnd.apache.parquet")
                service.append(time.perf_counter() - t)
                assert status == 201 and body["inserted"] == args.rows, body
            best_s, best_p = min(service), min(plain)
            print(f"rows per upload: {args.rows:,}  payload: {len(payload) / 1e6:.1f} MB  rounds: {args.repeat}")
            print(f"service end-to-end (HTTP upload, validate, de-duplicate, write, commit): "
                  f"best {best_s:.3f} s = {args.rows / best_s:,.0f} rows/s (median {np.median(service):.3f} s)")
            print(f"plain pyarrow.parquet.write_table of the same table:                     "
                  f"best {best_p:.3f} s = {args.rows / best_p:,.0f} rows/s (median {np.median(plain):.3f} s)")
            print(f"ratio service/plain (throughput): {best_p / best_s:.2f}  (target >= 0.30)")
            print(f"target 500,000 rows/s end to end: {'met' if args.rows / best_s >= 5e5 else 'NOT met'}")


if __name__ == "__main__":
    main()
