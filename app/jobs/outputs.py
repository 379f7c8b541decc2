"""Turn a TaskResult into stored artifacts: tables (Parquet; CSV too when short), figures (PNG), summary (JSON).

Bounded per job (issue 24): a table longer than :data:`CSV_STORED_MAX_ROWS` is stored as Parquet only, its CSV
made on request from the Parquet (:func:`csv_chunks`, streamed by the artifact download route for the
``<table>.csv`` name); a table is stored with at most :data:`TABLE_MAX_ROWS` rows; the artifacts of one job stay
within :data:`JOB_ARTIFACT_MAX_BYTES` (a table, file or figure that would go beyond is left out). What was
done is stated in the summary's ``outputs`` and in a note. Figures (stored here only with
``ATTITUDE_FIGURES=eager``; by default drawn on first request, app.jobs.figures) are drawn once, with every line
of more than :data:`FIGURE_LINE_MAX_POINTS` points thinned for display first (:func:`thin_lines`: each pixel
column's first, last, lowest and highest point kept, so the picture is the same and spikes stay).
"""

from __future__ import annotations

import io
import json
import math
import os
from collections import deque
from collections.abc import Iterable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
from numpy.typing import NDArray

from processing.tasks import TaskResult
from processing.time import timescales
from storage.jobs import ArtifactStore, StoredArtifact

CSV_STORED_MAX_ROWS = 50_000
"""Tables of up to this many rows are stored as CSV too; longer ones as Parquet only (CSV on request)."""
TABLE_MAX_ROWS = 5_000_000
"""A table is stored with at most this many rows (its first ones); ``outputs.truncated`` names it."""
JOB_ARTIFACT_MAX_BYTES = 256 * 2**20
"""The artifacts of one job: a table, file or figure that would go beyond this is left out (``outputs.omitted``)."""
FIGURE_LINE_MAX_POINTS = 4_000
"""Lines with more points are thinned for display (about 2 points per pixel column of a 9-inch, 110-dpi figure)."""
FIGURE_MARKERS_MAX_POINTS = 20_000
"""Marker-only lines (scatter) with more points keep a regular subsample plus every column's extremes."""
CSV_BATCH_ROWS = 65_536
ENCODE_THREADS = 2
"""Tables encoded (Arrow, Parquet, CSV) at the same time at job end, at most this many (and the machine's cores)."""

if TYPE_CHECKING:  # matplotlib is imported by the job types, not at start-up
    from matplotlib.figure import Figure


def jsonable(value: Any) -> Any:
    """Plain JSON types only: numpy scalars/arrays converted, non-finite floats -> None."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        return jsonable(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


FORMULA_START = "=+-@\t\r"
"""First characters that make a spreadsheet read a CSV cell as a formula (OWASP "CSV injection")."""


def csv_cell(value: Any) -> Any:
    """A text cell prefixed with ``'`` when it begins like a formula; other values as they are."""
    return "'" + value if isinstance(value, str) and value[:1] in FORMULA_START and value else value


def csv_safe(table: pa.Table) -> pa.Table:
    """The table with every text cell that begins with ``= + - @``, a tab or a carriage return prefixed with
    ``'`` (vectorised; numbers, including negative ones, are not text and stay as they are)."""
    columns = []
    for field, column in zip(table.schema, table.columns, strict=True):
        kind = field.type.value_type if pa.types.is_dictionary(field.type) else field.type
        if pa.types.is_string(kind) or pa.types.is_large_string(kind):
            text = pc.cast(column, pa.large_string())
            risky = pc.match_substring_regex(text, "^[=+\\-@\t\r]")
            quote = pa.scalar("'", pa.large_string())
            column = pc.if_else(risky, pc.binary_join_element_wise(quote, text, pa.scalar("", pa.large_string())), text)
        columns.append(column)
    return pa.table(columns, names=table.column_names)


