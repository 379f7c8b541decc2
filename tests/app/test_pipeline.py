"""The reconstruction pipeline: stage order, screened data and the gyro bias passed along, progress by
stage, one combined result and report. Real stages where their job types exist (star_tracker_accuracy,
gyro_bias_fit); small stand-ins for the stages still being written (screening, orbital attitude)."""

from __future__ import annotations

import dataclasses
import importlib

import numpy as np
import pytest
from pydantic import BaseModel, ConfigDict

from app.jobs import registry as registry_module
from app.jobs.registry import JobType
from app.jobs.types import reconstruction, reconstruction_flow
from processing.attitude import rotations
from processing.simulate.seed003 import simulate_seed003
from processing.spacecraft import Spacecraft
from processing.tasks import TaskError, TaskInputs, TaskResult
from processing.time import timescales
from tests.app.helpers import SQLITE_ONLY

pytestmark = SQLITE_ONLY

START = int(timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])


class NoParams(BaseModel):
    model_config = ConfigDict(extra="forbid")


def fake_screening(inputs: TaskInputs, params: NoParams, progress) -> TaskResult:
    """Rejects every 10th star-tracker sample (a 'flags' table shaped as data_screening's artifact)."""
    st = inputs.stream("star_tracker")
    n = len(st["time_tai_ns"])
    rejected = np.arange(n) % 10 == 0
    progress(0.5, "flagging")
    return TaskResult(summary={"star_tracker": {"n_total": n, "n_rejected": int(rejected.sum())}},
                      tables={"flags": {"time_tai_ns": st["time_tai_ns"], "stream": np.full(n, "star_tracker"),
                                        "sensor": st["sensor"], "key": np.full(n, ""), "accepted": ~rejected}})


def fake_orbital(inputs: TaskInputs, params: NoParams, progress) -> TaskResult:
    g = inputs.stream("gyro")
    return TaskResult(summary={"mean_rate_rad_s": [float(np.mean(g[c])) for c in ("wx", "wy", "wz")],
                               "n_star_tracker": len(inputs.stream("star_tracker")["time_tai_ns"])})


def failing(inputs: TaskInputs, params: NoParams, progress) -> TaskResult:
    raise TaskError("no orbit in the window")


def _registry(extra: dict[str, JobType]):
    jobs = {}
    for module in ("star_tracker_accuracy", "gyro_bias_fit"):
        try:
            job = importlib.import_module(f"app.jobs.types.{module}").JOB
        except Exception:  # noqa: BLE001 - a stage being written may not import yet: leave it out
            continue
        jobs[job.name] = job
    jobs.update(extra)
    jobs["reconstruction"] = reconstruction.JOB
    return jobs


SCREENING = JobType(name="data_screening", title="screening (stand-in)", paper="", params=NoParams,
                    run=fake_screening, any_stream=True)
ORBITAL = JobType(name="orbital_attitude", title="orbital (stand-in)", paper="", params=NoParams, run=fake_orbital,
                  streams=("star_tracker", "gyro"))


@pytest.fixture(scope="module")
def scenario():
    return simulate_seed003(start_tai_ns=START, duration_s=600.0, seed=11)


@pytest.fixture
def inputs(scenario):
    return TaskInputs(streams=scenario.streams, spacecraft=Spacecraft.from_json(scenario.config), start_tai_ns=START,
                      end_tai_ns=START + 600 * 10**9)


@pytest.fixture
def stages(monkeypatch):
    jobs = _registry({"data_screening": SCREENING, "orbital_attitude": ORBITAL})
    from app.jobs import runner
    from app.services import jobs as jobs_service

    for module in (registry_module, runner, jobs_service):  # in-process only: worker processes import afresh
        monkeypatch.setattr(module, "registry", lambda: jobs)
    return jobs


