"""Job types: name -> (parameters model, streams needed, pure task, figures).

Each job type lives in ``app/jobs/types/<name>.py`` and exposes ``JOB = JobType(...)``; the task it
wraps is a pure function in ``processing/``. Add new modules to ``_MODULES``.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel

from processing.tasks import Progress, TaskInputs, TaskResult

if TYPE_CHECKING:  # the job types import matplotlib when the registry is first read, not at start-up
    from matplotlib.figure import Figure

    from app.reports.headline import Answer


def no_figures(result: TaskResult, params: Any) -> dict[str, Figure]:
    """``JobType.figures`` of a job type that draws none."""
    return {}


@dataclass(frozen=True)
class JobType:
    name: str
    title: str
    paper: str  # e.g. "003 §1" or "" for service jobs
    params: type[BaseModel]
    run: Callable[[TaskInputs, Any, Progress], TaskResult]
    streams: tuple[str, ...] = ()  # all must have samples in the window (checked at submission)
    optional_streams: tuple[str, ...] = ()
    any_stream: bool = False  # True: load every stream; at least one must have samples
    # the streams a run with these (validated) params reads, where its params leave some of the above unused
    # (e.g. star_tracker_accuracy with use_gyro = false): the runner loads only those (required ones always);
    # None: every stream above
    input_streams: Callable[[Any], Collection[str]] | None = None
    figures: Callable[[TaskResult, Any], dict[str, Figure]] = no_figures
    # the names ``figures`` gives for a result with this summary and tables (table name -> row count), told
    # without drawing: lazy figures are recorded by name at job end (app.jobs.figures); None: known once drawn.
    # Declared beside ``figures``; tests/app/test_lazy_figures.py checks the two agree for every job type.
    figure_names: Callable[[Mapping[str, Any], Mapping[str, int]], list[str] | None] | None = None
    description: str = ""
    reference: tuple[str, ...] = ()  # reference kinds the task can use (each optional)
    produces_calibration: str | None = None  # on success with summary["calibration_complete"]: a new version
    applies_calibration: str | None = None  # the runner applies the pinned version ("gyro", "magnetometer")
    # extra report sections (app.reports.sections: ReportContext -> sequence of ReportSection)
    report_sections: Callable[[Any], Sequence[Any]] | None = None
    # the summary keys that answer the job's question, shown first in its report (app.reports.headline);
    # None: the generic rule (the quantities the specification judges, then numbers with a unit suffix)
    headline: tuple[Answer, ...] | None = None
    # the summary's declared schema (the OpenAPI ``<Type>Summary``; a test checks it on simulated runs);
    # None: the one in app/jobs/results.py for this name, else the generic one (warnings typed)
    result_model: type[BaseModel] | None = None

    def names_of_figures(self, summary: Mapping[str, Any], rows: Mapping[str, int]) -> list[str] | None:
        """The names ``figures`` gives for this summary and tables, without drawing: ``figure_names``'s answer;
        none for a job type without figures; None when ``figure_names`` is not declared."""
        if self.figure_names is not None:
            return self.figure_names(summary, rows)
        return [] if self.figures is no_figures else None


def always(*names: str) -> Callable[[Mapping[str, Any], Mapping[str, int]], list[str]]:
    """``JobType.figure_names`` of a job type whose ``figures`` always gives these figures."""
    return lambda summary, rows: list(names)


_MODULES = ("coverage", "executor_check", "star_tracker_accuracy", "gyro_bias_fit", "orbital_attitude", "gyroless_ekf",
            "alignment_calibration", "data_screening", "vector_attitude", "reconstruction", "definitive_attitude",
            "gyro_noise", "magnetometer_calibration")


def registry() -> dict[str, JobType]:
    jobs = {}
    for module in _MODULES:
        job: JobType = importlib.import_module(f"app.jobs.types.{module}").JOB
        jobs[job.name] = job
    return jobs
