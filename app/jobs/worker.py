"""Entry point of a job's worker process (local executor)."""

from __future__ import annotations

import logging
import os

from app.jobs import runner
from app.settings import Settings


def run(job_id: str, settings: Settings) -> None:
    import matplotlib  # already imported (and set to Agg) by the forkserver's app.jobs.preload

    matplotlib.use("Agg")
    logging.basicConfig(level=logging.INFO, format=f"%(asctime)s job {job_id} pid {os.getpid()} %(message)s")
    runner.execute(job_id, settings)
