"""Constellation benchmark (issue 24): K simulated spacecraft x H hours (10 Hz gyro, 1 Hz star tracker, 1 Hz
GNSS, Earth pointing; the paper-003 simulator) uploaded over HTTP and run through the ``reconstruction``
pipeline, on the local executor and on a Dask LocalCluster with 1 and 2 workers, in the same run.

For each executor: a service process of its own (SQLite + Parquet in a temporary directory), the K uploads
(timed: ingest), then K reconstruction jobs submitted at once; the job records are polled every 0.25 s and
the time each job spends in each stage (its ``stage`` field) is summed. Printed per executor: minutes per
spacecraft-day (wall time of the K jobs / K / days), the split between ingest and each stage (CPU-seconds
summed over jobs, as the jobs overlap), peak memory (the largest summed RSS of the service and all its
child processes, and of the Dask workers, sampled with the polls), and the scaling ratio (local time over
the executor's time). At the end, the extrapolation to 100 spacecraft-days.

Run: ``.venv/bin/python bench/constellation.py [--spacecraft K] [--hours H] [--modes local,dask1,dask2]``
(defaults K=10, H=24: tens of minutes on 2 cores; ``--spacecraft 2 --hours 6`` for a quick look).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections import defaultdict
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from app.client import ApiClient
from app.devserver import running_server, serving_pid
from processing.simulate.seed003 import simulate_seed003
from processing.time import timescales

TOKEN = "bench-constellation-admin-token"
POLL_S = 0.25


def _tree_rss_bytes(root_pid: int) -> int:
    """Summed RSS of a process and all its descendants (Linux /proc)."""
    children: dict[int, list[int]] = defaultdict(list)
    rss: dict[int, int] = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text().rsplit(")", 1)[1].split()
            rss[int(d.name)] = int(stat[21]) * os.sysconf("SC_PAGE_SIZE")
            children[int(stat[1])].append(int(d.name))
        except (OSError, IndexError, ValueError):
            continue
    total, todo = 0, [root_pid]
    while todo:
        pid = todo.pop()
        total += rss.get(pid, 0)
        todo += children.get(pid, [])
    return total


def run_mode(mode: str, env: dict[str, str], scenarios: list[Any], timeout_s: float,
             dask_pids: list[int]) -> dict[str, Any]:
    with running_server(env) as base:
        client = ApiClient(base, TOKEN)
        pid = serving_pid(base)
        t0 = time.perf_counter()
        for k, sc in enumerate(scenarios):
            client.post("/api/v1/spacecraft", {"name": f"sat{k:03d}", "config": sc.config})
            for stream, columns in sc.streams.items():
                client.upload_columns(f"sat{k:03d}", stream, columns)
        ingest_s = time.perf_counter() - t0
        client.wait_for_job(client.submit_job("executor_check", "sat000")["id"], timeout_s=timeout_s)  # warm-up
        t0 = time.perf_counter()
        ids = [client.submit_job("reconstruction", f"sat{k:03d}")["id"] for k in range(len(scenarios))]
        stage_s: dict[str, float] = defaultdict(float)
        peak = 0
        deadline = time.monotonic() + timeout_s
        last = time.perf_counter()
        jobs: dict[str, Any] = {}
        while True:
            jobs = {i: client.get(f"/api/v1/jobs/{i}") for i in ids}
            now = time.perf_counter()
            for j in jobs.values():
                if j["status"] == "running":
                    stage_s[(j["stage"] or "?").split(":")[0].strip()] += now - last
            last = now
            peak = max(peak, _tree_rss_bytes(pid) + sum(_tree_rss_bytes(p) for p in dask_pids))
            if all(j["status"] in ("succeeded", "failed", "cancelled") for j in jobs.values()):
                break
            if time.monotonic() > deadline:
                raise TimeoutError(f"{mode}: reconstruction jobs not finished after {timeout_s} s")
            time.sleep(POLL_S)
        run_s = time.perf_counter() - t0
    failed = {i: j["error"] for i, j in jobs.items() if j["status"] != "succeeded"}
    return {"mode": mode, "ingest_s": ingest_s, "run_s": run_s, "stage_s": dict(stage_s), "peak_rss": peak,
            "failed": failed}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--spacecraft", type=int, default=10)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--modes", default="local,dask1,dask2")
    ap.add_argument("--timeout", type=float, default=7200.0)
    a = ap.parse_args()
    start = int(timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])
    t = time.perf_counter()
    scenarios = [simulate_seed003(start_tai_ns=start, duration_s=a.hours * 3600.0, seed=100 + k, st_period_s=1.0,
                                  gyro_period_s=0.1, gnss_period_s=1.0) for k in range(a.spacecraft)]
    rows = {k: len(v["time_tai_ns"]) for k, v in scenarios[0].streams.items()}
    days = a.hours / 24.0
    print(f"{a.spacecraft} spacecraft x {a.hours:g} h, rows per spacecraft {rows} (simulated in "
          f"{time.perf_counter() - t:.0f} s); {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}")
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for mode in a.modes.split(","):
            env = {"ATTITUDE_DATA_DIR": str(Path(tmp) / mode), "ATTITUDE_DATABASE_URL": "",
                   "ATTITUDE_BOOTSTRAP_TOKEN": TOKEN, "ATTITUDE_MAX_JOBS": "2",
                   "ATTITUDE_RATE_LIMIT_PER_MINUTE": "1000000", "ATTITUDE_EXECUTOR": "local",
                   "ATTITUDE_JOB_TIMEOUT_S": str(int(a.timeout))}
            with ExitStack() as stack:
                dask_pids: list[int] = []
                if mode.startswith("dask"):
                    import dask
                    from distributed import Client, LocalCluster

                    stack.enter_context(dask.config.set({"distributed.scheduler.allowed-failures": 0}))
                    cluster = stack.enter_context(LocalCluster(n_workers=int(mode[4:] or 1), threads_per_worker=1,
                                                               processes=True, dashboard_address=None, memory_limit=0,
                                                               silence_logs=40))
                    with Client(cluster) as c:
                        dask_pids = list(c.run(os.getpid).values())
                    env.update(ATTITUDE_EXECUTOR="dask", ATTITUDE_DASK_ADDRESS=cluster.scheduler_address)
                r = run_mode(mode, env, scenarios, a.timeout, dask_pids)
            results.append(r)
            per_day = r["run_s"] / a.spacecraft / days / 60.0
            stages = ", ".join(f"{k} {v:.0f} s" for k, v in sorted(r["stage_s"].items(), key=lambda kv: -kv[1]))
            print(f"\n{mode}: ingest {r['ingest_s']:.1f} s ({r['ingest_s'] / a.spacecraft:.1f} s per spacecraft); "
                  f"pipeline {r['run_s']:.1f} s for {a.spacecraft} -> {per_day:.2f} min per spacecraft-day; "
                  f"peak RSS {r['peak_rss'] / 2**30:.2f} GiB")
            print(f"  job-seconds per stage (summed over the overlapping jobs): {stages}")
            if r["failed"]:
                print(f"  FAILED: {r['failed']}")
    base = results[0]
    print("\nscaling (wall time of the first mode / this mode):",
          ", ".join(f"{r['mode']} {base['run_s'] / r['run_s']:.2f}" for r in results))
    best = min(results, key=lambda r: r["run_s"])
    per_sc_day = (best["run_s"] + best["ingest_s"]) / a.spacecraft / days
    print(f"extrapolated: 100 spacecraft-days on this machine ({best['mode']}) ~ {100 * per_sc_day / 60:.0f} min; "
          f"in 10 minutes it would take ~{max(1, round(100 * per_sc_day / 600 * 2))} cores at this per-core cost")


if __name__ == "__main__":
    main()