def text_columns(table: pa.Table) -> list[str]:
    """The columns worth Parquet's dictionary encoding: text (sensor names, reasons, ISO times repeat); numbers
    rarely do, and trying costs more than their encoding (a spacecraft-day's tables: 0.48 -> 0.25-0.31 s, smaller)."""
    return [f.name for f in table.schema if pa.types.is_string(f.type) or pa.types.is_large_string(f.type)]


def table_to_arrow(columns: dict[str, Any]) -> pa.Table:
    """Columns -> Arrow; a ``time_tai_ns`` column gets an ISO UTC ``time`` column in front of it."""
    arrays: dict[str, Any] = {}
    if "time_tai_ns" in columns:
        arrays["time"] = iso_column(np.asarray(columns["time_tai_ns"], np.int64))
    for name, values in columns.items():
        arr = np.asarray(values)
        arrays[name] = pa.array(arr)  # object arrays (text) converted by Arrow directly, not via a list
    return pa.table(arrays)


class _Budget:
    """What one job may still store (JOB_ARTIFACT_MAX_BYTES) and what was left out or shortened."""

    def __init__(self, limit: int) -> None:
        self.left = limit
        self.outputs: dict[str, Any] = {"parquet_only": [], "truncated": {}, "omitted": []}

    def take(self, name: str, size: int) -> bool:
        if size > self.left:
            self.outputs["omitted"].append(name)
            return False
        self.left -= size
        return True


def table_columns(table: pa.Table) -> dict[str, np.ndarray]:
    """A stored table's columns as numpy arrays (a window's telemetry, a job's result table); text columns (the
    sensor names) as object arrays holding one str per distinct value, not one per row (a day of 10 Hz gyro:
    8 bytes a row instead of ~60)."""
    out: dict[str, np.ndarray] = {}
    for c in table.column_names:
        col = table.column(c)
        if col.null_count == 0 and (pa.types.is_string(col.type) or pa.types.is_large_string(col.type)):
            encoded = col.combine_chunks().dictionary_encode()
            values = np.array(encoded.dictionary.to_pylist(), dtype=object)
            out[c] = values[encoded.indices.to_numpy(zero_copy_only=False)]
        else:
            out[c] = col.to_numpy(zero_copy_only=False)
    return out


def iso_column(tai_ns: NDArray[np.int64]) -> pa.Array:
    """ISO UTC times as an Arrow string column, built from the character codes without a Python string per
    value (the same column as ``pa.array(timescales.tai_ns_to_iso(tai_ns))``)."""
    codes = timescales.tai_ns_to_iso_codes(tai_ns, dtype=np.uint8)
    n, width = codes.shape
    if n * width >= 2**31 - 1:  # beyond 32-bit offsets
        return pa.array(timescales.tai_ns_to_iso(tai_ns), pa.string())
    offsets = np.arange(n + 1, dtype=np.int32) * np.int32(width)
    return pa.StringArray.from_buffers(n, pa.py_buffer(offsets), pa.py_buffer(codes))


