"""Local executor: each job runs in a child process, at most ``max_jobs`` at a time.

The catalog is the queue: a dispatcher thread claims queued jobs (conditional UPDATE, so several
service processes never run one job twice), starts a process per job and supervises it:
heartbeats while it lives, a kill on cancel (after a grace period for the cooperative cancel) or on
timeout, and a 'failed' state with the exit code if the process dies without finishing the job.
Running jobs whose heartbeat stopped (their service died) are failed by the periodic reaper.
"""

from __future__ import annotations

import multiprocessing as mp
import multiprocessing.forkserver
import os
import time
from dataclasses import dataclass, field
from multiprocessing.process import BaseProcess

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from app.jobs import worker
from app.jobs.dispatch import CANCEL_GRACE_S, CatalogDispatcher
from app.jobs.lifetime import SERVICE_PID_VARIABLE
from app.settings import Settings
from storage import jobs as jobstore
from storage.jobs import ArtifactStore
from storage.models import Job

FORKSERVER_PRELOAD = ["app.jobs.forkserver_guard", "app.jobs.worker", "app.jobs.preload"]


def start_forkserver() -> None:
    """Start the job processes' forkserver now, from the calling thread (no-op while one is running).

    The forkserver imports every job type (several seconds of CPU) while the service goes on. Linux's
    parent-death signal (app.jobs.lifetime) follows the *thread* that started the forkserver: the service
    calls this from the thread that runs its lifespan, and a host that runs several services in one
    process (the test suite) from its main thread, so that one forkserver serves them all.
    """
    # One BLAS thread per job process: jobs already run side by side (max_jobs), and oversubscribed
    # OpenBLAS threads made small QR factorisations 5-10x slower on a busy 2-core machine.
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ[SERVICE_PID_VARIABLE] = str(os.getpid())  # the forkserver dies with this process
    mp.get_context("forkserver").set_forkserver_preload(FORKSERVER_PRELOAD)
    multiprocessing.forkserver.ensure_running()


@dataclass
class _Running:
    process: BaseProcess
    started: float
    cancel_seen_at: float | None = None
    killed_reason: str | None = field(default=None)


class LocalExecutor(CatalogDispatcher[_Running]):
    def __init__(self, settings: Settings, sessions: sessionmaker[Session], poll_s: float = 0.25) -> None:
        super().__init__(settings, sessions, poll_s)
        self._ctx = mp.get_context("forkserver")

    def _connect(self) -> None:
        start_forkserver()  # preloading while the service starts; a running forkserver is kept

    def _launch(self, job_id: str) -> None:
        proc = self._ctx.Process(target=worker.run, args=(job_id, self.settings, os.getpid()), name=f"job-{job_id}",
                                 daemon=False)
        try:
            proc.start()
        except Exception as exc:  # noqa: BLE001
            with self.sessions.begin() as session:
                jobstore.set_status(session, job_id, "failed", allowed_from=("running",),
                                    stage="failed", error=f"could not start a worker process: {exc}")
            return
        self._running[job_id] = _Running(proc, time.monotonic())

    def _abandon(self, job_id: str, run: _Running) -> None:
        run.process.kill()
        run.process.join(5)
        self._after_exit(job_id, run, "the service shut down while the job was running")

    def _supervise(self) -> None:
        if not self._running:
            return
        now = time.monotonic()
        with self.sessions() as session:
            rows = dict(session.execute(select(Job.id, Job.cancel_requested)
                                        .where(Job.id.in_(list(self._running)))).all())
        for job_id, run in list(self._running.items()):
            if not run.process.is_alive():
                run.process.join()
                del self._running[job_id]
                self._after_exit(job_id, run, None)
                continue
            if rows.get(job_id) and run.cancel_seen_at is None:
                run.cancel_seen_at = now
            if run.cancel_seen_at is not None and now - run.cancel_seen_at > CANCEL_GRACE_S:
                run.killed_reason = "cancelled"
                run.process.kill()
            elif now - run.started > self.settings.job_timeout_s:
                run.killed_reason = f"timed out after {self.settings.job_timeout_s} s"
                run.process.kill()

    def _after_exit(self, job_id: str, run: _Running, reason: str | None) -> None:
        """The process is gone: if it did not bring the job to a final state, do it here."""
        with self.sessions.begin() as session:
            if run.killed_reason == "cancelled":
                ended = jobstore.set_status(session, job_id, "cancelled", allowed_from=("running",),
                                            stage="cancelled")
            else:
                why = reason or run.killed_reason or (
                    f"the worker process exited with code {run.process.exitcode} without finishing the job")
                ended = jobstore.set_status(session, job_id, "failed", allowed_from=("running",),
                                            stage="failed", error=why)
        if ended:  # partial artifacts of a job that did not finish are of no use
            ArtifactStore(self.settings.artifacts_url).remove_job(job_id)
