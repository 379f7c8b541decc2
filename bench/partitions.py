"""Partitioned processing benchmark (issue 24): one long job on the local executor's worker and on a Dask
LocalCluster of 2 single-threaded worker processes, in the same run.

The job types that split their work with ``app.jobs.partitions.map_partitions`` (star_tracker_accuracy: the
per-segment smoothings; data_screening: the streams after GNSS), and the ``reconstruction`` pipeline that runs
both (its branches side by side: ``map_concurrent``), run on ``--hours`` of the paper-003 scenario at
the constellation benchmark's rates (10 Hz gyro, 1 Hz star tracker, 1 Hz GNSS):

- ``serial``: the job's ``run`` here, its parts one after the other (map_partitions with one worker; for
  ``reconstruction`` also its stages, ``parallel_stages=false``);
- ``local``: the job's ``run`` here, as in a local worker process (map_partitions: a thread pool);
- ``dask``: the job's ``run`` as a task on one worker of the cluster (as the Dask executor submits it), its
  parts submitted from there to every worker (map_partitions: ``worker_client``).

The inputs are simulated once and, for Dask, scattered to the cluster before the clock starts (the executor's
task reads them from the store on the worker). Each mode runs ``--repeat`` times after one warm-up; the best
time is printed with the ratios serial/dask and local/dask, and whether the summaries agree (1e-12 relative).

Run: ``.venv/bin/python bench/partitions.py [--hours 24] [--types star_tracker_accuracy,data_screening]``
"""

from __future__ import annotations

import argparse
import math
import os
import time
from functools import partial
from typing import Any

PARAMS: dict[str, dict[str, Any]] = {"star_tracker_accuracy": {}, "data_screening": {}, "reconstruction": {}}


SPLITTING = ("app.jobs.types.data_screening", "app.jobs.types.star_tracker_accuracy")
"""The job-type modules that call map_partitions (``serial`` runs their parts in order)."""


def run_job_type(name: str, inputs: Any, params: dict[str, Any], max_workers: int | None = None) -> dict[str, Any]:
    """The job type's run (on whichever process calls it, with the allocator set as the Dask executor's task
    sets it: app.jobs.allocator); returns its summary. ``max_workers=1``: every map_partitions in order, and a
    pipeline's stages one after the other."""
    import importlib

    import matplotlib

    matplotlib.use("Agg")
    from app.jobs import partitions
    from app.jobs.allocator import reuse_large_blocks
    from app.jobs.registry import registry
    from processing.tasks import no_progress

    if partitions._dask_client_available():
        reuse_large_blocks()
    jt = registry()[name]
    if max_workers != 1:
        return dict(jt.run(inputs, jt.params.model_validate(params), no_progress).summary)
    real = partitions.map_partitions

    def serial(func: Any, parts: Any, **kw: Any) -> Any:
        return real(func, parts, **{**kw, "max_workers": 1})

    modules = [importlib.import_module(m) for m in SPLITTING]
    for module in modules:
        module.map_partitions = serial  # type: ignore[attr-defined]
    try:
        if name == "reconstruction":
            params = {**params, "parallel_stages": False}
        return dict(jt.run(inputs, jt.params.model_validate(params), no_progress).summary)
    finally:
        for module in modules:
            module.map_partitions = real  # type: ignore[attr-defined]


def _close(a: Any, b: Any, rel: float = 1e-12) -> bool:
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k], rel) for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(_close(x, y, rel) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, rel_tol=rel, abs_tol=1e-300)
    return bool(a == b)


def _inputs(hours: float) -> Any:
    from processing.simulate.seed003 import simulate_seed003
    from processing.spacecraft import Spacecraft
    from processing.tasks import TaskInputs
    from processing.time import timescales

    start = int(timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])
    sc = simulate_seed003(start_tai_ns=start, duration_s=hours * 3600.0, seed=7, st_period_s=1.0,
                          gyro_period_s=0.1, gnss_period_s=1.0)
    streams = {name: dict(cols) for name, cols in sc.streams.items()}
    end = max(int(c["time_tai_ns"][-1]) for c in streams.values())
    return TaskInputs(streams=streams, spacecraft=Spacecraft.from_json(sc.config), start_tai_ns=start,
                      end_tai_ns=end)


def _best(fn: Any, repeat: int) -> tuple[float, Any]:
    fn()  # warm-up: imports, caches
    best, out = float("inf"), None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--types", default=",".join(PARAMS))
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args()
    import dask
    from distributed import Client, LocalCluster

    t = time.perf_counter()
    inputs = _inputs(a.hours)
    rows = {k: len(v["time_tai_ns"]) for k, v in inputs.streams.items()}
    print(f"telemetry: {a.hours:g} h, rows {rows} (simulated in {time.perf_counter() - t:.1f} s)")
    names = [n.strip() for n in a.types.split(",") if n.strip()]
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}), \
            LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                         memory_limit=0, silence_logs=40) as cluster, Client(cluster) as client:
        remote = client.scatter(inputs, broadcast=True)
        print(f"\n{'job type':24} {'serial s':>9} {'local s':>9} {'dask s':>9} {'serial/dask':>12} "
              f"{'local/dask':>11}  same summary")
        for name in names:
            params = PARAMS[name]
            serial_s, serial = _best(partial(run_job_type, name, inputs, params, max_workers=1), a.repeat)
            local_s, local = _best(partial(run_job_type, name, inputs, params), a.repeat)
            dask_s, remote_summary = _best(
                partial(lambda n, p: client.submit(run_job_type, n, remote, p, pure=False).result(), name, params),
                a.repeat)
            same = _close(serial, local) and _close(serial, remote_summary)
            print(f"{name:24} {serial_s:9.2f} {local_s:9.2f} {dask_s:9.2f} {serial_s / dask_s:12.2f} "
                  f"{local_s / dask_s:11.2f}  {same}", flush=True)
    load = os.getloadavg()[0]
    print(f"\nload average (1 min) at the end: {load:.1f} on {os.cpu_count()} cores: parallel parts gain only "
          "on cores that other processes leave free")


if __name__ == "__main__":
    main()
