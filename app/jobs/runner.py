"""Run one job: load its window from storage, call the pure task, store summary and artifacts.

Runs in a worker process (local executor) or on a Dask worker; talks to the catalog and the stores
only through ``Settings``. Every outcome ends in a final state: succeeded, failed (with the reason)
or cancelled. A deliberate input error (processing.tasks.TaskError) fails the job with its message;
any other exception is an internal error, logged with its traceback and recorded as
"internal error: <type>: <message>".
"""

from __future__ import annotations

import logging
import time
import traceback
from typing import Any

import numpy as np
import pyarrow.parquet as pq
from pydantic import BaseModel, ValidationError
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from app.jobs.figures import figure_names, table_rows
from app.jobs.inputs import spacecraft_from_stored
from app.jobs.outputs import jsonable, table_columns, write_outputs
from app.jobs.registry import JobType, registry
from app.reports.inputs import describe_inputs
from app.settings import Settings
from processing.screening.flags import filter_streams
from processing.spacecraft import IDENTITY_QUATERNION, Spacecraft
from processing.streams import STREAMS
from processing.tasks import ReferenceData, TaskError, TaskInputs
from storage import jobs as jobstore
from storage.calibrations import add_version
from storage.db import make_engine, session_factory
from storage.jobs import ArtifactStore
from storage.models import Artifact, Calibration, Job, ReferenceDataset, SpacecraftConfig, utcnow
from storage.parquet_store import ParquetStore
from storage.reference import ReferenceStore
from storage.telemetry import read_window

log = logging.getLogger("attitude.jobs")


class JobCancelled(Exception):
    pass


class ProgressReporter:
    """Progress callback for tasks: stores progress (at most every 0.5 s) and honours cancels."""

    def __init__(self, sessions: sessionmaker[Session], job_id: str, min_interval_s: float = 0.5) -> None:
        self.sessions = sessions
        self.job_id = job_id
        self.min_interval_s = min_interval_s
        self._last = 0.0

    def __call__(self, fraction: float, stage: str) -> None:
        now = time.monotonic()
        if now - self._last < self.min_interval_s and fraction < 1.0:
            return
        self._last = now
        with self.sessions.begin() as session:
            cancel = jobstore.report_progress(session, self.job_id, fraction, stage)
        if cancel:
            raise JobCancelled()


def stream_names(job_type: JobType, params: BaseModel | None = None) -> tuple[str, ...]:
    """The streams a job of this type reads: every one it declares (``params`` None: what a job of the type
    may read, for submission checks and retractions), or, given its validated params, those its
    ``input_streams`` says this run uses (the required ones always)."""
    names = tuple(STREAMS) if job_type.any_stream else job_type.streams + job_type.optional_streams
    if params is None or job_type.input_streams is None:
        return names
    used = set(job_type.input_streams(params)) | set(job_type.streams)
    return tuple(n for n in names if n in used)


