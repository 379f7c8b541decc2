"""Report sections a job type may contribute (the optional ``JobType.report_sections`` hook).

The generic report already shows every job's inputs, parameters, summary (scalars, per-axis vectors,
statistics, record lists), specification checks, stored figures and tables. A job type adds what only
it knows, e.g. the paper's figure with an explanation or a per-axis table in the paper's layout::

    def report_sections(ctx: ReportContext) -> list[ReportSection]:
        sigma = ctx.summary["sigma_arcsec"]
        return [ReportSection(
            title="Accuracy per sensor axis (003 §1.4, table 2)",
            paragraphs=("Residuals of the sine-series fit ...",),
            tables=(ReportTable(columns=("axis", "sigma [arcsec]"), rows=tuple(zip("xyz", sigma))),),
            figure_names=("residuals",),          # stored figures (``JobType.figures``) shown here
            figures={"spectrum": draw(ctx.table("residuals"))},  # or drawn at report time
        )]

Sections hold data, never HTML: the renderer escapes all text. Drawing at report time must be fast
(the report is rendered on every request); prefer figures stored by the job.
"""

from __future__ import annotations

import io
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow.parquet as pq
from numpy.typing import NDArray

from app.reports.specs import Specifications

if TYPE_CHECKING:  # matplotlib is imported by the job types, not at start-up
    from matplotlib.figure import Figure

log = logging.getLogger("attitude.reports")


@dataclass(frozen=True)
class ReportTable:
    columns: Sequence[str]
    rows: Sequence[Sequence[Any]]
    title: str = ""
    caption: str = ""


@dataclass(frozen=True)
class ReportSection:
    title: str
    paragraphs: Sequence[str] = ()
    tables: Sequence[ReportTable] = ()
    figure_names: Sequence[str] = ()  # stored figure artifacts (without ".png") to show in this section
    figures: Mapping[str, Figure] = field(default_factory=dict)  # drawn at report time


@dataclass(frozen=True)
class ReportContext:
    """What a section hook may read: the stored summary, the job's parameters, its configuration."""

    job_type: str
    summary: Mapping[str, Any]
    params: Any  # the job type's parameter model (validated), or the raw dict if it no longer validates
    config: Mapping[str, Any]
    specifications: Specifications | None
    load_table: Callable[[str], bytes | None] = field(default=lambda name: None, repr=False)

    def table(self, name: str) -> dict[str, NDArray[Any]] | None:
        """A table the job stored (``<name>.parquet``) as columns, or None if it has none by that name."""
        raw = self.load_table(name)
        if raw is None:
            return None
        table = pq.read_table(io.BytesIO(raw))
        return {c: table.column(c).to_numpy(zero_copy_only=False) for c in table.column_names}


SectionHook = Callable[[ReportContext], Sequence[ReportSection]]


def contributed_sections(job_type: Any, ctx: ReportContext) -> tuple[list[ReportSection], list[str]]:
    """The sections of ``job_type.report_sections`` (if it has the hook) and the problems met.

    A failing hook must not cost the user the whole report: its error is shown in place of its sections.
    """
    hook: SectionHook | None = getattr(job_type, "report_sections", None)
    if hook is None:
        return [], []
    try:
        sections = list(hook(ctx))
    except Exception as exc:  # noqa: BLE001 - the rest of the report still renders
        log.exception("report sections of %s failed", ctx.job_type)
        return [], [f"the {ctx.job_type} report sections could not be drawn: {type(exc).__name__}: {exc}"]
    bad = [s for s in sections if not isinstance(s, ReportSection)]
    if bad:
        return [s for s in sections if isinstance(s, ReportSection)], [
            f"{ctx.job_type}.report_sections returned {len(bad)} objects that are not ReportSection"]
    return sections, []


def as_cell(value: Any) -> str:
    """Text of one table cell: floats to 6 significant digits, None as a dash."""
    if value is None:
        return "—"
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value)).lower()
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.6g}"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return str(value)