def test_pipeline_runs_the_registered_stages_and_passes_data_along(stages, inputs):
    calls = []
    params = reconstruction.Params(stage_params={"gyro_bias_fit": {"subintervals": []}}
                                   if "gyro_bias_fit" in stages else {}, parallel_stages=False)
    result = reconstruction.run(inputs, params, lambda f, s: calls.append((f, s)))
    expected = [s for s in reconstruction.STAGE_NAMES if s in stages and s != "alignment_calibration"]
    assert result.summary["stages_run"] == expected
    # progress: monotone, inside the runner's span, every stage named, in order
    fractions = [f for f, _ in calls]
    assert fractions == sorted(fractions) and 0.05 <= fractions[0] and fractions[-1] == pytest.approx(0.88)
    seen = list(dict.fromkeys(s.split(":")[0] for _, s in calls))
    assert seen == expected
    # screened data: every later stage saw 10 % fewer star-tracker samples
    n_st = len(inputs.streams["star_tracker"]["time_tai_ns"])
    n_rejected = result.summary["stages"]["data_screening"]["summary"]["star_tracker"]["n_rejected"]
    assert result.summary["calibrations"]["screened_out"] == {"star_tracker": n_rejected}
    assert result.summary["stages"]["orbital_attitude"]["summary"]["n_star_tracker"] == n_st - n_rejected
    screened, _ = reconstruction.apply_screening(inputs.streams, stages["data_screening"].run(inputs, NoParams(),
                                                                                             lambda f, s: None))
    screened_inputs = TaskInputs(streams=screened, spacecraft=inputs.spacecraft, start_tai_ns=inputs.start_tai_ns,
                                 end_tai_ns=inputs.end_tai_ns)
    if "star_tracker_accuracy" in stages:  # the stage's summary is the stand-alone job's on the screened data
        jt = stages["star_tracker_accuracy"]
        alone = jt.run(screened_inputs, jt.params(), lambda f, s: None)
        assert repr(result.summary["stages"]["star_tracker_accuracy"]["summary"]) == repr(
            {"warnings": [w.as_dict() for w in alone.warnings], **alone.summary})
    raw_mean = np.array([np.mean(inputs.streams["gyro"][c]) for c in ("wx", "wy", "wz")])
    seen_mean = np.array(result.summary["stages"]["orbital_attitude"]["summary"]["mean_rate_rad_s"])
    if "gyro_bias_fit" in stages:  # calibration: orbital attitude got the rates without the fitted bias
        bias_B = np.array(result.summary["calibrations"]["gyro_bias_rad_s"])
        q_BG = inputs.spacecraft.gyro_mounting()
        bias_G = rotations.quat_rotate(rotations.quat_conjugate(q_BG), bias_B)
        np.testing.assert_allclose(seen_mean, raw_mean - bias_G, rtol=0, atol=1e-15)
        assert np.linalg.norm(bias_B) > 0
        assert any(k.startswith("gyro_bias_fit__") for k in result.tables)
    else:
        np.testing.assert_array_equal(seen_mean, raw_mean)


