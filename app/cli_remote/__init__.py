"""Command-line client of a running service: ``attitude spacecraft ...``, ``attitude upload``,
``attitude telemetry get``, ``attitude jobs ...``, ``attitude schedules ...``, ``attitude reference ...``.

Every command talks HTTP to ``--url`` (or ``ATTITUDE_URL``, default http://127.0.0.1:8000) with the API key
``--token`` (or ``ATTITUDE_TOKEN``) through :class:`app.client.Client`. Ids may be given as unique prefixes
(the 8 characters shown). Long uploads and jobs show a progress bar on stderr (a plain line every 10 % when
stderr is not a terminal); results go to stdout, as text or with ``--json`` as JSON. Errors go to stderr, every
row/column error of an upload listed (``--json``: the service's whole answer on stdout too).
Exit codes: 0 success, 1 a job that failed or was cancelled, 2 usage, connection or HTTP errors.

Layout: one module per command group (upload.py, jobs.py, spacecraft.py, telemetry.py, reference.py,
schedules.py), the shared options and output in common.py, the error handling in errors.py.
"""

from __future__ import annotations

from typing import Any

from app.cli_remote.common import DEFAULT_URL, ProgressBar, UsageError, _remote_parent
from app.cli_remote.errors import run_remote
from app.cli_remote.jobs import _job_outcome, add_jobs_commands
from app.cli_remote.reference import add_reference_commands
from app.cli_remote.schedules import add_schedules_commands
from app.cli_remote.spacecraft import add_spacecraft_commands
from app.cli_remote.telemetry import add_telemetry_commands
from app.cli_remote.upload import add_upload_commands

__all__ = ["DEFAULT_URL", "ProgressBar", "UsageError", "_job_outcome", "add_remote_commands", "run_remote"]


def add_remote_commands(sub: Any) -> None:
    """Register upload, jobs, schedules, spacecraft, telemetry and reference on the ``attitude`` parser."""
    parent = _remote_parent()
    add_upload_commands(sub, parent)
    add_jobs_commands(sub, parent)
    add_spacecraft_commands(sub, parent)
    add_telemetry_commands(sub, parent)
    add_reference_commands(sub, parent)
    add_schedules_commands(sub, parent)
