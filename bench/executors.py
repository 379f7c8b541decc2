"""Executor benchmark (issue 10): 200 small jobs and one 24-hour gyro-fit job, on the local executor and
on a Dask LocalCluster, in the same run, through the real HTTP service.

Each executor gets its own service process, catalog and Parquet store with the same telemetry (the
paper-003 scenario simulated over ``--hours``): the local one runs jobs in child processes
(``ATTITUDE_MAX_JOBS`` = ``--workers``), the Dask one submits them to a ``LocalCluster`` started here
with ``--workers`` single-threaded worker processes. Same cores for both.

- small jobs: ``--small`` telemetry_coverage jobs over a 10-minute window, all submitted at once;
  throughput = jobs / (last finished - first submitted);
- long job: ``gyro_bias_fit`` over the whole window (or, when that job type is not registered in this
  installation, ``telemetry_coverage`` over the same 24 h, and the output says so); wall time from
  submission to the final state, and its summary compared between the two executors.

Run: ``.venv/bin/python bench/executors.py [--small 200] [--hours 24] [--workers 2]``.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path
from typing import Any

from app.client import ApiClient
from app.devserver import running_server
from processing.simulate.seed003 import simulate_seed003
from processing.time import timescales

TOKEN = "bench-executors-admin-token"
SMALL_WINDOW_S = 600.0


def _wait_all(client: ApiClient, job_type: str, n: int, timeout_s: float) -> tuple[float, dict[str, int]]:
    deadline = time.monotonic() + timeout_s
    while True:
        counts = {s: len(client.get("/api/v1/jobs", params={"type": job_type, "status": s, "limit": 500}))
                  for s in ("succeeded", "failed", "cancelled")}
        if sum(counts.values()) >= n:
            return time.perf_counter(), counts
        if time.monotonic() > deadline:
            raise TimeoutError(f"{job_type}: {counts} of {n} finished after {timeout_s} s")
        time.sleep(0.1)


def _close(a: Any, b: Any, rel: float = 1e-9) -> bool:
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k], rel) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_close(x, y, rel) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=rel, abs_tol=1e-15)
    return bool(a == b)


def run_mode(mode: str, env: dict[str, str], scenario: Any, start_tai_ns: int, n_small: int,
             timeout_s: float) -> dict[str, Any]:
    with running_server(env) as base:
        client = ApiClient(base, TOKEN)
        client.post("/api/v1/spacecraft", {"name": "bench", "config": scenario.config})
        for stream, columns in scenario.streams.items():
            client.upload_columns("bench", stream, columns)
        types = {t["type"] for t in client.get("/api/v1/jobs/types")}
        long_type = "gyro_bias_fit" if "gyro_bias_fit" in types else "telemetry_coverage"
        window = {"start": start_tai_ns / 1e9, "end": start_tai_ns / 1e9 + SMALL_WINDOW_S, "time_scale": "tai"}

        # warm-up (worker start, imports): one job, not counted
        client.wait_for_job(client.submit_job("executor_check", "bench")["id"], timeout_s=timeout_s)

        t0 = time.perf_counter()
        for _ in range(n_small):
            client.submit_job("telemetry_coverage", "bench", **window)
        t_done, counts = _wait_all(client, "telemetry_coverage", n_small, timeout_s)
        small_s = t_done - t0

        t0 = time.perf_counter()
        job = client.wait_for_job(client.submit_job(long_type, "bench")["id"], timeout_s=timeout_s, poll_s=0.1)
        long_s = time.perf_counter() - t0
    return {"mode": mode, "small_s": small_s, "small_counts": counts, "throughput": n_small / small_s,
            "long_type": long_type, "long_s": long_s, "long_status": job["status"], "long_error": job["error"],
            "long_result": job["result"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--small", type=int, default=200, help="number of small jobs")
    ap.add_argument("--hours", type=float, default=24.0, help="length of the simulated telemetry (long job)")
    ap.add_argument("--workers", type=int, default=2, help="job processes (local) = Dask worker processes")
    ap.add_argument("--timeout", type=float, default=1800.0)
    args = ap.parse_args()

    import dask
    from distributed import LocalCluster

    start = int(timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])
    t = time.perf_counter()
    scenario = simulate_seed003(start_tai_ns=start, duration_s=args.hours * 3600.0, seed=5)
    rows = {k: len(v["time_tai_ns"]) for k, v in scenario.streams.items()}
    print(f"telemetry: {args.hours:g} h of the 003 scenario {rows} (simulated in {time.perf_counter() - t:.1f} s)")
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for mode in ("local", "dask"):
            data = Path(tmp) / mode
            env = {"ATTITUDE_DATA_DIR": str(data), "ATTITUDE_DATABASE_URL": "", "ATTITUDE_BOOTSTRAP_TOKEN": TOKEN,
                   "ATTITUDE_MAX_JOBS": str(args.workers), "ATTITUDE_EXECUTOR": mode,
                   "ATTITUDE_RATE_LIMIT_PER_MINUTE": "100000",
                   "ATTITUDE_MAX_JOBS_PER_KEY": str(args.workers)}  # one key: every slot (as on Dask)
            if mode == "dask":
                with dask.config.set({"distributed.scheduler.allowed-failures": 0}), \
                        LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                                     dashboard_address=None, memory_limit=0, silence_logs=40) as cluster:
                    env["ATTITUDE_DASK_ADDRESS"] = cluster.scheduler_address
                    results.append(run_mode(mode, env, scenario, start, args.small, args.timeout))
            else:
                results.append(run_mode(mode, env, scenario, start, args.small, args.timeout))
    local, remote = results
    print(f"\n{'executor':9} {'small jobs':>12} {'throughput':>14} {'long job (' + local['long_type'] + ')':>34}")
    for r in results:
        print(f"{r['mode']:9} {r['small_s']:10.1f} s {r['throughput']:9.2f} jobs/s {r['long_s']:27.1f} s "
              f"({r['long_status']})")
    print(f"\nsmall-job throughput ratio dask/local: {remote['throughput'] / local['throughput']:.2f}")
    print(f"long-job speed ratio dask/local (local time / dask time): {local['long_s'] / remote['long_s']:.2f}")
    same = _close(local["long_result"], remote["long_result"])
    print(f"long job: same summary on both executors (rel 1e-9): {same}")
    for r in results:
        if r["small_counts"]["succeeded"] != args.small or r["long_status"] != "succeeded":
            print(f"WARNING {r['mode']}: small {r['small_counts']}, long {r['long_status']} {r['long_error'] or ''}")
    if local["long_type"] != "gyro_bias_fit":
        print("note: gyro_bias_fit is not registered in app/jobs/registry.py here; the long job was "
              "telemetry_coverage over the same window")


if __name__ == "__main__":
    main()
