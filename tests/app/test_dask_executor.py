"""Jobs on a real Dask cluster (LocalCluster, 2 worker processes): same results as the local executor,
worker loss retried or failed with a clear reason, cancel and timeout, partitioned processing."""

from __future__ import annotations

import importlib
import math
import os
import signal
import time
from dataclasses import replace

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.jobs.partitions import map_concurrent, map_partitions, split_columns, time_partitions
from app.jobs.registry import registry
from app.main import create_app
from processing.simulate.seed003 import simulate_seed003
from processing.time import timescales
from tests.app.helpers import make_spacecraft
from tests.app.test_jobs_api import upload_columns, wait

distributed = pytest.importorskip("distributed")
dask = pytest.importorskip("dask")

pytestmark = pytest.mark.slow

SQLITE_ONLY = pytest.mark.parametrize("database_url", ["sqlite"], indirect=True)
START = int(timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])


@pytest.fixture(scope="module")
def cluster():
    # Worker loss surfaces at once as KilledWorker; the executor's own retry policy decides what follows.
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}), \
            distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                     memory_limit=0, silence_logs=50) as c, \
            distributed.Client(c, set_as_default=False) as client:
        yield c, client


def dask_settings(settings, cluster, **kw):
    return replace(settings, executor="dask", dask_address=cluster[0].scheduler_address, **kw)


def open_client(settings) -> TestClient:
    c = TestClient(create_app(settings))
    c.headers["Authorization"] = f"Bearer {settings.bootstrap_token}"
    return c


