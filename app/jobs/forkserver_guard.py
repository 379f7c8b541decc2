"""Imported first by the local executor's forkserver: the forkserver dies with the service (app.jobs.lifetime)."""

import os

from app.jobs.lifetime import SERVICE_PID_VARIABLE, die_with_parent

die_with_parent(int(os.environ.get(SERVICE_PID_VARIABLE) or os.getppid()))
