"""One spacecraft-day through ``reconstruction`` in-process, on the worker's code path (issue 24).

Simulates one spacecraft (paper-003 simulator: 10 Hz gyro, 1 Hz star tracker, 1 Hz GNSS, Earth pointing),
uploads it through the API into a temporary data directory (embedded SQLite + Parquet; not timed), submits a
default ``reconstruction`` job through the service and runs it with :func:`app.jobs.runner.execute` - what a
local worker process runs (app/jobs/worker.py) - in this process: reading the window from storage, the
stages, the figures and the output writing. Printed: wall and CPU seconds per stage (each stage's job-type
``run`` timed), figure drawing and output writing, the job's total, artifact count and bytes (largest
first), peak RSS of this process (ru_maxrss; simulation and upload included, so an upper bound), and a
cProfile top ten by cumulative CPU time of the job.

Run: ``.venv/bin/python bench/pipeline_day.py [--hours H] [--seed S] [--top N] [--serial | --in-order]
[--profile-out F]`` (default 24 h; the issue's
target: the job under 6 s on this machine). The machine is shared: compare CPU seconds when the load is high,
and ``--no-profile`` for times without the profiler's overhead.
"""

from __future__ import annotations

import argparse
import cProfile
import importlib
import io
import os
import pstats
import resource
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq
from fastapi.testclient import TestClient

from app.jobs import runner
from app.main import create_app
from app.services import jobs as job_service
from app.services.access import Principal
from app.settings import Settings
from processing.simulate.seed003 import simulate_seed003
from processing.time import timescales
from storage import jobs as jobstore
from storage.db import make_engine, session_factory
from storage.models import Artifact, Job

TOKEN = "bench-pipeline-day-admin-token"


