"""A job's figures drawn from its stored artifacts, on first request (issue 24: "figures rendered once, lazily").

With ``ATTITUDE_FIGURES=lazy`` (the default) a job stores its summary, tables and files and draws no figure; it
records only the figure *names* (:func:`figure_names`: the names each job type declares beside its ``figures()``,
``JobType.figure_names``, told from the summary and the tables' row counts without drawing). A figure is drawn
when it is first asked for: the job
type's ``figures()`` runs on the result read back from the stored artifacts (:func:`stored_result`), the figure
is rendered exactly as the job would have rendered it (:func:`app.jobs.outputs.figure_png`) and stored as the
artifact ``<name>.png`` (app.services.figures), so it is rendered once.

Read back, a table has the columns the job gave it: the ISO ``time`` column that
:func:`app.jobs.outputs.table_to_arrow` put in front of ``time_tai_ns`` is dropped, text columns come back as
object arrays of ``str`` (as the runner hands telemetry to tasks), numbers and booleans as numpy arrays of
their stored type. A table shortened by the output bounds (``summary.outputs.truncated``) is drawn from its
stored rows; one left out (``omitted``) is missing, and a figure that needs it cannot be drawn.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
import pyarrow as pa

from app.jobs.outputs import table_columns
from processing.tasks import TaskResult

if TYPE_CHECKING:
    from app.jobs.registry import JobType

def figure_names(job_type: JobType, summary: Mapping[str, Any], rows: Mapping[str, int]) -> list[str] | None:
    """The names of the figures ``job_type.figures`` draws for a result with this summary and tables (``rows``:
    table name -> row count), without drawing (``JobType.names_of_figures``); None when the job type does not
    declare them (its figures are then listed once drawn)."""
    return job_type.names_of_figures(summary, rows)


def table_rows(tables: Mapping[str, Mapping[str, Any]]) -> dict[str, int]:
    """Table name -> row count of a result's in-memory tables."""
    return {name: (len(next(iter(cols.values()))) if cols else 0) for name, cols in tables.items()}


def columns_from_arrow(table: pa.Table) -> dict[str, np.ndarray]:
    """A stored result table as the columns the job gave it (see the module docstring)."""
    names = table.column_names
    if "time_tai_ns" in names and names[0] == "time" and pa.types.is_string(table.schema.field("time").type):
        table = table.drop_columns(["time"])  # added by table_to_arrow for display, not a column of the job
    return table_columns(table)


V = TypeVar("V")


class Lazy(Mapping[str, V]):
    """A mapping whose values are loaded on first access (a stored table read only when a figure asks for it)."""

    def __init__(self, keys: list[str], load: Callable[[str], V]) -> None:
        self._keys = list(dict.fromkeys(keys))
        self._load = load
        self._cache: dict[str, V] = {}

    def __getitem__(self, key: str) -> V:
        if key not in self._cache:
            if key not in self._keys:
                raise MissingData(key)
            self._cache[key] = self._load(key)
        return self._cache[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._keys)

    def __len__(self) -> int:
        return len(self._keys)

    def __contains__(self, key: object) -> bool:
        return key in self._keys


class MissingData(KeyError):
    """A figure asked for a table (or file) the job did not store."""


def stored_result(summary: dict[str, Any], tables: Mapping[str, Callable[[], pa.Table]],
                  files: Mapping[str, tuple[Callable[[], bytes], str]]) -> TaskResult:
    """The TaskResult a job's figures are drawn from, rebuilt from its stored summary, tables (name -> reader of
    the stored Arrow table) and files (name -> (reader of the bytes, media type)); read lazily."""
    table_map: Lazy[dict[str, np.ndarray]] = Lazy(list(tables), lambda k: columns_from_arrow(tables[k]()))
    file_map: Lazy[tuple[bytes, str]] = Lazy(list(files), lambda k: (files[k][0](), files[k][1]))
    return TaskResult(summary=summary, tables=table_map, files=file_map)  # type: ignore[arg-type]


def draw(job_type: JobType, result: TaskResult, params: Any, wanted: set[str] | None,
         ) -> tuple[dict[str, tuple[bytes, str]], list[str]]:
    """Run the job type's ``figures()`` and render the ``wanted`` ones (None: all): name -> (PNG, title), and
    the names ``figures()`` gave."""
    from app.jobs.outputs import figure_png

    figs = job_type.figures(result, params)
    out = {name: (figure_png(fig), str(fig.get_label() or name)) for name, fig in figs.items()
           if wanted is None or name in wanted}
    return out, list(figs)
