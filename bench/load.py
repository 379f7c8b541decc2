"""Load benchmark (issue 12): concurrent uploads and reads against the real server for a bounded time.

Runs the service on PostgreSQL when ATTITUDE_BENCH_DATABASE_URL is set (a schema of its own, dropped
afterwards), else on the embedded SQLite; N client threads loop over: upload a 1,000-row gyro batch
(new times), read a window back, list ingests. Prints throughput, error count and p50/p99 latency
per request kind. Bounded: --seconds (default 20), loopback only.

Run: ``.venv/bin/python bench/load.py [--threads 8] [--seconds 20]``
"""

from __future__ import annotations

import argparse
import os
import tempfile
import threading
import time
import uuid
from collections import defaultdict
from pathlib import Path

import numpy as np
from sqlalchemy import create_engine, text
from sqlalchemy.engine import make_url

from app.client import ApiClient, ApiError
from app.devserver import running_server

TOKEN = "load-bench-token"


def batch_csv(batch: int, rows: int = 1000) -> bytes:
    t0 = 1_685_577_600 + batch * rows
    t = t0 + np.arange(rows)
    body = "\n".join(f"{x},{batch},{i},0.5" for i, x in enumerate(t))
    return ("time,wx,wy,wz\n" + body + "\n").encode()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=8)
    ap.add_argument("--seconds", type=float, default=20.0)
    args = ap.parse_args()
    pg = os.environ.get("ATTITUDE_BENCH_DATABASE_URL")
    schema = f"bench_{uuid.uuid4().hex[:8]}"
    with tempfile.TemporaryDirectory() as tmp:
        db_url = ""
        if pg:
            admin = create_engine(pg)
            with admin.begin() as c:
                c.execute(text(f'CREATE SCHEMA "{schema}"'))
            db_url = make_url(pg).update_query_dict({"options": f"-csearch_path={schema}"}).render_as_string(
                hide_password=False)
        env = {"ATTITUDE_DATA_DIR": str(Path(tmp) / "data"), "ATTITUDE_BOOTSTRAP_TOKEN": TOKEN,
               "ATTITUDE_DATABASE_URL": db_url, "ATTITUDE_RATE_LIMIT_PER_MINUTE": "100000000"}
        try:
            with running_server(env, log_path=Path(tmp) / "server.log") as base:
                api = ApiClient(base, TOKEN, timeout_s=60)
                api.post("/api/v1/spacecraft", {"name": "load"})
                latencies: dict[str, list[float]] = defaultdict(list)
                errors: dict[str, int] = defaultdict(int)
                counter = [0]
                lock = threading.Lock()
                deadline = time.monotonic() + args.seconds

                def worker() -> None:
                    client = ApiClient(base, TOKEN, timeout_s=60)
                    while time.monotonic() < deadline:
                        with lock:
                            batch = counter[0]
                            counter[0] += 1
                        t0 = 1_685_577_600 + batch * 1000
                        for kind, call in (
                            ("upload", lambda b=batch: client.post("/api/v1/spacecraft/load/telemetry/gyro",
                                                                   body=batch_csv(b), content_type="text/csv")),
                            ("read", lambda t=t0: client.request("GET", "/api/v1/spacecraft/load/telemetry/gyro",
                                                                 params={"start": t, "end": t + 999,
                                                                         "format": "parquet"})),
                            ("list", lambda: client.get("/api/v1/spacecraft/load/ingests", params={"limit": 20})),
                        ):
                            start = time.perf_counter()
                            try:
                                call()
                            except (ApiError, OSError):
                                with lock:
                                    errors[kind] += 1
                                continue
                            with lock:
                                latencies[kind].append(time.perf_counter() - start)

                threads = [threading.Thread(target=worker) for _ in range(args.threads)]
                t_start = time.monotonic()
                for t in threads:
                    t.start()
                for t in threads:
                    t.join()
                elapsed = time.monotonic() - t_start
        finally:
            if pg:
                with admin.begin() as c:
                    c.execute(text(f'DROP SCHEMA IF EXISTS "{schema}" CASCADE'))
                admin.dispose()
    print(f"catalog: {'PostgreSQL' if pg else 'SQLite'}; {args.threads} client threads for {elapsed:.1f} s")
    total = sum(len(v) for v in latencies.values())
    print(f"{'kind':<8} {'requests':>8} {'req/s':>8} {'p50 ms':>8} {'p99 ms':>8} {'errors':>7}")
    for kind in ("upload", "read", "list"):
        lat = np.array(latencies[kind]) * 1e3
        if lat.size:
            print(f"{kind:<8} {lat.size:>8} {lat.size / elapsed:>8.1f} {np.percentile(lat, 50):>8.1f} "
                  f"{np.percentile(lat, 99):>8.1f} {errors[kind]:>7}")
    print(f"total    {total:>8} {total / elapsed:>8.1f} requests/s; rows uploaded "
          f"{len(latencies['upload']) * 1000:,} ({len(latencies['upload']) * 1000 / elapsed:,.0f} rows/s); "
          f"errors {sum(errors.values())}")


if __name__ == "__main__":
    main()