def load_inputs(session: Session, settings: Settings, job: Job, job_type: JobType,
                params: BaseModel | None = None) -> tuple[TaskInputs, list[str]]:
    """The task's inputs and notes on what was done to them (calibration applied); with ``params``, only the
    streams the run uses (:func:`stream_names`) are read from the store."""
    store = ParquetStore(settings.telemetry_url)
    spacecraft = spacecraft_from_stored(session.scalar(select(SpacecraftConfig.config).where(
        SpacecraftConfig.spacecraft_id == job.spacecraft_id, SpacecraftConfig.version == job.config_version)),
        job.config_version)
    streams: dict[str, dict[str, np.ndarray]] = {}
    for name in stream_names(job_type, params):
        table = read_window(session, store, job.spacecraft_id, STREAMS[name], job.start_tai_ns, job.end_tai_ns)
        if table.num_rows:
            streams[name] = table_columns(table)
        del table
    missing = [s for s in job_type.streams if s not in streams]
    if missing:
        raise TaskError(f"no {', '.join(missing)} samples in the job window")
    if job_type.any_stream and not streams:
        raise TaskError("no telemetry in the job window")
    screening_id = (job.reference or {}).get(SCREENING_KEY)
    screening_note: list[str] = []
    if screening_id is not None:
        streams = _apply_screening(session, settings, screening_id, streams)
        screening_note = [f"only samples accepted by data_screening job {screening_id} were used"]
    if job_type.applies_calibration:
        torquer = streams.get("magnetorquer")
        pinned = CALIBRATION_PREFIX + job_type.applies_calibration in (job.reference or {})
        if job_type.applies_calibration == "magnetometer" and pinned and torquer is None:  # for the coupling
            table = read_window(session, store, job.spacecraft_id, STREAMS["magnetorquer"], job.start_tai_ns,
                                job.end_tai_ns)
            if table.num_rows:
                torquer = table_columns(table)
        streams, spacecraft, notes = _apply_calibration(session, job, job_type.applies_calibration, streams,
                                                        spacecraft, torquer)
    else:
        notes = []
    notes = screening_note + notes
    references = ReferenceStore(settings.reference_url)
    reference: dict[str, ReferenceData] = {}
    for kind, dataset_id in (job.reference or {}).items():
        if kind.startswith(CALIBRATION_PREFIX) or kind == SCREENING_KEY:
            continue
        dataset = session.get(ReferenceDataset, dataset_id)
        if dataset is None:
            raise TaskError(f"reference data set {dataset_id} ({kind}) chosen for this job no longer exists")
        reference[kind] = ReferenceData(id=dataset.id, name=dataset.name, columns=references.columns(dataset),
                                        details=dataset.details)
    return TaskInputs(streams=streams, spacecraft=spacecraft, start_tai_ns=job.start_tai_ns,
                      end_tai_ns=job.end_tai_ns, reference=reference), notes


CALIBRATION_PREFIX = "calibration:"
SCREENING_KEY = "screening"


def _apply_screening(session: Session, settings: Settings, screening_job_id: str,
                     streams: dict[str, dict[str, np.ndarray]]) -> dict[str, dict[str, np.ndarray]]:
    """Drop the samples a data_screening job rejected (002: later jobs use accepted samples only)."""
    art = session.scalar(select(Artifact).where(Artifact.job_id == screening_job_id,
                                                Artifact.name == "flags.parquet"))
    if art is None:
        raise TaskError(f"data_screening job {screening_job_id} has no flags table")
    table = pq.read_table(ArtifactStore(settings.artifacts_url).path(art))
    flags = {c: table.column(c).to_numpy(zero_copy_only=False) for c in table.column_names}
    return filter_streams(streams, flags)


def _apply_calibration(session: Session, job: Job, kind: str, streams: dict[str, dict[str, np.ndarray]],
                       spacecraft: Spacecraft, torquer: dict[str, np.ndarray] | None = None,
                       ) -> tuple[dict[str, dict[str, np.ndarray]], Spacecraft, list[str]]:
    """Apply the calibration version pinned at submission to the gyro streams (000, eq. 2), or to the
    magnetometer stream (kind "magnetometer": :func:`apply_magnetometer_calibration`; ``torquer`` the
    magnetorquer columns of the window for the coupling term).

    The calibrated data are in the body frame, so the task gets a configuration with an identity gyro
    mounting (a new frozen Spacecraft; the stored one is unchanged)."""
    cal_id = (job.reference or {}).get(CALIBRATION_PREFIX + kind)
    if cal_id is None or kind not in ("gyro", "magnetometer"):
        return streams, spacecraft, []
    cal = session.get(Calibration, cal_id)
    if cal is None:
        raise TaskError(f"the {kind} calibration {cal_id} chosen for this job no longer exists")
    if kind == "magnetometer":
        streams, notes = apply_magnetometer_calibration(streams, cal.values, torquer)
        notes = [n.format(version=cal.version, id=cal.id, job=cal.job_id) for n in notes]
        return streams, spacecraft, notes
    from processing.gyro_calibration.calibration import apply_gyro_calibration  # scipy-heavy: only jobs that need it

    v = cal.values
    for name, cols, interval in (("gyro", ("wx", "wy", "wz"), None),
                                 ("gyro_increments", ("dax", "day", "daz"), "interval_s")):
        if name not in streams:
            continue
        data = dict(streams[name])
        x = np.stack([data[c] for c in cols], axis=-1)
        y = apply_gyro_calibration(x, q_BG=v["q_BG"], scale_factor_error=v["scale_factor_error"],
                                   drift_rad_s=v["drift_rad_s"],
                                   interval_s=data[interval] if interval else None)
        data.update({c: np.ascontiguousarray(y[:, i]) for i, c in enumerate(cols)})
        streams[name] = data
    note = (f"gyro data corrected with calibration version {cal.version} (id {cal.id}, from job {cal.job_id}): "
            "mounting, scale factor and drift; gyro rates are in the body frame")
    return streams, spacecraft.with_gyro_mounting(IDENTITY_QUATERNION), [note]


