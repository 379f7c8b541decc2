"""Dask executor: jobs run as tasks on a Dask distributed cluster (``ATTITUDE_EXECUTOR=dask``).

Same contract as :class:`app.jobs.executor.LocalExecutor`: the catalog is the queue, a dispatcher
thread claims queued jobs with the conditional UPDATE of :func:`storage.jobs.claim` (so several
service instances never run one job twice) and submits ``app.jobs.runner.execute(job_id, settings)``
to the cluster at ``ATTITUDE_DASK_ADDRESS``. Workers need the same software and reach the same
catalog (``ATTITUDE_DATABASE_URL``) and Parquet store (``ATTITUDE_DATA_URL``); the task itself stores
the results and final state, exactly as in a local worker process.

Supervision (the service side, like the local executor):

- heartbeats for every job in flight; ``fail_stale`` fails jobs whose service died;
- worker loss: Dask reports ``KilledWorker`` (or loses the task); the job is submitted again up to
  ``ATTITUDE_DASK_RETRIES`` times, then failed with a message that says the worker died;
- cancel and timeout: a task cannot be killed from outside, so the job is moved to its final state
  here after a grace period and ``cancel_requested`` is set: the task stops at its next progress
  report and its late result is discarded by the conditional state changes (``allowed_from``).

Nothing is left running forever: every in-flight job ends by its task, by the timeout, or by the
stale-heartbeat reaper of any instance.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any, Protocol

from sqlalchemy import select, update
from sqlalchemy.orm import Session, sessionmaker

from app.jobs.dispatch import CANCEL_GRACE_S, CatalogDispatcher
from app.settings import Settings
from storage import jobs as jobstore
from storage.jobs import ArtifactStore
from storage.models import Job, utcnow

log = logging.getLogger("attitude.executor.dask")



class Executor(Protocol):
    """What the app needs of an executor (LocalExecutor, DaskExecutor)."""

    def start(self) -> None: ...
    def wake(self) -> None: ...
    def stop(self) -> None: ...


def make_executor(settings: Settings, sessions: sessionmaker[Session]) -> Executor:
    """The executor chosen by ``ATTITUDE_EXECUTOR`` (``local`` or ``dask``)."""
    if settings.executor == "dask":
        return DaskExecutor(settings, sessions)
    if settings.executor != "local":
        raise ValueError(f"unknown executor {settings.executor!r}; expected local or dask")
    from app.jobs.executor import LocalExecutor

    return LocalExecutor(settings, sessions)


def run_job(job_id: str, settings: Settings) -> str:
    """The task a Dask worker runs: the same runner as the local worker processes (with the allocator set as
    app.jobs.allocator explains)."""
    import matplotlib

    from app.jobs.allocator import reuse_large_blocks

    reuse_large_blocks()
    matplotlib.use("Agg")
    from app.jobs import runner

    return runner.execute(job_id, settings)


@dataclass
class _InFlight:
    future: Any  # distributed.Future
    started: float
    attempt: int
    cancel_seen_at: float | None = None


def _is_worker_loss(exc: BaseException | None) -> bool:
    from distributed.scheduler import KilledWorker

    if isinstance(exc, KilledWorker):
        return True
    name = type(exc).__name__ if exc is not None else ""
    return name in ("KilledWorker", "CommClosedError", "FutureCancelledError") or (
        exc is not None and "lost" in str(exc).lower())


class DaskExecutor(CatalogDispatcher[_InFlight]):
    """Dispatch catalog-queued jobs to a Dask cluster; ``client`` may be given (tests, benchmarks)."""

    thread_name = "dask-job-dispatcher"

    def __init__(self, settings: Settings, sessions: sessionmaker[Session], client: Any = None,
                 poll_s: float = 0.1, max_in_flight: int | None = None) -> None:
        super().__init__(settings, sessions, poll_s)
        self._client = client
        self._own_client = client is None
        self._max_in_flight = max_in_flight

    @property
    def client(self) -> Any:
        return self._client

    def _connect(self) -> None:
        if self._client is None:
            from distributed import Client

            if not self.settings.dask_address:
                raise ValueError("the Dask executor needs ATTITUDE_DASK_ADDRESS")
            self._client = Client(self.settings.dask_address, set_as_default=False, timeout="30s")

    def _disconnect(self) -> None:
        if self._own_client and self._client is not None:
            self._client.close()

    def _abandon(self, job_id: str, run: _InFlight) -> None:
        run.future.cancel()
        self._end(job_id, "failed", "the service shut down while the job was running", cancel_task=True)

    def capacity(self) -> int:
        """Jobs kept in flight: the configured maximum, or the cluster's worker threads - no more, so that a
        job claimed (``running`` in the catalog, its timeout counting) starts on a worker at once instead of
        waiting in the scheduler's queue; the others stay ``queued`` in the catalog."""
        if self._max_in_flight is not None:
            return self._max_in_flight
        try:
            threads = sum(self._client.nthreads().values())
        except Exception:  # noqa: BLE001 - a scheduler hiccup: keep what is in flight
            return len(self._running)
        return max(1, threads)

    def _launch(self, job_id: str) -> None:
        try:
            self._submit(job_id, 1)
        except Exception as exc:  # noqa: BLE001 - e.g. the scheduler is unreachable
            self._end(job_id, "failed", f"could not submit the job to the Dask cluster: {exc}")

    def _submit(self, job_id: str, attempt: int) -> None:
        future = self._client.submit(run_job, job_id, self.settings, key=f"attitude-job-{job_id}-{attempt}",
                                     pure=False, retries=0)
        self._running[job_id] = _InFlight(future, time.monotonic(), attempt)

    def _supervise(self) -> None:
        if not self._running:
            return
        now = time.monotonic()
        with self.sessions() as session:
            rows = dict(session.execute(select(Job.id, Job.cancel_requested)
                                        .where(Job.id.in_(list(self._running)))).all())
        for job_id, run in list(self._running.items()):
            status = run.future.status
            if status == "finished":
                del self._running[job_id]
                self._after_task(job_id, None)
                continue
            if status in ("error", "cancelled", "lost"):
                del self._running[job_id]
                exc: BaseException | None = None
                if status == "error":
                    try:
                        exc = run.future.exception(timeout=5)
                    except Exception as e:  # noqa: BLE001
                        exc = e
                if status != "error" or _is_worker_loss(exc):
                    self._worker_lost(job_id, run, exc)
                else:
                    self._after_task(job_id, f"the Dask task failed: {type(exc).__name__}: {exc}")
                continue
            if rows.get(job_id) and run.cancel_seen_at is None:
                run.cancel_seen_at = now
            if run.cancel_seen_at is not None and now - run.cancel_seen_at > CANCEL_GRACE_S:
                del self._running[job_id]
                run.future.cancel()
                self._end(job_id, "cancelled", None)
            elif now - run.started > self.settings.job_timeout_s:
                del self._running[job_id]
                run.future.cancel()
                self._end(job_id, "failed", f"timed out after {self.settings.job_timeout_s} s", cancel_task=True)

    def _worker_lost(self, job_id: str, run: _InFlight, exc: BaseException | None) -> None:
        why = f"{type(exc).__name__}: {exc}" if exc is not None else "the task was lost by the cluster"
        if run.attempt <= self.settings.dask_retries:
            with self.sessions.begin() as session:
                still = session.execute(
                    update(Job).where(Job.id == job_id, Job.status == "running", Job.cancel_requested.is_(False))
                    .values(stage=f"retrying after worker loss (attempt {run.attempt + 1})", progress=0.0,
                            heartbeat_at=utcnow()))
            if still.rowcount:  # type: ignore[attr-defined]
                log.warning("job %s: Dask worker lost (%s); submitting again", job_id, why)
                ArtifactStore(self.settings.artifacts_url).remove_job(job_id)
                try:
                    self._submit(job_id, run.attempt + 1)
                    return
                except Exception as exc:  # noqa: BLE001 - e.g. the scheduler is gone too
                    why += f"; submitting again failed: {exc}"
        self._end(job_id, "failed", f"the Dask worker running the job died ({run.attempt} attempt"
                                    f"{'s' if run.attempt > 1 else ''}; last: {why})")

    def _after_task(self, job_id: str, reason: str | None) -> None:
        """The task returned (or raised): if the job is not final yet, fail it with the reason."""
        self._end(job_id, "failed", reason or "the Dask task ended without finishing the job")

    def _end(self, job_id: str, state: str, reason: str | None, cancel_task: bool = False) -> None:
        with self.sessions.begin() as session:
            values: dict[str, Any] = {"stage": state}
            if reason is not None and state == "failed":
                values["error"] = reason
            if cancel_task:  # a task still running stops at its next progress report
                values["cancel_requested"] = True
            ended = jobstore.set_status(session, job_id, state, allowed_from=("running",), **values)
        if ended:
            ArtifactStore(self.settings.artifacts_url).remove_job(job_id)