def test_stage_selection_failure_and_continue(stages, inputs, monkeypatch):
    result = reconstruction.run(inputs, reconstruction.Params(stages=["data_screening", "orbital_attitude"]),
                                lambda f, s: None)
    assert result.summary["stages_run"] == ["data_screening", "orbital_attitude"]
    broken = dict(stages, orbital_attitude=JobType(name="orbital_attitude", title="", paper="", params=NoParams,
                                                   run=failing, streams=("magnetometer",)))
    monkeypatch.setattr(registry_module, "registry", lambda: broken)
    result = reconstruction.run(inputs, reconstruction.Params(stages=["data_screening", "orbital_attitude"]),
                                lambda f, s: None)
    assert result.summary["stages"]["orbital_attitude"] == {"status": "skipped",
                                                           "reason": "no magnetometer samples in the window"}
    mag = dict(inputs.streams, magnetometer={"time_tai_ns": np.array([START]), "sensor": np.array(["magnetometer"]),
                                             **{c: np.zeros(1) for c in ("bx", "by", "bz")}})
    with_gnss = TaskInputs(streams=mag, spacecraft=inputs.spacecraft, start_tai_ns=START, end_tai_ns=START + 10**12)
    with pytest.raises(TaskError, match="pipeline stage orbital_attitude failed: no orbit in the window"):
        reconstruction.run(with_gnss, reconstruction.Params(stages=["data_screening", "orbital_attitude"]),
                           lambda f, s: None)
    result = reconstruction.run(with_gnss, reconstruction.Params(stages=["data_screening", "orbital_attitude"],
                                                                 continue_on_error=True), lambda f, s: None)
    assert result.summary["stages"]["orbital_attitude"]["status"] == "failed"
    assert "orbital_attitude failed: no orbit in the window" in result.notes
    with pytest.raises(TaskError, match="unknown stages"):
        reconstruction.run(inputs, reconstruction.Params(stages=["astrology"]), lambda f, s: None)
    with pytest.raises(ValueError, match="data_screening: x: Extra inputs"):  # refused at submission (issue 22)
        reconstruction.Params(stage_params={"data_screening": {"x": 1}})
    stored_before = reconstruction.Params.model_construct(  # params stored before that check: refused at run time
        stages=None, stage_params={"data_screening": {"x": 1}}, calibrate_alignment=None, apply_screening=True,
        apply_gyro_bias=True, continue_on_error=False)
    with pytest.raises(TaskError, match="stage_params.data_screening"):
        reconstruction.run(inputs, stored_before, lambda f, s: None)


def test_pipeline_job_end_to_end_with_one_combined_report(stages, settings, scenario):
    """Through the real runner: artifacts of every stage, prefixed, and one report with all stages."""
    from fastapi.testclient import TestClient

    from app.jobs import runner
    from app.main import create_app
    from storage.db import make_engine, session_factory
    from storage.models import Job
    from tests.app.helpers import make_spacecraft
    from tests.app.test_jobs_api import upload_columns

    with TestClient(create_app(settings)) as client:
        client.headers["Authorization"] = f"Bearer {settings.bootstrap_token}"
        make_spacecraft(client, "meteor", scenario.config)
        for stream, columns in scenario.streams.items():
            upload_columns(client, "meteor", stream, columns)
        engine = make_engine(settings.database_url)
        with session_factory(engine).begin() as session:  # claimed already: the executor leaves it to us
            params = {"stage_params": {"gyro_bias_fit": {"subintervals": []}} if "gyro_bias_fit" in stages else {}}
            session.add(Job(id="pipeline1", type="reconstruction", spacecraft_id=1, config_version=1,
                            start_tai_ns=START, end_tai_ns=START + 600 * 10**9, params=params, status="running",
                            stage="starting", progress=0.0, software_version="test", cancel_requested=False))
        engine.dispose()
        assert runner.execute("pipeline1", settings) == "succeeded"
        job = client.get("/api/v1/jobs/pipeline1").json()
        assert job["status"] == "succeeded" and job["progress"] == 1.0
        assert job["result"]["stages_run"][0] == "data_screening"
        names = {a["name"] for a in client.get("/api/v1/jobs/pipeline1/artifacts").json()}
        assert "summary.json" in names
        if "star_tracker_accuracy" in stages:
            assert any(n.startswith("star_tracker_accuracy__") and n.endswith(".png") for n in names)
        html = client.get("/api/v1/jobs/pipeline1/report").text
        for stage in job["result"]["stages_run"]:
            assert stage in html


