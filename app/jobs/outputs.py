"""Turn a TaskResult into stored artifacts: tables (Parquet + CSV), figures (PNG), summary (JSON)."""

from __future__ import annotations

import io
import json
import math
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from processing.tasks import TaskResult
from processing.time import timescales
from storage.jobs import ArtifactStore, StoredArtifact

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


def table_to_arrow(columns: dict[str, Any]) -> pa.Table:
    """Columns -> Arrow; a ``time_tai_ns`` column gets an ISO UTC ``time`` column in front of it."""
    arrays: dict[str, Any] = {}
    if "time_tai_ns" in columns:
        arrays["time"] = pa.array(timescales.tai_ns_to_iso(np.asarray(columns["time_tai_ns"], np.int64)))
    for name, values in columns.items():
        arr = np.asarray(values)
        arrays[name] = pa.array(arr.tolist() if arr.dtype == object else arr)
    return pa.table(arrays)


def write_outputs(store: ArtifactStore, job_id: str, result: TaskResult,
                  figures: dict[str, Figure], summary: dict[str, Any]) -> list[StoredArtifact]:
    out: list[StoredArtifact] = []
    out.append(store.write(job_id, "summary.json", json.dumps(summary, indent=2).encode(), kind="summary",
                           media_type="application/json", description="job summary"))
    for name, columns in result.tables.items():
        table = table_to_arrow(columns)
        buf = io.BytesIO()
        pq.write_table(table, buf)
        out.append(store.write(job_id, f"{name}.parquet", buf.getvalue(), kind="table",
                               media_type="application/vnd.apache.parquet", description=f"table {name}"))
        buf = io.BytesIO()
        pacsv.write_csv(csv_safe(table), buf)
        out.append(store.write(job_id, f"{name}.csv", buf.getvalue(), kind="table", media_type="text/csv",
                               description=f"table {name}"))
    for name, (content, media_type) in result.files.items():
        out.append(store.write(job_id, name, content, kind="file", media_type=media_type,
                               description=f"file {name}"))
    for name, fig in figures.items():
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
        out.append(store.write(job_id, f"{name}.png", buf.getvalue(), kind="figure", media_type="image/png",
                               description=str(fig.get_label() or name)))
    return out
