"""Job memory benchmark (issue 24): peak RSS of each job type that reads telemetry, per hour of data.

The paper-003 scenario at the constellation benchmark's rates (10 Hz gyro, 1 Hz star tracker, 1 Hz GNSS)
is simulated over the longest duration, uploaded once (in-process service, SQLite + Parquet in a temporary
directory), and each (job type, duration) runs in a child process of its own through the real runner
(``app.jobs.runner.execute``: loading from the store, the task, figures and artifacts). The child reports
its resident memory after the job modules are imported (``base``) and its peak (``VmHWM``) after the job;
``job`` = peak - base is what the job itself needed.

Printed per job type: the job's memory at each duration, MB per hour of data (the slope between the
shortest and the longest duration) and the growth ratio job(longest) / job(shortest) against the ratio of
the durations (equal: memory linear in the window; smaller: sub-linear).

Run: ``.venv/bin/python bench/job_memory.py [--hours 1,6,24] [--types star_tracker_accuracy,...]``
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

CASES: dict[str, tuple[str, dict[str, Any]]] = {  # label -> (job type, params)
    "star_tracker_accuracy": ("star_tracker_accuracy", {}),
    "star_tracker_accuracy(use_gyro=false)": ("star_tracker_accuracy", {"use_gyro": False}),
    "data_screening": ("data_screening", {}),
    "gyro_bias_fit": ("gyro_bias_fit", {}),
    "orbital_attitude": ("orbital_attitude", {}),
    "reconstruction": ("reconstruction", {}),
}
DEFAULT_CASES = ("star_tracker_accuracy", "star_tracker_accuracy(use_gyro=false)", "data_screening",
                 "gyro_bias_fit")
TOKEN = "bench-job-memory-admin-token-0123"


def _status_kb(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise RuntimeError(f"{field} not in /proc/self/status")


def child(data_dir: str, job_id: str) -> None:
    """Run one job through the runner; print base and peak RSS (MB) as JSON."""
    import matplotlib

    matplotlib.use("Agg")
    from app.jobs import runner
    from app.jobs.registry import registry
    from app.settings import Settings

    registry()  # every job module imported before the base is taken
    settings = Settings.from_env({"ATTITUDE_DATA_DIR": data_dir})
    base = _status_kb("VmRSS")
    t = time.perf_counter()
    state = runner.execute(job_id, settings)
    wall = time.perf_counter() - t
    print(json.dumps({"state": state, "base_mb": base / 1024, "peak_mb": _status_kb("VmHWM") / 1024,
                      "wall_s": wall}))


def _prepare(data_dir: Path, hours: float) -> tuple[int, dict[str, int]]:
    """Simulate and upload; returns the window start and the rows per stream."""
    import dataclasses
    import io

    import pyarrow as pa
    import pyarrow.parquet as pq
    from fastapi.testclient import TestClient

    from app.main import create_app
    from app.settings import Settings
    from processing.simulate.seed003 import simulate_seed003
    from processing.time import timescales

    start = int(timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])
    scenario = simulate_seed003(start_tai_ns=start, duration_s=hours * 3600.0, seed=7, st_period_s=1.0,
                                gyro_period_s=0.1, gnss_period_s=1.0)
    settings = Settings.from_env({"ATTITUDE_DATA_DIR": str(data_dir), "ATTITUDE_BOOTSTRAP_TOKEN": TOKEN})
    settings = dataclasses.replace(settings, scheduler=False)
    with TestClient(create_app(settings)) as c:
        c.headers["Authorization"] = f"Bearer {TOKEN}"
        r = c.post("/api/v1/spacecraft", json={"name": "bench", "config": scenario.config})
        assert r.status_code in (200, 201), r.text
        for stream, columns in scenario.streams.items():
            cols = dict(columns)
            t = cols.pop("time_tai_ns")
            table = pa.table({"time": pa.array(t, pa.timestamp("ns")), **cols})
            buf = io.BytesIO()
            pq.write_table(table, buf)
            r = c.post(f"/api/v1/spacecraft/bench/telemetry/{stream}", content=buf.getvalue(),
                       headers={"Content-Type": "application/vnd.apache.parquet"}, params={"time_scale": "tai"})
            assert r.status_code in (200, 201), r.text
    return start, {k: len(v["time_tai_ns"]) for k, v in scenario.streams.items()}


def _add_job(data_dir: Path, job_id: str, job_type: str, params: dict[str, Any], start: int, end: int) -> None:
    from app.settings import Settings
    from storage.db import make_engine, session_factory
    from storage.models import Job, Spacecraft, SpacecraftConfig

    settings = Settings.from_env({"ATTITUDE_DATA_DIR": str(data_dir)})
    engine = make_engine(settings.database_url)
    with session_factory(engine).begin() as session:
        sc_id = session.query(Spacecraft.id).filter(Spacecraft.name == "bench").scalar()
        version = session.query(SpacecraftConfig.version).filter(SpacecraftConfig.spacecraft_id == sc_id).scalar()
        session.add(Job(id=job_id, type=job_type, spacecraft_id=sc_id, config_version=version, start_tai_ns=start,
                        end_tai_ns=end, params=params, status="running", stage="starting", progress=0.0,
                        software_version="bench", cancel_requested=False, reference={}))
    engine.dispose()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", default="1,6,24", help="window lengths (comma-separated)")
    ap.add_argument("--types", default=",".join(DEFAULT_CASES), help=f"cases, of: {', '.join(CASES)}")
    ap.add_argument("--child", nargs=2, metavar=("DATA_DIR", "JOB_ID"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        child(*a.child)
        return
    hours = sorted(float(h) for h in a.hours.split(","))
    cases = [c.strip() for c in a.types.split(",") if c.strip()]
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        ap.error(f"unknown cases {unknown}; known: {', '.join(CASES)}")
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "data"
        t = time.perf_counter()
        start, rows = _prepare(data, hours[-1])
        print(f"telemetry: {hours[-1]:g} h, rows {rows} (simulated and uploaded in {time.perf_counter() - t:.1f} s)")
        print(f"\n{'case':40} {'hours':>5} {'base MB':>8} {'peak MB':>8} {'job MB':>8} {'wall s':>7}  state")
        results: dict[str, list[tuple[float, float]]] = {}
        for case in cases:
            job_type, params = CASES[case]
            for h in hours:
                job_id = f"{job_type}-{len(results.get(case, []))}-{abs(hash(case)) % 10**6}-{h:g}h"
                _add_job(data, job_id, job_type, params, start, start + int(h * 3600e9))
                out = subprocess.run([sys.executable, __file__, "--child", str(data), job_id], check=True,
                                     capture_output=True, text=True)
                r = json.loads(out.stdout.strip().splitlines()[-1])
                job_mb = r["peak_mb"] - r["base_mb"]
                results.setdefault(case, []).append((h, job_mb))
                print(f"{case:40} {h:5g} {r['base_mb']:8.0f} {r['peak_mb']:8.0f} {job_mb:8.0f} {r['wall_s']:7.1f}  "
                      f"{r['state']}", flush=True)
        print(f"\n{'case':40} {'MB per hour':>12} {'growth ratio':>13} {'hours ratio':>12}")
        for case, pts in results.items():
            (h0, m0), (h1, m1) = pts[0], pts[-1]
            slope = (m1 - m0) / (h1 - h0) if h1 > h0 else float("nan")
            print(f"{case:40} {slope:12.1f} {m1 / m0 if m0 > 0 else float('nan'):13.2f} {h1 / h0:12.1f}")


if __name__ == "__main__":
    main()
