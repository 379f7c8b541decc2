"""Job ``executor_check``: a diagnostic that exercises the job machinery without telemetry.

Operators use it to check that workers run, report progress, can be cancelled, and that failures
come back with their reason (``fail``), including a worker that dies (``crash``), and that result
warnings reach the reports, the UI and the CLI (``warning``).
"""

from __future__ import annotations

import os
import time
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from app.jobs.registry import JobType
from processing.tasks import WARNING_CODES, Progress, ResultWarning, TaskError, TaskInputs, TaskResult


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    duration_s: float = Field(0.0, ge=0.0, le=600.0, description="how long to run, reporting progress")
    fail: bool = Field(False, description="end with a task error")
    crash: bool = Field(False, description="terminate the worker process abruptly")
    warning: Literal[tuple(WARNING_CODES)] | None = Field(  # type: ignore[valid-type]
        None, description="end with this result warning (exercises how warnings reach reports, UI and CLI)")


def run(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    t0 = time.monotonic()
    while (elapsed := time.monotonic() - t0) < params.duration_s:
        progress(elapsed / params.duration_s, "waiting")
        time.sleep(min(0.05, params.duration_s))
    if params.crash:
        os._exit(3)
    if params.fail:
        raise TaskError("executor_check was asked to fail")
    warnings = [ResultWarning(params.warning, f"executor_check was asked to warn {params.warning}",
                              {"requested": True})] if params.warning else []
    return TaskResult(summary={"duration_s": params.duration_s, "worker_pid": os.getpid()}, warnings=warnings)


JOB = JobType(name="executor_check", title="Executor check", paper="", params=Params, run=run,
              description="Diagnostic job: runs for duration_s with progress; optionally fails or crashes.")
