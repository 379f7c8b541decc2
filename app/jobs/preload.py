"""Imported by the local executor's forkserver, never by the service itself: every job type (and with
them matplotlib, scipy and the processing modules) is imported once there, so each job process forked
from it starts without imports, while the service starts without them."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

from app.jobs.registry import registry  # noqa: E402 - after choosing the backend

registry()
