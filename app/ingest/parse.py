"""Decode an upload body (CSV, Parquet, Arrow IPC stream, JSON records) into an Arrow table.

CSV columns are read as strings so that validation can report the row of every bad value;
Parquet/Arrow keep their types. Nothing here knows about streams.

The work is bounded before it is done (:class:`DecodeLimits`): the rows of a CSV are counted from its
line ends, those of a Parquet file and its decoded size read from its footer, an Arrow stream is read
batch by batch; JSON bodies are limited in size and in distinct keys (building columns is records x keys).
Beyond a limit :class:`LimitExceeded` is raised (413) before the table is built.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass

import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.ipc as ipc
import pyarrow.parquet as pq

from app.ingest.errors import RowError, UploadError

CSV_TYPES = ("text/csv", "application/csv")
PARQUET_TYPES = ("application/vnd.apache.parquet", "application/x-parquet", "application/parquet")
ARROW_TYPES = ("application/vnd.apache.arrow.stream",)
JSON_TYPES = ("application/json",)
SUPPORTED_TYPES = CSV_TYPES + PARQUET_TYPES + ARROW_TYPES + JSON_TYPES


class UnsupportedMediaType(ValueError):
    pass


class LimitExceeded(ValueError):
    """The upload would need more rows, decoded bytes or columns than allowed (answered with 413)."""


@dataclass(frozen=True)
class DecodeLimits:
    max_rows: int = 20_000_000
    max_decoded_bytes: int = 4 << 30  # Arrow memory of the decoded table (Parquet: from its footer)
    max_columns: int = 64  # distinct columns or JSON keys: no stream has more than a dozen
    max_json_bytes: int = 64 << 20  # JSON records are parsed whole into Python objects (~10x the body)


NO_LIMITS = DecodeLimits(max_rows=1 << 62, max_decoded_bytes=1 << 62, max_columns=1 << 30, max_json_bytes=1 << 62)


def media_type(content_type: str | None) -> str:
    return (content_type or "").split(";", 1)[0].strip().lower()


def parse_body(body: bytes, content_type: str | None, limits: DecodeLimits = NO_LIMITS) -> pa.Table:
    """Return the upload as an Arrow table; raise UploadError (422), UnsupportedMediaType (415) or
    LimitExceeded (413, checked before decoding where the format allows)."""
    kind = media_type(content_type)
    if kind not in SUPPORTED_TYPES:
        hint = ("; a text file in a mission format (GRACE-FO Level-1B ASCII, CCSDS OEM or AEM) is uploaded with the "
                "query parameter format= (gracefo-l1b, ccsds-oem, ccsds-aem: GET /api/v1/formats lists them)"
                if kind == "text/plain" else "")
        raise UnsupportedMediaType(
            f"Content-Type {kind or '(none)'!r} is not supported; use one of {', '.join(SUPPORTED_TYPES)}{hint}")
    if not body.strip():
        raise UploadError([RowError(None, None, "the request body is empty")])
    try:
        if kind in CSV_TYPES:
            return _parse_csv(body, limits)
        if kind in PARQUET_TYPES:
            return _parse_parquet(body, limits)
        if kind in ARROW_TYPES:
            return _parse_arrow(body, limits)
        return _parse_json(body, limits)
    except (UploadError, LimitExceeded):
        raise
    except RecursionError:
        raise UploadError([RowError(None, None, "the body is nested too deeply")]) from None
    except (pa.ArrowException, OSError, ValueError) as exc:
        what = {**dict.fromkeys(CSV_TYPES, "CSV"), **dict.fromkeys(PARQUET_TYPES, "Parquet"),
                **dict.fromkeys(ARROW_TYPES, "an Arrow IPC stream"), **dict.fromkeys(JSON_TYPES, "JSON")}
        raise UploadError([RowError(None, None, f"the body is not readable as {what[kind]}: {exc}")]) from exc


def _too_many_rows(n: int, limits: DecodeLimits, how: str = "") -> LimitExceeded:
    return LimitExceeded(f"{how}{n} rows exceed the limit of {limits.max_rows} rows per upload; split the upload")


def _check_columns(n: int, limits: DecodeLimits, what: str = "columns") -> None:
    if n > limits.max_columns:
        raise UploadError([RowError(None, None, f"{n} {what}; at most {limits.max_columns} (no stream has more "
                                                f"than a dozen columns)")])


def _parse_csv(body: bytes, limits: DecodeLimits) -> pa.Table:
    lines = body.count(b"\n") + (not body.endswith(b"\n"))  # header included; quoted line ends overcount
    if lines - 1 > limits.max_rows:
        raise _too_many_rows(lines - 1, limits, "about ")
    first_line = body.split(b"\n", 1)[0].decode("utf-8-sig", errors="replace")
    header = next(csv.reader([first_line]), [])
    names = [h.strip() for h in header]
    if not any(names):
        raise UploadError([RowError(None, None, "the CSV has no header line")])
    _check_columns(len(names), limits)
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise UploadError([RowError(None, n, "column appears more than once in the header") for n in dup])
    return pacsv.read_csv(
        io.BytesIO(body),
        read_options=pacsv.ReadOptions(column_names=names, skip_rows=1, use_threads=True),
        convert_options=pacsv.ConvertOptions(column_types=dict.fromkeys(names, pa.string()),
                                             strings_can_be_null=False, quoted_strings_can_be_null=False),
    )


def _parse_parquet(body: bytes, limits: DecodeLimits) -> pa.Table:
    """Rows, columns and decoded size from the footer first: a small file of 2e8 constant rows is
    refused without decoding a row."""
    pf = pq.ParquetFile(io.BytesIO(body))
    md = pf.metadata
    _check_columns(md.num_columns, limits)
    if md.num_rows > limits.max_rows:
        raise _too_many_rows(md.num_rows, limits)
    decoded = sum(md.row_group(i).total_byte_size for i in range(md.num_row_groups))
    if decoded > limits.max_decoded_bytes:
        raise LimitExceeded(f"the Parquet file decodes to {decoded} bytes; the limit is "
                            f"{limits.max_decoded_bytes} bytes per upload")
    return pf.read()


def _parse_arrow(body: bytes, limits: DecodeLimits) -> pa.Table:
    """Batch by batch, stopping at the first batch that takes the upload past a limit."""
    batches = []
    rows = size = 0
    with ipc.open_stream(io.BytesIO(body)) as reader:
        _check_columns(len(reader.schema), limits)
        for batch in reader:
            rows += batch.num_rows
            size += batch.nbytes
            if rows > limits.max_rows:
                raise _too_many_rows(rows, limits, "at least ")
            if size > limits.max_decoded_bytes:
                raise LimitExceeded(f"the Arrow stream decodes to more than {limits.max_decoded_bytes} bytes")
            batches.append(batch)
        return pa.Table.from_batches(batches, schema=reader.schema)


def _parse_json(body: bytes, limits: DecodeLimits) -> pa.Table:
    if len(body) > limits.max_json_bytes:
        raise LimitExceeded(f"JSON uploads are limited to {limits.max_json_bytes} bytes (got {len(body)}); "
                            "send larger batches as CSV, Parquet or Arrow")
    data = json.loads(body)
    if isinstance(data, dict) and isinstance(data.get("records"), list):
        data = data["records"]
    if not isinstance(data, list) or not all(isinstance(r, dict) for r in data):
        raise UploadError([RowError(None, None,
                                    "JSON body must be a list of records (objects), or {\"records\": [...]}")])
    if not data:
        raise UploadError([RowError(None, None, "the upload has no rows")])
    if len(data) > limits.max_rows:
        raise _too_many_rows(len(data), limits)
    names: list[str] = []
    seen: set[str] = set()
    for rec in data:
        for k in rec:
            if k not in seen:
                seen.add(k)
                names.append(k)
                _check_columns(len(names), limits, "distinct keys")
    columns: dict[str, list[object]] = {n: [rec.get(n) for rec in data] for n in names}
    arrays = {}
    for n, values in columns.items():
        try:
            arrays[n] = pa.array(values)
        except (pa.ArrowException, OverflowError):
            arrays[n] = pa.array([None if v is None else str(v) for v in values], pa.string())
    return pa.table(arrays)
