"""The typed input boundary in the runner: the stored configuration becomes a processing Spacecraft once,
a pinned gyro calibration gives a new one with an identity gyro mounting (the stored one unchanged), and a
failure is either a deliberate input error (its message) or an internal error (logged with its traceback)."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from pydantic import BaseModel, ConfigDict

from app.config_schema import SpacecraftConfig
from app.jobs import outputs, runner
from app.jobs.inputs import spacecraft_from_config, spacecraft_from_stored
from app.jobs.registry import JobType
from processing.spacecraft import Spacecraft
from processing.tasks import TaskError, TaskInputs, TaskResult
from storage.calibrations import add_version
from storage.db import make_engine, session_factory
from storage.models import Job
from tests.app.helpers import SQLITE_ONLY, make_spacecraft
from tests.app.test_jobs_api import upload_columns

pytestmark = SQLITE_ONLY

S = 2 ** -0.5
CONFIG = {
    "star_trackers": {"st1": {"q_BS": [S, 0.0, S, 0.0]}, "st2": {"q_BS": [1, 0, 0, 0]}},
    "gyro": {"q_BG": [0.0, 0.0, 0.0, 1.0]},
    "magnetometer": {"q_BM": [0.5, 0.5, 0.5, 0.5]},
    "solar_panels": [{"normal_B": [1, 0, 0], "max_current_a": 1.2}, {"normal_B": [0, 1, 0], "max_current_a": 1.1}],
    "gnss_antenna_axis_B": [0, 0, -1],
    "inertia_kg_m2": [[51.44, 0, 0], [0, 51.48, 0], [0, 0, 0.76]],
}
START = 1_700_000_000 * 10**9


def _same(a: Spacecraft, b: Spacecraft) -> None:
    assert a.star_tracker_names == b.star_tracker_names
    for name in a.star_tracker_names:
        np.testing.assert_array_equal(a.star_tracker_mounting(name), b.star_tracker_mounting(name))
    for method in ("gyro_mounting", "magnetometer_mounting", "antenna_axis_B", "panel_normals_B",
                   "panel_max_current_a"):
        np.testing.assert_array_equal(getattr(a, method)(), getattr(b, method)())
    np.testing.assert_array_equal(a.inertia_kg_m2, b.inertia_kg_m2)
    assert (a.sun_sensor_q_BS is None) == (b.sun_sensor_q_BS is None)


def test_the_validated_configuration_becomes_the_processing_spacecraft() -> None:
    typed = spacecraft_from_config(SpacecraftConfig.model_validate(CONFIG))
    _same(typed, Spacecraft.from_json(CONFIG))
    np.testing.assert_allclose(typed.star_tracker_mounting("st1"), [S, 0.0, S, 0.0], rtol=0, atol=1e-16)
    with pytest.raises(TaskError, match=r"the sun sensor is not in the spacecraft configuration"):
        typed.sun_sensor_mounting()
    assert spacecraft_from_stored(None).star_tracker_names == () and not spacecraft_from_stored({}).has_gyro
    with pytest.raises(TaskError, match=r"(?s)spacecraft configuration version 3 is not valid: .*q_BS"):
        spacecraft_from_stored({"star_trackers": {"st1": {"q_BS": [2, 0, 0, 0]}}}, 3)


class NoParams(BaseModel):
    model_config = ConfigDict(extra="forbid")


def seen(inputs: TaskInputs, params: NoParams, progress) -> TaskResult:  # noqa: ANN001
    sc = inputs.spacecraft
    return TaskResult(summary={"q_BS": sc.star_tracker_mounting("st1").tolist(), "q_BG": sc.gyro_mounting().tolist(),
                               "panels": len(sc.solar_panels)})


def input_error(inputs: TaskInputs, params: NoParams, progress) -> TaskResult:  # noqa: ANN001
    inputs.spacecraft.star_tracker_mounting("st9")
    raise AssertionError("unreachable")


def bug(inputs: TaskInputs, params: NoParams, progress) -> TaskResult:  # noqa: ANN001
    raise ValueError("operands could not be broadcast together")


JOBS = {name: JobType(name=name, title=name, paper="", params=NoParams, run=run, applies_calibration=calibration)
        for name, run, calibration in (("seen", seen, None), ("calibrated", seen, "gyro"),
                                       ("input_error", input_error, None), ("bug", bug, None))}


@pytest.fixture
def jobs(client, settings, monkeypatch):
    """Runs a job of the types above through the real runner; returns (state, error, summary)."""
    monkeypatch.setattr(runner, "registry", lambda: JOBS)
    make_spacecraft(client, "sat1", CONFIG)
    engine = make_engine(settings.database_url)
    sessions = session_factory(engine)

    def run(job_type: str, reference: dict | None = None) -> tuple[str, str | None, dict | None]:
        job_id = f"job-{job_type}"
        with sessions.begin() as session:  # claimed already: the executor leaves it to us
            session.add(Job(id=job_id, type=job_type, spacecraft_id=1, config_version=1, start_tai_ns=START,
                            end_tai_ns=START + 10**12, params={}, status="running", stage="starting", progress=0.0,
                            software_version="test", cancel_requested=False, reference=reference or {}))
        state = runner.execute(job_id, settings)
        with sessions() as session:
            job = session.get(Job, job_id)
            assert job is not None and job.status == state
            return state, job.error, (job.result or {}).get("summary")

    run.sessions = sessions  # type: ignore[attr-defined]
    yield run
    engine.dispose()


def test_the_runner_gives_the_task_the_typed_configuration(jobs) -> None:
    state, error, summary = jobs("seen")
    assert state == "succeeded", error
    np.testing.assert_allclose(summary["q_BS"], [S, 0.0, S, 0.0], rtol=0, atol=1e-16)
    assert summary["q_BG"] == [0.0, 0.0, 0.0, 1.0] and summary["panels"] == 2


def test_a_pinned_gyro_calibration_gives_an_identity_gyro_mounting(jobs) -> None:
    with jobs.sessions.begin() as session:
        cal = add_version(session, 1, "gyro", {"q_BG": [1.0, 0.0, 0.0, 0.0], "scale_factor_error": 0.0,
                                               "drift_rad_s": [0.0, 0.0, 0.0]}, None)
        cal_id = cal.id
    state, error, summary = jobs("calibrated", {"calibration:gyro": cal_id})
    assert state == "succeeded", error
    assert summary["q_BG"] == [1.0, 0.0, 0.0, 0.0]
    state, error, summary = jobs("seen")  # the stored configuration keeps its mounting
    assert summary["q_BG"] == [0.0, 0.0, 0.0, 1.0]


def test_input_errors_fail_with_their_message_other_errors_are_internal_and_logged(jobs, caplog) -> None:
    with caplog.at_level(logging.ERROR, logger="attitude.jobs"):
        state, error, _ = jobs("input_error")
    assert state == "failed"
    assert error == ("star tracker 'st9' is not in the spacecraft configuration (configured: st1, st2); "
                     "add star_trackers.st9.q_BS")
    assert not caplog.records
    with caplog.at_level(logging.ERROR, logger="attitude.jobs"):
        state, error, _ = jobs("bug")
    assert state == "failed"
    assert error == "internal error: ValueError: operands could not be broadcast together"
    logged = "\n".join(r.getMessage() for r in caplog.records)
    assert "job job-bug crashed" in logged and "Traceback" in logged and "in bug" in logged


class GyroChoice(BaseModel):
    model_config = ConfigDict(extra="forbid")
    use_gyro: bool = True


def streams_seen(inputs: TaskInputs, params: GyroChoice, progress) -> TaskResult:  # noqa: ANN001
    return TaskResult(summary={"streams": sorted(inputs.streams)})


def test_a_stream_the_params_leave_unused_is_not_read(client, settings, monkeypatch) -> None:
    """input_streams: the runner reads only what this run uses (the required streams always), through the real
    store; without the declaration, or for submission checks (no params), every declared stream."""
    declared = JobType(name="picky", title="picky", paper="", params=GyroChoice, run=streams_seen,
                       streams=("star_tracker",), optional_streams=("gyro", "gnss"),
                       input_streams=lambda p: ("gyro",) if p.use_gyro else ())
    monkeypatch.setattr(runner, "registry", lambda: {"picky": declared})
    make_spacecraft(client, "sat1", CONFIG)
    t = START + np.arange(5, dtype=np.int64) * 10**9
    upload_columns(client, "sat1", "star_tracker", {"time_tai_ns": t, "sensor": ["st1"] * 5, "q0": np.ones(5),
                                                    "q1": np.zeros(5), "q2": np.zeros(5), "q3": np.zeros(5)})
    upload_columns(client, "sat1", "gyro", {"time_tai_ns": t, "sensor": ["g1"] * 5, "wx": np.zeros(5),
                                            "wy": np.zeros(5), "wz": np.full(5, 1e-3)})
    read: list[str] = []
    real_read = runner.read_window
    monkeypatch.setattr(runner, "read_window", lambda s, store, sc, spec, *a: read.append(spec.name) or real_read(
        s, store, sc, spec, *a))
    sessions = session_factory(engine := make_engine(settings.database_url))
    try:
        summaries = {}
        for use_gyro in (True, False):
            job_id = f"job-gyro-{use_gyro}"
            with sessions.begin() as session:
                session.add(Job(id=job_id, type="picky", spacecraft_id=1, config_version=1, start_tai_ns=START,
                                end_tai_ns=START + 10**12, params={"use_gyro": use_gyro}, status="running",
                                stage="starting", progress=0.0, software_version="test", cancel_requested=False,
                                reference={}))
            assert runner.execute(job_id, settings) == "succeeded"
            with sessions() as session:
                job = session.get(Job, job_id)
                summaries[use_gyro] = (job.result["summary"]["streams"], sorted(job.result["inputs"]))
            summaries[use_gyro] += (sorted(read),)
            read.clear()
    finally:
        engine.dispose()
    assert summaries[True] == (["gyro", "star_tracker"], ["gyro", "star_tracker"], ["gyro", "star_tracker"])
    assert summaries[False] == (["star_tracker"], ["star_tracker"], ["star_tracker"])
    assert runner.stream_names(declared) == ("star_tracker", "gyro", "gnss")


def test_stored_columns_become_the_same_arrays_with_one_str_per_sensor() -> None:
    import pyarrow as pa

    chunks = [pa.table({"time_tai_ns": pa.array(t, pa.int64()), "sensor": pa.array(s), "wx": pa.array(w)})
              for t, s, w in (([1, 2, 3], ["g1", "g2", "g1"], [0.5, 1.5, 2.5]), ([4], ["g2"], [3.5]))]
    table = pa.concat_tables(chunks)
    cols = outputs.table_columns(table)
    assert cols["sensor"].dtype == object and cols["sensor"].tolist() == ["g1", "g2", "g1", "g2"]
    assert all(type(x) is str for x in cols["sensor"]) and cols["sensor"][0] is cols["sensor"][2]
    np.testing.assert_array_equal(cols["time_tai_ns"], [1, 2, 3, 4])
    np.testing.assert_array_equal(cols["wx"], [0.5, 1.5, 2.5, 3.5])
    one = outputs.table_columns(pa.table({"sensor": pa.array(["st1"] * 3)}))["sensor"]
    assert one.shape == (3,) and one.tolist() == ["st1"] * 3


def test_a_window_is_read_in_identity_order_whatever_order_its_files_came_in(client, settings) -> None:
    """read_window gives (sensor, time) order: one sensor's files uploaded later part first are sorted (the
    catalog lists them in upload order); one sensor's files in time order are taken as they are; two sensors'
    files are sorted by sensor, then time."""
    from processing.streams import STREAMS
    from storage.parquet_store import ParquetStore
    from storage.telemetry import read_window

    make_spacecraft(client, "sat1", CONFIG)
    t = START + np.arange(30, dtype=np.int64) * 10**9

    def gyro(rows, sensor):
        return {"time_tai_ns": t[rows], "sensor": [sensor] * len(t[rows]), "wx": t[rows] / 1e18,
                "wy": np.zeros(len(t[rows])), "wz": np.zeros(len(t[rows]))}

    for rows, sensor in ((slice(20, 30), "g1"), (slice(0, 10), "g1"), (slice(10, 20), "g1"),
                         (slice(0, 30), "g0")):
        upload_columns(client, "sat1", "gyro", gyro(rows, sensor))
    engine = make_engine(settings.database_url)
    try:
        with session_factory(engine)() as session:
            store = ParquetStore(settings.telemetry_url)
            for sensor in ("g1", "g0", None):
                table = read_window(session, store, 1, STREAMS["gyro"], START, START + 10**12, sensor=sensor)
                names = table.column("sensor").to_pylist()
                times = table.column("time_tai_ns").to_numpy()
                expected = sorted(zip(names, times.tolist(), strict=True))
                assert list(zip(names, times.tolist(), strict=True)) == expected
                assert len(expected) == (60 if sensor is None else 30) == len(set(expected))
                np.testing.assert_array_equal(table.column("wx").to_numpy(), times / 1e18)
    finally:
        engine.dispose()