def test_real_screening_output_is_applied_with_its_own_filter(inputs):
    try:
        screening = importlib.import_module("app.jobs.types.data_screening").JOB
        from processing.screening.flags import filter_streams
    except Exception:  # noqa: BLE001 - not written yet in this checkout
        pytest.skip("data_screening is not available")
    result = screening.run(inputs, screening.params(), lambda f, s: None)
    screened, removed = reconstruction.apply_screening(inputs.streams, result)
    expected = filter_streams(inputs.streams, result.tables["flags"])
    assert screened.keys() == expected.keys()
    for name in expected:
        np.testing.assert_array_equal(screened[name]["time_tai_ns"], expected[name]["time_tai_ns"])
        assert removed.get(name, 0) == len(inputs.streams[name]["time_tai_ns"]) - len(expected[name]["time_tai_ns"])


def test_alignment_stage_is_skipped_on_an_arc_without_rate_variation(inputs):
    """Earth pointing (seed 003): a constant rate cannot be told from drift, so the stage says why it did not
    run instead of spending the pipeline's largest share on null results; an arc with slews passes."""
    params = reconstruction.Params(stages=["alignment_calibration"], calibrate_alignment=True)
    if "alignment_calibration" not in registry_module.registry():
        pytest.skip("alignment_calibration is not registered")
    result = reconstruction.run(inputs, params, lambda f, s: None)
    stage = result.summary["stages"]["alignment_calibration"]
    assert stage["status"] == "skipped" and "hardly varies" in stage["reason"]
    assert result.summary["stages_run"] == []
    assert isinstance(reconstruction._alignment_excited(inputs, 0.0), TaskInputs)
    t = inputs.streams["gyro"]["time_tai_ns"]
    slews = {**inputs.streams["gyro"], "wx": 0.01 * np.sin(2 * np.pi * (t - t[0]) / 3e11)}
    moved = TaskInputs(streams={**inputs.streams, "gyro": slews}, spacecraft=inputs.spacecraft,
                       start_tai_ns=inputs.start_tai_ns, end_tai_ns=inputs.end_tai_ns)
    assert reconstruction._alignment_excited(moved, 0.01) is moved


def test_in_sorted_is_isin():
    """The gyro bridging's membership test by binary search is np.isin (duplicates, misses, empty sides)."""
    rng = np.random.default_rng(1)
    for _ in range(30):
        x = rng.integers(0, 500, size=rng.integers(0, 200))
        values = np.sort(rng.integers(0, 500, size=rng.integers(0, 200)))
        np.testing.assert_array_equal(reconstruction_flow._in_sorted(x, values), np.isin(x, values))


def _tables_equal(a, b):
    assert set(a) == set(b)
    for name in a:
        assert set(a[name]) == set(b[name]), name
        for col in a[name]:
            np.testing.assert_array_equal(np.asarray(a[name][col]), np.asarray(b[name][col]), err_msg=f"{name}.{col}")


