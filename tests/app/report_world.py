"""Simulated spacecraft with every job type run once: shared by the report and browser tests.

Seed-003 (Meteor-M: star tracker, gyros, GNSS) and seed-004 (gyroless microsatellite: magnetometer,
sun sensor, GNSS, magnetorquers) telemetry with known truth is uploaded; every registered job type runs
with its default parameters on the first spacecraft that has the streams it needs, so new job types
are covered as soon as they are registered.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import types
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from app.jobs.registry import JobType, registry
from processing.simulate.seed003 import simulate_seed003
from processing.time import timescales

START_ISO = "2023-06-01T00:00:00Z"
START = int(timescales.iso_to_tai_ns([START_ISO])[0])
DURATION_S = 600.0
SEED = 3
SPACECRAFT = "meteor-sim"
# Limits loose enough for the simulated sensors, plus a generic one that fails on purpose (the
# simulation has star-tracker gaps), so every report shows both PASS and FAIL rows where they apply.
SPECIFICATIONS = {
    "star_tracker_sigma_arcsec": [10.0, 10.0, 40.0],
    "gyro_bias_max_deg_h": [20.0, 20.0, 20.0],
    "orbital_attitude_deg": {"pitch": [-1.0, 1.0], "yaw": [-2.0, 3.0], "roll": [-1.0, 1.0]},
    "limits": [{"job_type": "telemetry_coverage", "key": "n_gaps", "max": 0, "label": "gaps in the window"}],
}
# Summary keys that legitimately differ between two runs of the same job.
VOLATILE_KEYS = {"worker_pid"}


def output_dir(*parts: str) -> Path:
    """Where tests leave artifacts for people (screenshots, PDF pages): $ATTITUDE_TEST_OUTPUT or var/test-output."""
    root = Path(os.environ.get("ATTITUDE_TEST_OUTPUT") or Path(__file__).resolve().parents[2] / "var" / "test-output")
    path = root.joinpath(*parts)
    path.mkdir(parents=True, exist_ok=True)
    return path


GYROLESS = "microsat-sim"
SMALLSAT = "smallsat-sim"
# Job types that belong to one scenario's paper even where another spacecraft has the streams they need.
PREFERRED = {"data_screening": SMALLSAT, "vector_attitude": SMALLSAT, "gyroless_ekf": GYROLESS}


def scenario() -> Any:
    return simulate_seed003(start_tai_ns=START, duration_s=DURATION_S, seed=SEED)


def scenarios() -> dict[str, Any]:
    """Spacecraft name -> simulated scenario (``streams``, ``config``, ``truth``), the seed-003 one first."""
    from processing.formats.rinex_nav import parse_rinex_nav_reference
    from processing.simulate.seed002 import simulate_seed002
    from processing.simulate.seed004 import simulate_seed004
    from tests.real_data import GNSS_NAV

    worlds = {SPACECRAFT: scenario(), GYROLESS: simulate_seed004(start_tai_ns=START, duration_s=DURATION_S, seed=4)}
    # paper 002: magnetometer, panel currents, GNSS visibility from the real ephemerides
    nav = (GNSS_NAV / "brdc2800.15n").read_bytes()
    worlds[SMALLSAT] = simulate_seed002(nav=parse_rinex_nav_reference(nav).columns, seed=2, duration_s=DURATION_S)
    return worlds


def config_with_specs(config: dict[str, Any]) -> dict[str, Any]:
    return {**config, "specifications": SPECIFICATIONS}


def runnable(job_types: Iterable[JobType], streams: Iterable[str]) -> tuple[list[str], dict[str, str]]:
    """(types to run, {type: why it is skipped}) for the simulated streams."""
    present = set(streams)
    run, skipped = [], {}
    for jt in sorted(job_types, key=lambda j: j.name):
        missing = [s for s in jt.streams if s not in present]
        if missing:
            skipped[jt.name] = f"needs {', '.join(missing)}, which the simulation does not provide"
        else:
            run.append(jt.name)
    return run, skipped


def assign(job_types: Iterable[JobType], worlds: dict[str, Any]) -> tuple[dict[str, str], dict[str, str]]:
    """({job type: the first spacecraft with the streams it needs}, {job type: why none has them})."""
    where: dict[str, str] = {}
    skipped: dict[str, str] = {}
    types = list(job_types)
    for name, sim in worlds.items():
        run, _ = runnable(types, sim.streams)
        for t in run:
            if PREFERRED.get(t, name) == name:
                where.setdefault(t, name)
    for jt in types:
        if jt.name in where:
            continue
        if PREFERRED.get(jt.name) is not None:  # its paper's scenario could not be simulated here
            skipped[jt.name] = f"its scenario ({PREFERRED[jt.name]}) is not simulated here"
        else:
            skipped[jt.name] = (f"needs {', '.join(jt.streams)}, which no simulated spacecraft "
                                f"({', '.join(worlds)}) provides")
    return where, skipped


WORLD_ADMIN = "report-world-admin-token-0123456789"


def run_in_process(jt: JobType, sim: Any) -> tuple[Any, Any]:
    """(TaskResult, params) of the job type run directly, with default params, on the simulated streams it reads."""
    from app.jobs.runner import stream_names
    from processing.spacecraft import Spacecraft
    from processing.tasks import TaskInputs, no_progress

    names = stream_names(jt)
    streams = {k: v for k, v in sim.streams.items() if k in names}
    times = [np.asarray(v["time_tai_ns"], dtype=np.int64) for v in streams.values()] or [np.array([0])]
    inputs = TaskInputs(streams=streams, spacecraft=Spacecraft.from_json(config_with_specs(sim.config)),
                        start_tai_ns=int(min(t.min() for t in times)), end_tai_ns=int(max(t.max() for t in times)),
                        reference={})
    params = jt.params.model_validate({})
    return jt.run(inputs, params, no_progress), params


def _build_world(data_dir: Path) -> dict[str, dict[str, Any]]:
    """Upload every scenario into a service on ``data_dir`` (SQLite catalog inside it) and run every job type
    once on its spacecraft; returns {job type: the finished job as the API shows it}."""
    from fastapi.testclient import TestClient

    from app.main import create_app
    from app.settings import Settings
    from tests.app.test_jobs_api import upload_columns, wait

    settings = Settings(data_dir=data_dir, database_url=f"sqlite:///{data_dir / 'catalog.db'}",
                        bootstrap_token=WORLD_ADMIN, max_jobs=2)
    worlds = scenarios()
    with TestClient(create_app(settings)) as client:
        client.headers["Authorization"] = f"Bearer {WORLD_ADMIN}"
        for sc, sim in worlds.items():
            r = client.post("/api/v1/spacecraft", json={"name": sc, "config": config_with_specs(sim.config)})
            assert r.status_code == 201, r.text
            for stream, columns in sim.streams.items():
                upload_columns(client, sc, stream, columns)
        where, _ = assign(registry().values(), worlds)
        ids = {}
        for name, sc in where.items():
            r = client.post("/api/v1/jobs", json={"type": name, "spacecraft": sc})
            assert r.status_code == 202, (name, r.text)
            ids[name] = r.json()["id"]
        return {name: wait(client, job_id, timeout_s=900) for name, job_id in ids.items()}


def report_world(tmp_path_factory: Any, name: str) -> types.SimpleNamespace:
    """A private copy of the report world: ``data_dir`` (catalog ``data_dir/catalog.db``), ``jobs``,
    ``worlds`` (the scenarios), ``where``/``skipped`` (:func:`assign`), ``sim`` (the seed-003 one).

    The world is built once per test run and copied for each caller: under pytest-xdist the workers share
    it through a directory beside their base temporary directories, built by the first under a file lock
    (the report tests and the browser tests both need it, and it costs tens of seconds of CPU)."""
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    base = Path(tmp_path_factory.getbasetemp())
    cache = base.parent / f"report-world-{run}" if run else base / "report-world"
    with open(f"{cache}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (cache / "jobs.json").exists():
            shutil.rmtree(cache, ignore_errors=True)
            jobs = _build_world(cache / "data")
            (cache / "jobs.json").write_text(json.dumps(jobs))
    dest = Path(tmp_path_factory.mktemp(name)) / "data"
    shutil.copytree(cache / "data", dest)
    worlds = scenarios()
    where, skipped = assign(registry().values(), worlds)
    return types.SimpleNamespace(data_dir=dest, jobs=json.loads((cache / "jobs.json").read_text()), worlds=worlds,
                                 where=where, skipped=skipped, sim=worlds[SPACECRAFT])


def all_type_names() -> list[str]:
    return sorted(registry())


def strip_volatile(summary: Any) -> Any:
    if isinstance(summary, dict):
        return {k: strip_volatile(v) for k, v in summary.items() if k not in VOLATILE_KEYS}
    if isinstance(summary, list):
        return [strip_volatile(v) for v in summary]
    return summary


def png_ink_fraction(png_path: Path) -> float:
    """Share of pixels that are not (near) white: 0 for a blank page."""
    from matplotlib.image import imread

    img = np.asarray(imread(png_path))
    rgb = img[..., :3].astype(float)
    if rgb.max() > 1.0:
        rgb = rgb / 255.0
    return float(np.mean(rgb.min(axis=-1) < 0.9))


def missing_tools(tools: dict[str, str]) -> str | None:
    """None when every binary is on PATH ({binary: Debian package}), else the reason to skip with the
    command that installs them. Tests never install anything: `.ci/run` does, as root."""
    missing = {b: p for b, p in tools.items() if shutil.which(b) is None}
    if not missing:
        return None
    packages = " ".join(sorted(set(missing.values())))
    return (f"{', '.join(missing)} not installed: install the Debian packages {packages} "
            "(as root; .ci/run does it for CI)")
