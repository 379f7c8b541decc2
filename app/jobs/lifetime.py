"""Job processes die with the service that started them (Linux: the parent-death signal).

The local executor starts a forkserver (a child of the service) that forks one process per job. When the
service is killed, both must go too: otherwise jobs would run on beside a restarted service, which marks
them failed by their stopped heartbeat, and a forkserver still importing its preload modules would not
notice the death of its parent until it finished. The forkserver imports :mod:`app.jobs.forkserver_guard`
first, which arms the signal against the service; each job process arms it against the forkserver.
"""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import sys

PR_SET_PDEATHSIG = 1  # linux/prctl.h


SERVICE_PID_VARIABLE = "ATTITUDE_SERVICE_PID"
"""Set by the executor before it starts the forkserver, which inherits it: the pid it must die with."""


def die_with_parent(service_pid: int) -> None:
    """SIGKILL this process when its parent dies; exit at once if that already happened.

    ``service_pid``: the service this process belongs to. After arming, the process exits when its parent
    changed meanwhile (it was reparented: the parent died first) or the service is gone. Elsewhere than
    Linux nothing is armed (the executor still ends the jobs it supervises)."""
    if not sys.platform.startswith("linux"):
        return
    parent = os.getppid()
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) != 0:
        logging.getLogger("attitude").warning("prctl(PR_SET_PDEATHSIG) failed: errno %d", ctypes.get_errno())
        return
    try:
        os.kill(service_pid, 0)
    except ProcessLookupError:
        os._exit(1)
    if os.getppid() != parent:
        os._exit(1)
