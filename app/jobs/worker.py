"""Entry point of a job's worker process (local executor)."""

from __future__ import annotations

import logging
import os

import matplotlib

from app.jobs import registry as _registry  # noqa: F401 - preloaded by the forkserver
from app.jobs import runner
from app.settings import Settings

matplotlib.use("Agg")
_registry.registry()  # the forkserver preloads every job type once, so each job starts without imports


def run(job_id: str, settings: Settings) -> None:
    logging.basicConfig(level=logging.INFO, format=f"%(asctime)s job {job_id} pid {os.getpid()} %(message)s")
    runner.execute(job_id, settings)