def assert_close(a, b, path="result", rel=1e-9, abs_=1e-12):
    """Recursive comparison of JSON values with a float tolerance."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), f"{path}: keys {sorted(a)} != {sorted(b)}"
        for k in a:
            assert_close(a[k], b[k], f"{path}.{k}", rel, abs_)
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), f"{path}: lengths differ"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_close(x, y, f"{path}[{i}]", rel, abs_)
    elif isinstance(a, float) or isinstance(b, float):
        assert a is not None and b is not None and math.isclose(a, b, rel_tol=rel, abs_tol=abs_), f"{path}: {a} != {b}"
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"


def _run_all(client, jobs):
    ids = [client.post("/api/v1/jobs", json={"type": t, "spacecraft": "meteor", "params": p}).json()["id"]
           for t, p in jobs]
    return [wait(client, i, timeout_s=240) for i in ids]


@SQLITE_ONLY  # results do not depend on the backend; PostgreSQL claiming is the local executor's (test_jobs_api)
def test_same_results_on_local_and_dask_executors(settings, cluster):
    scenario = simulate_seed003(start_tai_ns=START, duration_s=600.0, seed=11)
    available = registry()
    jobs = [("telemetry_coverage", {}), ("executor_check", {"duration_s": 0.2})]
    jobs += [(t, {}) for t in ("star_tracker_accuracy", "gyro_bias_fit") if t in available]
    # the pipeline: its two branches go to two workers on Dask, to two threads locally
    jobs += [("reconstruction", {"stage_params": {"gyro_bias_fit": {"subintervals": []}}})]
    with open_client(settings) as local:
        make_spacecraft(local, "meteor", scenario.config)
        for stream, columns in scenario.streams.items():
            upload_columns(local, "meteor", stream, columns)
        on_local = _run_all(local, jobs)
    with open_client(dask_settings(settings, cluster)) as remote:
        on_dask = _run_all(remote, jobs)
        for job_l, job_d in zip(on_local, on_dask, strict=True):
            assert job_l["status"] == job_d["status"] == "succeeded", (job_l["error"], job_d["error"])
            result_l, result_d = dict(job_l["result"]), dict(job_d["result"])
            if job_l["type"] == "executor_check":  # the pid says where it ran
                worker_pids = set(cluster[1].run(os.getpid).values())
                assert result_d.pop("worker_pid") in worker_pids and result_l.pop("worker_pid") not in worker_pids
            assert_close(result_l, result_d, job_l["type"])
            assert job_l["inputs"] == job_d["inputs"]
            arts_l = {a["name"]: a for a in remote.get(f"/api/v1/jobs/{job_l['id']}/artifacts").json()}
            arts_d = {a["name"]: a for a in remote.get(f"/api/v1/jobs/{job_d['id']}/artifacts").json()}
            assert set(arts_l) == set(arts_d)
            for name in arts_l:
                if name.endswith(".csv"):  # tables: identical text (floats printed in full)
                    assert remote.get(arts_l[name]["url"]).text == remote.get(arts_d[name]["url"]).text, name


@SQLITE_ONLY  # the supervision does not depend on the catalog's backend
def test_worker_loss_is_retried_then_failed_with_the_reason(settings, cluster):
    with open_client(dask_settings(settings, cluster, dask_retries=1)) as client:
        make_spacecraft(client)
        r = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1",
                                              "params": {"crash": True}})
        job = wait(client, r.json()["id"], timeout_s=120)
    assert job["status"] == "failed"
    assert "Dask worker running the job died (2 attempts" in job["error"], job["error"]
    cluster[1].wait_for_workers(2, timeout=180)


@SQLITE_ONLY  # the supervision does not depend on the catalog's backend
def test_worker_killed_mid_job_is_retried_and_succeeds(settings, cluster):
    _, dclient = cluster
    dclient.wait_for_workers(2, timeout=180)
    with open_client(dask_settings(settings, cluster, dask_retries=1)) as client:
        make_spacecraft(client)
        job_id = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1",
                                                   "params": {"duration_s": 4.0}}).json()["id"]
        wait(client, job_id, until=("running",))
        deadline = time.monotonic() + 30
        while not (busy := [w for w, keys in dclient.processing().items() if any(job_id in str(k) for k in keys)]):
            assert time.monotonic() < deadline
            time.sleep(0.05)
        killed_pid = dclient.run(os.getpid, workers=busy)[busy[0]]
        time.sleep(0.5)
        os.kill(killed_pid, signal.SIGKILL)  # the worker process dies under the job
        job = wait(client, job_id, timeout_s=120)
    assert job["status"] == "succeeded", job["error"]
    assert job["result"]["worker_pid"] != killed_pid
    dclient.wait_for_workers(2, timeout=180)


@SQLITE_ONLY  # the supervision does not depend on the catalog's backend
def test_cancel_and_timeout_on_dask(settings, cluster):
    cluster[1].wait_for_workers(2, timeout=180)
    with open_client(dask_settings(settings, cluster, job_timeout_s=2)) as client:
        make_spacecraft(client)
        slow = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1",
                                                 "params": {"duration_s": 30}}).json()["id"]
        timed = wait(client, slow, timeout_s=30)
        assert timed["status"] == "failed" and "timed out after 2 s" in timed["error"]
    with open_client(dask_settings(settings, cluster)) as client:
        job_id = client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1",
                                                   "params": {"duration_s": 30}}).json()["id"]
        wait(client, job_id, until=("running",))
        time.sleep(0.3)
        assert client.post(f"/api/v1/jobs/{job_id}/cancel").status_code == 200
        t0 = time.monotonic()
        job = wait(client, job_id, timeout_s=20)
        assert job["status"] == "cancelled" and time.monotonic() - t0 < 5


@SQLITE_ONLY  # the dispatching does not depend on the catalog's backend
def test_a_job_is_running_only_while_a_worker_runs_it(settings, cluster):
    """More jobs than worker threads: the others stay queued in the catalog (not running in Dask's queue), so
    each recorded duration is the job's own and its timeout does not count the wait."""
    from datetime import datetime

    cluster[1].wait_for_workers(2, timeout=180)
    with open_client(dask_settings(settings, cluster)) as client:
        make_spacecraft(client)
        ids = [client.post("/api/v1/jobs", json={"type": "executor_check", "spacecraft": "sat1",
                                                 "params": {"duration_s": 1.0}}).json()["id"] for _ in range(3)]
        most = 0
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            states = [client.get(f"/api/v1/jobs/{i}").json()["status"] for i in ids]
            most = max(most, states.count("running"))
            if all(st in ("succeeded", "failed") for st in states):
                break
            time.sleep(0.05)
        jobs = [client.get(f"/api/v1/jobs/{i}").json() for i in ids]
    assert [j["status"] for j in jobs] == ["succeeded"] * 3
    assert most <= 2  # two worker threads
    spans = [(datetime.fromisoformat(j["started_at"]), datetime.fromisoformat(j["finished_at"])) for j in jobs]
    for start, _ in spans:  # the recorded runs overlap no more than the threads allow: no wait counted in
        assert sum(a <= start < b for a, b in spans) <= 2
    assert all((b - a).total_seconds() >= 1.0 for a, b in spans)


def _partition_sum(part):
    """A module-level partition task (Dask pickles it by reference)."""
    return float(np.sum(part["x"])), os.getpid()


def _fan_out(n_parts: int):
    cols = {"time_tai_ns": np.arange(1000, dtype=np.int64) * 10**9, "x": np.arange(1000, dtype=float)}
    parts = split_columns(cols, time_partitions(0, 999 * 10**9, 100.0))
    return map_partitions(_partition_sum, parts)[:n_parts]


def test_partitions_fan_out_on_the_cluster_and_match_in_process(cluster):
    _, dclient = cluster
    dclient.wait_for_workers(2, timeout=180)
    on_dask = dclient.submit(_fan_out, 10, pure=False).result(timeout=60)
    in_process = _fan_out(10)
    assert [s for s, _ in on_dask] == [s for s, _ in in_process] == [float(sum(range(i * 100, i * 100 + 100)))
                                                                      for i in range(10)]
    assert {pid for _, pid in on_dask} <= set(dclient.run(os.getpid).values())
    assert {pid for _, pid in in_process} == {os.getpid()}


def _branch(part, progress):
    """A module-level branch: sleeps, so that two branches overlap when they run side by side."""
    start = time.time()
    time.sleep(part["sleep_s"])
    return part["name"], os.getpid(), (start, time.time())


def _two_branches(sleep_s: float):
    polls: list[list[int]] = []
    reports: list[tuple[str, float, str]] = []
    out = map_concurrent(_branch, [{"name": "a", "sleep_s": sleep_s}, {"name": "b", "sleep_s": sleep_s}],
                         [lambda f, s, _k=k: reports.append((_k, f, s)) for k in "ab"], poll=polls.append)
    return out, polls, reports


def test_concurrent_branches_run_on_two_workers(cluster):
    """map_concurrent inside a job on the cluster: one task per branch, the two on different workers at the same
    time (the job's task waits without holding its worker's thread), results in the order of the parts."""
    _, dclient = cluster
    dclient.wait_for_workers(2, timeout=180)
    dclient.run(importlib.import_module, __name__)  # every worker has imported this module (as after a first job)
    out, polls, reports = dclient.submit(_two_branches, 1.0, pure=False).result(timeout=120)
    # the job's thread reports for the tasks: both started, then each done
    assert reports[:2] == [("a", 0.0, "running on a Dask worker"), ("b", 0.0, "running on a Dask worker")]
    assert sorted(reports[2:]) == [("a", 1.0, "done on a Dask worker"), ("b", 1.0, "done on a Dask worker")]
    assert [name for name, _, _ in out] == ["a", "b"]
    pids = {pid for _, pid, _ in out}
    assert len(pids) == 2 and pids <= set(dclient.run(os.getpid).values())
    (a0, a1), (b0, b1) = (span for _, _, span in out)
    assert a0 < b1 and b0 < a1, "the branches did not run at the same time"
    assert polls[-1] == [0, 1] and len(polls) >= 2


def test_concurrent_branches_on_a_single_thread_cluster_run_in_order_in_the_task():
    """One worker thread: the parts run one after the other inside the job's task, with their own progress."""
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0",
                                  memory_limit=0, silence_logs=50) as c, \
            distributed.Client(c, set_as_default=False) as client:
        out, polls, reports = client.submit(_two_branches, 0.2, pure=False).result(timeout=60)
    assert [name for name, _, _ in out] == ["a", "b"]
    (a0, a1), (b0, b1) = (span for _, _, span in out)
    assert a1 <= b0, "the parts overlapped on one worker thread"
    assert reports == [] and polls == []  # no Dask tasks to report for: the parts ran here


def test_time_partitions_cover_the_window_once():
    parts = time_partitions(0, 10 * 10**9, 3.0)
    assert parts == [(0, 3 * 10**9), (3 * 10**9, 6 * 10**9), (6 * 10**9, 9 * 10**9), (9 * 10**9, 10 * 10**9 + 1)]
    t = np.arange(0, 10 * 10**9 + 1, 10**8)
    pieces = split_columns({"time_tai_ns": t}, parts)
    assert np.array_equal(np.concatenate([p["time_tai_ns"] for p in pieces]), t)
    assert time_partitions(0, 10 * 10**9, 3.0, overlap_s=1.0)[1] == (2 * 10**9, 7 * 10**9)
    with pytest.raises(ValueError, match="partition_s must be positive"):
        time_partitions(0, 1, 0.0)