def test_branches_side_by_side_give_the_serial_result(stages, inputs, monkeypatch):
    """star_tracker_accuracy and gyro_bias_fit -> orbital_attitude run at the same time, in threads of their own;
    the result (summary, tables, notes, warnings) is the one of the stages in order, the progress never goes
    back and names every stage."""
    import threading

    from app.jobs import plausibility

    threads: dict[str, set[int]] = {}
    timed = {}
    for name, jt in stages.items():
        if name == "reconstruction":
            continue

        def run(i, p, progress, _run=jt.run, _name=name):
            threads.setdefault(_name, set()).add(threading.get_ident())
            return _run(i, p, progress)
        timed[name] = dataclasses.replace(jt, run=run)
    timed["reconstruction"] = stages["reconstruction"]
    monkeypatch.setattr(registry_module, "registry", lambda: timed)
    stage_params = {"gyro_bias_fit": {"subintervals": []}} if "gyro_bias_fit" in stages else {}
    runs = {}
    for parallel in (False, True):
        plausibility._cache.clear()
        calls: list[tuple[float, str]] = []
        runs[parallel] = reconstruction.run(
            inputs, reconstruction.Params(stage_params=stage_params, parallel_stages=parallel),
            lambda f, s, _calls=calls: _calls.append((f, s)))
        fractions = [f for f, _ in calls]
        assert fractions == sorted(fractions) and fractions[-1] == pytest.approx(0.88)
        assert {s.split(":")[0] for _, s in calls} == set(runs[parallel].summary["stages_run"])
    serial, parallel = runs[False], runs[True]
    assert repr(serial.summary) == repr(parallel.summary)
    assert serial.notes == parallel.notes
    assert [w.as_dict() for w in serial.warnings] == [w.as_dict() for w in parallel.warnings]
    _tables_equal(serial.tables, parallel.tables)
    if {"star_tracker_accuracy", "gyro_bias_fit"} <= set(stages):
        assert serial.summary["stages_run"] == ["data_screening", "star_tracker_accuracy", "gyro_bias_fit",
                                                "orbital_attitude"]
        # serial: every stage on this thread; side by side: the two branches each on a thread of their own
        assert {len(t) for t in threads.values()} <= {1, 2}
        assert threads["star_tracker_accuracy"] - threads["data_screening"]
        assert not (threads["star_tracker_accuracy"] - threads["data_screening"]) & threads["gyro_bias_fit"]


def test_failures_in_both_branches_report_the_first_stage_in_pipeline_order(stages, inputs, monkeypatch):
    def fails(message):
        def run(inputs, params, progress):
            if message == "slow":
                import time
                time.sleep(0.3)  # fails after the other branch did: the order of failing does not choose
            raise TaskError(message)
        return run

    broken = dict(stages, star_tracker_accuracy=JobType(name="star_tracker_accuracy", title="", paper="",
                                                        params=NoParams, run=fails("slow"), any_stream=True),
                  gyro_bias_fit=JobType(name="gyro_bias_fit", title="", paper="", params=NoParams,
                                        run=fails("no gyro fit"), any_stream=True))
    monkeypatch.setattr(registry_module, "registry", lambda: broken)
    for parallel in (True, False):
        with pytest.raises(TaskError, match="pipeline stage star_tracker_accuracy failed: slow"):
            reconstruction.run(inputs, reconstruction.Params(parallel_stages=parallel), lambda f, s: None)
        result = reconstruction.run(inputs, reconstruction.Params(parallel_stages=parallel, continue_on_error=True),
                                    lambda f, s: None)
        assert result.summary["stages"]["star_tracker_accuracy"] == {"status": "failed", "error": "slow"}
        assert result.summary["stages"]["gyro_bias_fit"] == {"status": "failed", "error": "no gyro fit"}
        assert result.summary["stages_run"] == ["data_screening", "orbital_attitude"]
        assert [n for n in result.notes if "failed" in n] == ["star_tracker_accuracy failed: slow",
                                                             "gyro_bias_fit failed: no gyro fit"]


def test_a_cancel_while_the_branches_run_stops_the_pipeline(stages, inputs, monkeypatch):
    """The job's own thread checks for a cancel while it waits for the branches: the cancel propagates."""
    import threading

    from app.jobs.runner import JobCancelled

    release = threading.Event()

    def slow(inputs, params, progress):
        assert release.wait(30)
        return TaskResult(summary={})

    slowed = dict(stages, star_tracker_accuracy=JobType(name="star_tracker_accuracy", title="", paper="",
                                                        params=NoParams, run=slow, any_stream=True))
    monkeypatch.setattr(registry_module, "registry", lambda: slowed)
    polls = []

    def progress(fraction, stage):
        polls.append(stage)
        if sum(not p.startswith("data_screening") for p in polls) > 3:  # the branches started, one is waiting
            release.set()
            raise JobCancelled()

    with pytest.raises(JobCancelled):
        reconstruction.run(inputs, reconstruction.Params(stages=["data_screening", "star_tracker_accuracy",
                                                                 "orbital_attitude"]), progress)
