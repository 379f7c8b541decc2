"""Crash safety of the real server: concurrent uploads and jobs, SIGKILL at random moments, restart.

Each cycle SIGKILLs the service process alone (not its process group): its forkserver and job workers
must die with it. Even cycles kill the service early (its first job submission still importing the job
types, the forkserver still preloading them), odd ones once a job was submitted. After the cycles: every
upload acknowledged with 201 is fully readable, no upload is partly visible, every catalogued file exists
and reads, no unreferenced file is left on disk, and no job stays queued or running. The number of cycles
is ATTITUDE_CRASH_CYCLES (default 3 on SQLite, 2 on PostgreSQL, to keep CI within its budget; set it
higher for a soak run, e.g. 30).
"""

from __future__ import annotations

import http.client
import json
import os
import random
import signal
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from sqlalchemy import create_engine, select

from app.devserver import free_port
from storage.models import TelemetryFile

TOKEN = "crash-test-token"
ROWS = 300
pytestmark = pytest.mark.slow


def request(base, method, path, body=None, content_type=None, timeout=10.0):
    headers = {"Authorization": f"Bearer {TOKEN}"}
    if content_type:
        headers["Content-Type"] = content_type
    req = urllib.request.Request(base + path, data=body, method=method, headers=headers)
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def start(env, log):
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "app.cli", "serve", "--port", str(port), "--log-level", "warning"],
                            env={**os.environ, **env}, stdout=log, stderr=log, start_new_session=True)
    base = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 60
    while True:
        assert proc.poll() is None, "server died during start-up"
        try:
            if request(base, "GET", "/healthz", timeout=2)[0] == 200:
                return proc, base
        except OSError:
            pass
        assert time.monotonic() < deadline, "server did not start"
        time.sleep(0.05)


