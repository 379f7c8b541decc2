"""Entry point of a job's worker process (local executor)."""

from __future__ import annotations

import logging
import os

from app.jobs import runner
from app.jobs.lifetime import die_with_parent
from app.settings import Settings


def run(job_id: str, settings: Settings, service_pid: int) -> None:
    die_with_parent(service_pid)  # the parent is the forkserver, which dies with the service
    import matplotlib  # already imported (and set to Agg) by the forkserver's app.jobs.preload

    matplotlib.use("Agg")
    logging.basicConfig(level=logging.INFO, format=f"%(asctime)s job {job_id} pid {os.getpid()} %(message)s")
    runner.execute(job_id, settings)