def write_outputs(store: ArtifactStore, job_id: str, result: TaskResult,
                  figures: dict[str, Figure], summary: dict[str, Any]) -> list[StoredArtifact]:
    """Store the job's tables, files, figures and summary (the summary first in the list).

    When a table is stored as Parquet only, shortened or left out (see the module's bounds), ``summary`` gets
    an ``outputs`` entry saying so (in place: the caller stores the same dict) and ``result.notes`` a note."""
    budget = _Budget(JOB_ARTIFACT_MAX_BYTES)
    out: list[StoredArtifact] = []
    # the tables encoded side by side (Arrow and Parquet release the GIL) and stored in order, so the budget
    # decides as it would one by one; at most one table more than the threads is held encoded at a time
    threads = min(ENCODE_THREADS, os.cpu_count() or 1)
    if threads == 1:  # one core (or ENCODE_THREADS = 1): here, one table at a time
        for name, columns in result.tables.items():
            out += _store_table(store, job_id, name, _encode_table(columns), budget)
    else:
        with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="encode") as pool:
            pending: deque[tuple[str, Future[_EncodedTable]]] = deque()
            for name, columns in result.tables.items():
                pending.append((name, pool.submit(_encode_table, columns)))
                if len(pending) > threads:
                    done, encoded = pending.popleft()
                    out += _store_table(store, job_id, done, encoded.result(), budget)
            while pending:
                done, encoded = pending.popleft()
                out += _store_table(store, job_id, done, encoded.result(), budget)
    for name, (content, media_type) in result.files.items():
        if budget.take(name, len(content)):
            out.append(store.write(job_id, name, content, kind="file", media_type=media_type,
                                   description=f"file {name}"))
    for name, fig in figures.items():
        png = figure_png(fig)
        if budget.take(f"{name}.png", len(png)):
            out.append(store.write(job_id, f"{name}.png", png, kind="figure", media_type="image/png",
                                   description=str(fig.get_label() or name)))
    outputs = {k: v for k, v in budget.outputs.items() if v}
    if outputs:
        outputs["limits"] = {"csv_stored_max_rows": CSV_STORED_MAX_ROWS, "table_max_rows": TABLE_MAX_ROWS,
                             "job_artifact_max_bytes": JOB_ARTIFACT_MAX_BYTES}
        summary["outputs"] = outputs
        result.notes.extend(_output_notes(outputs))
    head = store.write(job_id, "summary.json", json.dumps(summary, indent=2).encode(), kind="summary",
                       media_type="application/json", description="job summary")
    return [head, *out]


def figure_png(fig: Figure) -> bytes:
    """A figure as the stored PNG: long lines thinned for display (:func:`thin_lines`), 110 dpi, tight box. The
    one rendering of the job's figures, at job end (``ATTITUDE_FIGURES=eager``) or on request (app.jobs.figures)."""
    buf = io.BytesIO()
    thin_lines(fig)
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    return buf.getvalue()


@dataclass(frozen=True)
class _EncodedTable:
    rows: int  # before truncation
    stored_rows: int
    parquet: bytes
    csv: bytes | None  # None: longer than CSV_STORED_MAX_ROWS (Parquet only)


def _encode_table(columns: dict[str, Any]) -> _EncodedTable:
    n_rows = len(next(iter(columns.values()))) if columns else 0
    if n_rows > TABLE_MAX_ROWS:
        columns = {k: np.asarray(v)[:TABLE_MAX_ROWS] for k, v in columns.items()}
    table = table_to_arrow(columns)
    buf = io.BytesIO()
    pq.write_table(table, buf, use_dictionary=text_columns(table))
    csv = None
    if table.num_rows <= CSV_STORED_MAX_ROWS:
        text = io.BytesIO()
        pacsv.write_csv(csv_safe(table), text)
        csv = text.getvalue()
    return _EncodedTable(n_rows, table.num_rows, buf.getvalue(), csv)


def _store_table(store: ArtifactStore, job_id: str, name: str, table: _EncodedTable,
                 budget: _Budget) -> list[StoredArtifact]:
    if table.stored_rows < table.rows:
        budget.outputs["truncated"][name] = {"rows": table.rows, "stored_rows": table.stored_rows}
    if not budget.take(f"{name}.parquet", len(table.parquet)):
        return []
    out = [store.write(job_id, f"{name}.parquet", table.parquet, kind="table",
                       media_type="application/vnd.apache.parquet", description=f"table {name}")]
    if table.csv is None:
        budget.outputs["parquet_only"].append(name)
        return out
    if budget.take(f"{name}.csv", len(table.csv)):
        out.append(store.write(job_id, f"{name}.csv", table.csv, kind="table", media_type="text/csv",
                               description=f"table {name}"))
    return out


