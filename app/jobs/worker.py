"""Entry point of a job's worker process (local executor)."""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import sys

from app.jobs import runner
from app.settings import Settings

PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with_parent(service_pid: int) -> None:
    """Have the kernel SIGKILL this process when its parent dies (Linux; elsewhere nothing).

    The parent is the executor's forkserver, which exits as soon as the service does (its pipe to the
    service closes), so a SIGKILLed service takes its running jobs with it; they end failed by their
    stopped heartbeat at the next start-up instead of running on beside a new service."""
    if not sys.platform.startswith("linux"):
        return
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) != 0:
        logging.getLogger("attitude").warning("prctl(PR_SET_PDEATHSIG) failed: errno %d", ctypes.get_errno())
        return
    try:  # the service died before the signal was armed
        os.kill(service_pid, 0)
    except ProcessLookupError:
        os._exit(1)


def run(job_id: str, settings: Settings, service_pid: int) -> None:
    die_with_parent(service_pid)
    import matplotlib  # already imported (and set to Agg) by the forkserver's app.jobs.preload

    matplotlib.use("Agg")
    logging.basicConfig(level=logging.INFO, format=f"%(asctime)s job {job_id} pid {os.getpid()} %(message)s")
    runner.execute(job_id, settings)