MAX_TORQUER_AGE_S = 10.0
"""The coupling correction uses the latest magnetorquer sample at or before a magnetometer sample, if this recent."""


def apply_magnetometer_calibration(streams: dict[str, dict[str, np.ndarray]], values: dict[str, Any],
                                   torquer: dict[str, np.ndarray] | None,
                                   ) -> tuple[dict[str, dict[str, np.ndarray]], list[str]]:
    """Correct the calibrated sensor's magnetometer samples: B = (I + D)^-1 (B_meas - b - C mu_B)
    (processing.magnetometer.model); mu_B from the latest magnetorquer sample at or before each sample
    (samples without one within MAX_TORQUER_AGE_S are dropped when the calibration has a coupling).
    Notes carry {version}, {id}, {job} placeholders."""
    from processing.magnetometer.model import MagnetometerErrors

    if "magnetometer" not in streams:
        return streams, []
    C = values.get("coupling_nT_per_A_m2")
    errors = MagnetometerErrors(np.asarray(values["bias_nT"], dtype=np.float64),
                                np.asarray(values["D"], dtype=np.float64),
                                np.zeros((3, 3)) if C is None else np.asarray(C, dtype=np.float64))
    data = dict(streams["magnetometer"])
    sensor = values.get("sensor")
    rows = np.ones(len(data["time_tai_ns"]), dtype=bool) if sensor is None else (
        np.asarray(data["sensor"]).astype(str) == sensor)
    if not np.any(rows):
        return streams, [f"magnetometer calibration version {{version}} is for sensor {sensor!r}, which has no "
                         "samples in the window: not applied"]
    cols = ("bx", "by", "bz")
    B = np.stack([np.asarray(data[c], dtype=np.float64) for c in cols], axis=-1)
    t = np.asarray(data["time_tai_ns"], dtype=np.int64)
    mu = None
    drop = np.zeros(t.size, dtype=bool)
    note = ("magnetometer data corrected with calibration version {version} (id {id}, from job {job}): bias, "
            "scale factors, non-orthogonality")
    if C is not None:
        mu = np.zeros_like(B)
        if torquer is None:
            drop = rows.copy()
        else:
            order = np.argsort(torquer["time_tai_ns"], kind="stable")
            tt = np.asarray(torquer["time_tai_ns"], dtype=np.int64)[order]
            m = np.stack([np.asarray(torquer[c], dtype=np.float64)[order] for c in ("mx", "my", "mz")], axis=-1)
            i = np.searchsorted(tt, t, side="right") - 1
            ic = np.clip(i, 0, None)
            drop = rows & ((i < 0) | (t - tt[ic] > MAX_TORQUER_AGE_S * 1e9))
            mu = m[ic]
        note += " and magnetorquer coupling"
    corrected = errors.correct(B[rows], None if mu is None else mu[rows])
    B[rows] = corrected
    data.update({c: np.ascontiguousarray(B[:, i]) for i, c in enumerate(cols)})
    notes = [note]
    if np.any(drop):
        data = {k: np.asarray(v)[~drop] for k, v in data.items()}
        notes.append(f"{int(np.sum(drop))} magnetometer samples without a magnetorquer sample in the last "
                     f"{MAX_TORQUER_AGE_S:g} s dropped (the calibration's coupling term needs the dipole)")
    out = dict(streams)
    out["magnetometer"] = data
    return out, notes