def _output_notes(outputs: dict[str, Any]) -> list[str]:
    notes = []
    if outputs.get("parquet_only"):
        notes.append(f"tables of more than {CSV_STORED_MAX_ROWS} rows stored as Parquet only (their CSV is made "
                     f"on request, <table>.csv): {', '.join(outputs['parquet_only'])}")
    for name, t in outputs.get("truncated", {}).items():
        notes.append(f"table {name} truncated to its first {t['stored_rows']} of {t['rows']} rows")
    if outputs.get("omitted"):
        notes.append(f"left out to keep the job's artifacts within {JOB_ARTIFACT_MAX_BYTES // 2**20} MiB: "
                     f"{', '.join(outputs['omitted'])}")
    return notes


def csv_text(tables: Iterable[pa.Table], empty: pa.Schema | None = None) -> Iterator[bytes]:
    """Consecutive tables as one CSV (text cells made spreadsheet-safe), a piece per table: the header once,
    then the rows. No table at all: the header of ``empty`` alone (nothing when None)."""
    first = True
    for table in tables:
        buf = io.BytesIO()
        pacsv.write_csv(csv_safe(table), buf, write_options=pacsv.WriteOptions(include_header=first))
        first = False
        yield buf.getvalue()
    if first and empty is not None:
        yield from csv_text([empty.empty_table()])


def csv_chunks(path: Path) -> Iterator[bytes]:
    """A stored Parquet table as CSV in chunks of CSV_BATCH_ROWS rows: memory bounded by one batch."""
    pf = pq.ParquetFile(path)
    return csv_text((pa.Table.from_batches([b]) for b in pf.iter_batches(batch_size=CSV_BATCH_ROWS)),
                    pf.schema_arrow)


def thin_lines(fig: Figure, max_points: int = FIGURE_LINE_MAX_POINTS,
               max_markers: int = FIGURE_MARKERS_MAX_POINTS) -> None:
    """Thin, in place, the long lines of a figure for display (see :func:`display_indices`); lines whose data
    are not plain numbers, or connected lines whose x is not sorted, are left as they are."""
    for ax in fig.axes:
        log_x = ax.get_xscale() == "log"
        for line in ax.get_lines():
            x = np.asarray(line.get_xdata(orig=True))
            y = np.asarray(line.get_ydata(orig=True))
            connected = line.get_linestyle() not in ("None", "none", "", " ")
            bound = max_points if connected else max_markers
            if x.ndim != 1 or x.shape != y.shape or x.size <= bound:
                continue
            if not (np.issubdtype(x.dtype, np.number) and np.issubdtype(y.dtype, np.number)):
                continue
            keep = display_indices(x.astype(np.float64), y.astype(np.float64), bound, connected=connected,
                                   log_x=log_x)
            if keep is not None:
                line.set_data(x[keep], y[keep])


def display_indices(x: NDArray[np.float64], y: NDArray[np.float64], n_out: int, *, connected: bool,
                    log_x: bool = False) -> NDArray[np.int64] | None:
    """Indices (sorted) of the points that draw the same picture, or None to keep them all.

    Connected lines with sorted x: M4 (first, last, min and max of n_out/4 equal-width x columns, on log10 x for a
    log axis; a NaN in y is kept so that the line still breaks there; tsdownsample). Markers only: every k-th
    point, about n_out (the density of the cloud), plus the M4 points of n_out/400 sorted-x or index columns (its
outliers, few enough not to change the cloud)."""
    from tsdownsample import M4Downsampler, NaNM4Downsampler

    if not np.all(np.isfinite(x)):
        return None
    xs = x
    if log_x:
        if np.any(x <= 0):
            return None
        xs = np.log10(x)
    ordered = bool(np.all(np.diff(xs) >= 0))
    if connected and not ordered:
        return None
    columns = max(4, (n_out if connected else n_out // 100) // 4 * 4)
    sampler = NaNM4Downsampler() if np.any(np.isnan(y)) else M4Downsampler()
    base = xs if ordered else np.arange(x.size, dtype=np.float64)
    keep = np.asarray(sampler.downsample(base, y, n_out=columns), dtype=np.int64)
    if not connected:
        keep = np.union1d(keep, np.arange(0, x.size, max(1, -(-x.size // n_out)), dtype=np.int64))
    return np.unique(keep)