class Clock:
    """Wall and CPU seconds summed per name."""

    def __init__(self) -> None:
        self.wall: dict[str, float] = defaultdict(float)
        self.cpu: dict[str, float] = defaultdict(float)
        self.order: list[str] = []

    def wrap(self, name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def timed(*args: Any, **kwargs: Any) -> Any:
            w, c = time.perf_counter(), time.process_time()
            try:
                return fn(*args, **kwargs)
            finally:
                if name not in self.order:
                    self.order.append(name)
                self.wall[name] += time.perf_counter() - w
                self.cpu[name] += time.process_time() - c
        return timed


def upload(settings: Settings, streams: dict[str, dict[str, Any]], config: dict[str, Any]) -> None:
    with TestClient(create_app(settings)) as client:
        client.headers["Authorization"] = f"Bearer {TOKEN}"
        r = client.post("/api/v1/spacecraft", json={"name": "sat000", "config": config})
        assert r.status_code == 201, r.text
        for stream, columns in streams.items():
            cols = dict(columns)
            t = cols.pop("time_tai_ns")
            table = pa.table({"time": pa.array(t, pa.timestamp("ns")), **cols})
            buf = io.BytesIO()
            pq.write_table(table, buf)
            r = client.post(f"/api/v1/spacecraft/sat000/telemetry/{stream}", content=buf.getvalue(),
                            headers={"Content-Type": "application/vnd.apache.parquet"}, params={"time_scale": "tai"})
            assert r.status_code in (200, 201), r.text


def instrument(clock: Clock) -> None:
    """Time each stage's run, the figures and the output writing: the JOB each job-type module exports (the
    registry reads them afresh on every call) and the runner's own calls, wrapped."""
    for name in ("data_screening", "star_tracker_accuracy", "gyro_bias_fit", "orbital_attitude",
                 "alignment_calibration", "reconstruction"):
        module: Any = importlib.import_module(f"app.jobs.types.{name}")
        job = module.JOB
        if name == "reconstruction":
            module.JOB = replace(job, figures=clock.wrap("figures (drawing)", job.figures))
        else:
            module.JOB = replace(job, run=clock.wrap(name, job.run))
    runner.load_inputs = clock.wrap("reading inputs", runner.load_inputs)
    runner.write_outputs = clock.wrap("output writing", runner.write_outputs)


def in_order() -> None:
    """Every map_partitions of the job types in order and the tables encoded one at a time (cProfile sees only the
    thread it runs in)."""
    from app.jobs import outputs, partitions

    real = partitions.map_partitions

    def serial(func: Any, parts: Any, **kw: Any) -> Any:
        return real(func, parts, **{**kw, "max_workers": 1})

    for name in ("data_screening", "star_tracker_accuracy"):
        importlib.import_module(f"app.jobs.types.{name}").map_partitions = serial
    outputs.ENCODE_THREADS = 1


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--top", type=int, default=10)
    ap.add_argument("--no-profile", action="store_true", help="time without cProfile's overhead (no top list)")
    ap.add_argument("--profile-out", type=Path, help="also dump the job's cProfile stats to this file (pstats)")
    ap.add_argument("--serial", action="store_true", help="the stages one after the other (parallel_stages=false)")
    ap.add_argument("--in-order", action="store_true",
                    help="everything in the job's thread (--serial, partitions and table encoding in order), so that "
                         "the profile sees all the work")
    a = ap.parse_args()
    if a.in_order:
        a.serial = True
        in_order()
    start = int(timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])
    t0 = time.perf_counter()
    sc = simulate_seed003(start_tai_ns=start, duration_s=a.hours * 3600.0, seed=a.seed, st_period_s=1.0,
                          gyro_period_s=0.1, gnss_period_s=1.0)
    rows = {k: len(v["time_tai_ns"]) for k, v in sc.streams.items()}
    print(f"{a.hours:g} h, rows {rows}; simulated in {time.perf_counter() - t0:.1f} s; {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings(data_dir=Path(tmp) / "data", database_url=f"sqlite:///{tmp}/catalog.db",
                            bootstrap_token=TOKEN, scheduler=False, max_jobs=1)
        t0 = time.perf_counter()
        upload(settings, sc.streams, sc.config)
        telemetry_bytes = sum(p.stat().st_size for p in settings.telemetry_dir.rglob("*.parquet"))
        print(f"uploaded in {time.perf_counter() - t0:.1f} s ({telemetry_bytes / 1e6:.1f} MB of telemetry Parquet)")
        engine = make_engine(settings.database_url)
        sessions = session_factory(engine)
        with sessions() as session:
            who = Principal(key_id="bench", name="bench", role="admin")
            body = job_service.JobCreate.model_validate({"type": "reconstruction", "spacecraft": "sat000",
                                                         "params": {"parallel_stages": not a.serial}})
            job = job_service.submit(session, body, who, on_submit=lambda: None)
            job_id = job.id
        with sessions.begin() as session:
            assert jobstore.claim(session, job_id)
        clock = Clock()
        instrument(clock)
        profile = cProfile.Profile(time.process_time)  # CPU seconds: the shared machine's load distorts wall time
        w, c = time.perf_counter(), time.process_time()
        if not a.no_profile:
            profile.enable()
        state = runner.execute(job_id, settings)
        profile.disable()
        wall, cpu = time.perf_counter() - w, time.process_time() - c
        with sessions() as session:
            done = session.get(Job, job_id)
            assert done is not None
            arts = sorted(session.query(Artifact).filter(Artifact.job_id == job_id).all(),
                          key=lambda x: -x.size_bytes)
            stages = (done.result or {}).get("summary", {}).get("stages", {})
            error = done.error
        engine.dispose()
    print(f"\njob {state}{': ' + error if error else ''}: wall {wall:.2f} s, CPU {cpu:.2f} s")
    print(f"{'step':<28}{'wall s':>9}{'CPU s':>9}  status")
    for name in clock.order:
        st = stages.get(name, {})
        print(f"{name:<28}{clock.wall[name]:>9.2f}{clock.cpu[name]:>9.2f}  {st.get('status', '')}")
    for name, st in stages.items():
        if name not in clock.order:
            print(f"{name:<28}{'-':>9}{'-':>9}  {st.get('status')}: {st.get('reason', st.get('error', ''))[:90]}")
    total = sum(x.size_bytes for x in arts)
    print(f"\nartifacts: {len(arts)}, {total / 1e6:.2f} MB ({total / max(telemetry_bytes, 1):.2f}x the telemetry); "
          "largest: " + ", ".join(f"{x.name} {x.size_bytes / 1e6:.2f} MB" for x in arts[:5]))
    print(f"peak RSS of this process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10:.0f} MiB")
    if a.no_profile:
        return
    if a.profile_out is not None:
        profile.dump_stats(a.profile_out)
    out = io.StringIO()
    pstats.Stats(profile, stream=out).sort_stats("cumulative").print_stats(a.top)
    print("\ncProfile (CPU seconds of this process), top by cumulative time:")
    print("\n".join(line for line in out.getvalue().splitlines()[5:] if line.strip()))


if __name__ == "__main__":
    main()
