"""Dask worker plugin of the Dask executor (app.jobs.dask_executor registers it when it connects)."""

from __future__ import annotations

from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin


class WarmUp(WorkerPlugin):
    """A worker imports the job types (numpy, scipy, matplotlib, the algorithms: ~6 CPU s) when it joins the
    cluster or when the service connects, not inside the first job it runs - nor inside the pipeline branch a
    job sends to it (app.jobs.partitions.map_concurrent)."""

    name = "attitude-warm-up"

    def setup(self, worker: Any) -> None:
        from app.jobs.registry import registry

        registry()