def execute(job_id: str, settings: Settings) -> str:
    """Run a claimed (running) job to a final state; returns that state."""
    engine = make_engine(settings.database_url)
    sessions = session_factory(engine)
    artifacts = ArtifactStore(settings.artifacts_url)
    try:
        return _execute(job_id, settings, sessions, artifacts)
    finally:
        engine.dispose()


def _finish(sessions: sessionmaker[Session], job_id: str, state: str, **values: Any) -> bool:
    with sessions.begin() as session:
        return jobstore.set_status(session, job_id, state, allowed_from=("running",), **values)


def _execute(job_id: str, settings: Settings, sessions: sessionmaker[Session], artifacts: ArtifactStore) -> str:
    progress = ProgressReporter(sessions, job_id)
    try:
        with sessions() as session:
            job = session.get(Job, job_id)
            if job is None or job.status != "running":
                return job.status if job else "missing"
            # the run starts now, on this worker: its recorded duration excludes the dispatch
            job.started_at = utcnow()
            session.commit()
            job_type = registry()[job.type]
            try:
                params = job_type.params.model_validate(job.params)
            except ValidationError as exc:  # valid at submission; a software update may have changed the model
                raise TaskError(str(exc)) from exc
            progress(0.01, "loading telemetry")
            inputs, input_notes = load_inputs(session, settings, job, job_type, params)
            spacecraft_id = job.spacecraft_id
        # what the record says of the inputs, taken now: the telemetry is let go once the task has run, before
        # the figures and artifacts (the largest arrays of a long window need not be held twice)
        described = describe_inputs(inputs.streams, inputs.start_tai_ns, inputs.end_tai_ns)
        counts = {name: {sensor: int(d["n_samples"]) for sensor, d in described.get(name, {}).items()}
                  for name in inputs.streams}  # samples per stream and sensor
        coverage = jsonable(described)
        progress(0.05, "computing")
        result = job_type.run(inputs, params, progress)
        del inputs
        figures: dict[str, Any] = {}
        if settings.figures == "eager":
            progress(0.9, "drawing figures")
            figures = job_type.figures(result, params)
        # lazy (default): no figure is drawn here; their names, told without drawing, are recorded and each is
        # drawn from the stored artifacts when first requested (app.jobs.figures, app.services.figures)
        names = figure_names(job_type, result.summary, table_rows(result.tables))
        summary = jsonable({"warnings": [w.as_dict() for w in result.warnings], **result.summary})
        stored = write_outputs(artifacts, job_id, result, figures, summary)
        figure_record = {"mode": settings.figures, "names": names}
        with sessions.begin() as session:
            jobstore.add_artifacts(session, job_id, stored)
            done = jobstore.set_status(
                session, job_id, "succeeded", allowed_from=("running",), progress=1.0, stage="done",
                result={"summary": summary, "inputs": counts, "input_coverage": coverage,
                        "notes": input_notes + list(result.notes), "figures": figure_record})
            if done and job_type.produces_calibration and summary.get("calibration_complete"):
                add_version(session, spacecraft_id, job_type.produces_calibration, summary["calibration"], job_id)
            if not done:
                session.rollback()
        if not done:
            artifacts.remove_job(job_id)
            with sessions() as session:
                job = session.get(Job, job_id)
                return job.status if job else "missing"
        return "succeeded"
    except JobCancelled:
        artifacts.remove_job(job_id)
        _finish(sessions, job_id, "cancelled", stage="cancelled")
        return "cancelled"
    except TaskError as exc:  # a deliberate input error: its message is the reason
        artifacts.remove_job(job_id)
        _finish(sessions, job_id, "failed", stage="failed", error=str(exc) or type(exc).__name__)
        return "failed"
    except Exception as exc:  # noqa: BLE001 - anything else (a ValueError too) is a bug: logged with traceback
        log.error("job %s crashed:\n%s", job_id, traceback.format_exc())
        artifacts.remove_job(job_id)
        _finish(sessions, job_id, "failed", stage="failed", error=f"internal error: {type(exc).__name__}: {exc}")
        return "failed"
