"""What every executor shares: the catalog is the queue, a dispatcher thread claims and supervises.

One loop, the same for the local executor (a child process per job) and the Dask executor (a task per
job): each iteration supervises the jobs in flight, claims queued jobs up to the free capacity with
the conditional UPDATE of :func:`storage.jobs.claim` (so several service instances never run one job
twice), launches each claimed job, and every ``heartbeat_timeout_s / 4`` sends heartbeats for the
jobs in flight and fails running jobs whose heartbeat stopped (their service or worker died). At
start-up, jobs left running by a service that stopped are failed.

Subclasses say how a claimed job is launched (:meth:`_launch`), how the jobs in flight are
supervised (:meth:`_supervise`), how many may be in flight (:meth:`capacity`) and what becomes of a
job still in flight when the service stops (:meth:`_abandon`).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Generic, TypeVar

from sqlalchemy.orm import Session, sessionmaker

from app.settings import Settings
from storage import jobs as jobstore

log = logging.getLogger("attitude.executor")

InFlight = TypeVar("InFlight")

CANCEL_GRACE_S = 3.0
"""A job whose cancel was requested gets this long to stop by itself before the executor stops it."""


class CatalogDispatcher(Generic[InFlight]):
    """Claims catalog-queued jobs and keeps them supervised; ``_running`` maps job id -> in-flight state."""

    thread_name = "job-dispatcher"

    def __init__(self, settings: Settings, sessions: sessionmaker[Session], poll_s: float) -> None:
        self.settings = settings
        self.sessions = sessions
        self.poll_s = poll_s
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._running: dict[str, InFlight] = {}
        self._thread: threading.Thread | None = None
        self._last_reap = 0.0

    def start(self) -> None:
        self._connect()
        with self.sessions.begin() as session:
            failed = jobstore.fail_stale(session, self.settings.heartbeat_timeout_s,
                                         "the service stopped while the job was running")
        if failed:
            log.warning("marked %d interrupted jobs as failed", len(failed))
        self._thread = threading.Thread(target=self._loop, name=self.thread_name, daemon=True)
        self._thread.start()

    def wake(self) -> None:
        self._wake.set()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=30)
        for job_id, run in list(self._running.items()):
            self._abandon(job_id, run)
        self._running.clear()
        self._disconnect()

    # -- the loop ---------------------------------------------------------------------------------
    def _loop(self) -> None:
        while not self._stop.is_set():
            try:
                self._tick()
            except Exception:  # noqa: BLE001 - the dispatcher must survive a database or network hiccup
                log.exception("%s iteration failed", self.thread_name)
            self._wake.wait(self.poll_s)
            self._wake.clear()

    def _tick(self) -> None:
        self._supervise()
        free = self.capacity() - len(self._running)
        if free > 0:
            with self.sessions() as session:
                candidates = jobstore.fair_queued_ids(session, free, self.settings.jobs_per_key)
            for job_id in candidates:
                with self.sessions.begin() as session:
                    claimed = jobstore.claim(session, job_id)
                if claimed:
                    self._launch(job_id)
        now = time.monotonic()
        if now - self._last_reap > max(1.0, self.settings.heartbeat_timeout_s / 4):
            self._last_reap = now
            with self.sessions.begin() as session:
                jobstore.heartbeat(session, list(self._running))
                jobstore.fail_stale(session, self.settings.heartbeat_timeout_s,
                                    "the job's worker stopped sending heartbeats (service or worker died)")

    # -- what an executor provides ----------------------------------------------------------------
    def capacity(self) -> int:
        """Jobs kept in flight at once."""
        return self.settings.max_jobs

    def _connect(self) -> None:
        """Before the first claim (e.g. connect to a cluster); raise if the executor cannot work."""

    def _disconnect(self) -> None:
        """After the last job in flight was abandoned."""

    def _launch(self, job_id: str) -> None:
        """Run the claimed (now 'running') job and record it in ``_running``, or bring it to a final state."""
        raise NotImplementedError

    def _supervise(self) -> None:
        """Finish, cancel or time out the jobs in ``_running`` (remove the ones that ended)."""
        raise NotImplementedError

    def _abandon(self, job_id: str, run: InFlight) -> None:
        """The service stops while the job runs: stop it and give it a final state."""
        raise NotImplementedError