def descendants(pid: int) -> set[int]:
    """Every live process below ``pid`` (from /proc)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry.name))
    out: set[int] = set()
    todo = [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            out.add(child)
            todo.append(child)
    return out


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def describe(pids: set[int]) -> dict[int, str]:
    """pid -> command line and state, for a failure message."""
    out = {}
    for pid in pids:
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")[:160]
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            cmd, state = "?", "gone"
        out[pid] = f"{state} {cmd}"
    return out


def batch_csv(batch: int) -> bytes:
    t0 = 1_685_577_600 + batch * 1000  # distinct windows, 1000 s apart
    lines = [f"{t0 + 0.5 * i:.1f},{batch},{i},{i * 0.5}" for i in range(ROWS)]
    return ("time,wx,wy,wz\n" + "\n".join(lines) + "\n").encode()


def rows_of(base, batch):
    t0 = 1_685_577_600 + batch * 1000
    status, body = request(base, "GET", f"/api/v1/spacecraft/sat/telemetry/gyro?format=json&time_scale=utc"
                                        f"&start={t0}&end={t0 + 999}")
    assert status == 200
    return json.loads(body)


def test_sigkill_during_uploads_and_jobs(tmp_path: Path, database_url: str):
    cycles = int(os.environ.get("ATTITUDE_CRASH_CYCLES", "3" if database_url.startswith("sqlite") else "2"))
    env = {"ATTITUDE_DATA_DIR": str(tmp_path / "data"), "ATTITUDE_DATABASE_URL": database_url,
           "ATTITUDE_BOOTSTRAP_TOKEN": TOKEN, "ATTITUDE_JOB_HEARTBEAT_TIMEOUT_S": "2", "ATTITUDE_MAX_JOBS": "2",
           "ATTITUDE_RATE_LIMIT_PER_MINUTE": "1000000"}
    rng = random.Random(20261122)
    acknowledged: set[int] = set()
    attempted: set[int] = set()
    next_batch = [0]
    lock = threading.Lock()
    with open(tmp_path / "server.log", "ab") as log:
        for cycle in range(cycles):
            proc, base = start(env, log)
            if cycle == 0:
                assert request(base, "POST", "/api/v1/spacecraft", json.dumps({"name": "sat"}).encode(),
                               "application/json")[0] == 201
            stop = threading.Event()

            def uploader(stop: threading.Event = stop, base: str = base) -> None:
                while not stop.is_set():
                    with lock:
                        batch = next_batch[0]
                        next_batch[0] += 1
                        attempted.add(batch)
                    try:
                        status, _ = request(base, "POST", "/api/v1/spacecraft/sat/telemetry/gyro", batch_csv(batch),
                                            "text/csv")
                    except (OSError, http.client.HTTPException):
                        return  # the server is gone (maybe mid-answer): this batch may or may not have committed
                    if status == 201:
                        with lock:
                            acknowledged.add(batch)

            def reader(stop: threading.Event = stop, base: str = base) -> None:
                while not stop.is_set():
                    try:
                        request(base, "GET", "/api/v1/spacecraft/sat/telemetry/gyro?format=parquet")
                    except (OSError, http.client.HTTPException):
                        return

            submitted = threading.Event()

            def submitter(base: str = base, submitted: threading.Event = submitted) -> None:
                try:
                    request(base, "POST", "/api/v1/jobs", json.dumps(
                        {"type": "executor_check", "spacecraft": "sat", "params": {"duration_s": 0.3}}).encode(),
                        "application/json", timeout=60)
                except (OSError, http.client.HTTPException):
                    return
                submitted.set()

            threads = [threading.Thread(target=uploader) for _ in range(3)]
            threads += [threading.Thread(target=reader), threading.Thread(target=submitter)]
            for t in threads:
                t.start()
            if cycle % 2:  # a job submitted (its worker starting or running) when the service dies
                submitted.wait(60)
                time.sleep(rng.uniform(0.05, 1.0))
            else:  # early: the service's first job submission and the forkserver's preload still under way
                time.sleep(rng.uniform(0.2, 2.0))
            below = descendants(proc.pid)  # the forkserver and any running job worker
            os.kill(proc.pid, signal.SIGKILL)  # the service alone: its workers must follow it
            proc.wait()
            deadline = time.monotonic() + 10
            while (survivors := {p for p in below if alive(p)}) and time.monotonic() < deadline:
                time.sleep(0.05)
            assert not survivors, f"cycle {cycle}: processes outlived the service: {describe(survivors)}"
            stop.set()
            for t in threads:
                t.join(30)

        proc, base = start(env, log)
        try:
            assert len(acknowledged) > cycles, "too few uploads got through to test anything"
            for batch in sorted(attempted):
                rows = rows_of(base, batch)
                if batch in acknowledged:
                    assert len(rows) == ROWS, f"acknowledged batch {batch} has {len(rows)} of {ROWS} rows"
                else:
                    assert len(rows) in (0, ROWS), f"unacknowledged batch {batch} is half visible"
                if rows:
                    assert {r["wx"] for r in rows} == {batch}
            engine = create_engine(database_url)
            with engine.connect() as conn:
                paths = conn.scalars(select(TelemetryFile.path)).all()
            engine.dispose()
            for p in paths:  # the catalog lists only complete, readable files
                assert pq.read_metadata(tmp_path / "data" / "telemetry" / p).num_rows > 0
            on_disk = {str(f.relative_to(tmp_path / "data" / "telemetry"))
                       for f in (tmp_path / "data" / "telemetry").rglob("*.parquet")}
            assert on_disk == set(paths), f"unreferenced files after the restart: {sorted(on_disk - set(paths))}"
            deadline = time.monotonic() + 30
            while True:  # interrupted jobs end (failed by their stopped heartbeat) or finish
                status, body = request(base, "GET", "/api/v1/jobs?limit=500")
                active = [j for j in json.loads(body) if j["status"] in ("queued", "running")]
                if not active:
                    break
                assert time.monotonic() < deadline, f"jobs left active: {active}"
                time.sleep(0.5)
        finally:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
