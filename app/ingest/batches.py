"""Decode an upload body in bounded record batches (issue 24), or whole (:func:`parse_body`), with the
limits of :class:`app.ingest.parse.DecodeLimits`.

:func:`iter_tables` yields ``(first upload row, table)`` pairs of at most ``batch_rows`` rows:
Parquet by ``ParquetFile.iter_batches`` (rows, columns and decoded size checked from the footer first),
an Arrow IPC stream batch by batch, CSV through pyarrow's streaming reader with a bounded block size
(every column as text; rows counted from the line ends before decoding), JSON records
(size-capped) turned into columns one slice of records at a time, so the cost is records x columns once.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterator

import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.ipc as ipc
import pyarrow.parquet as pq

from app.ingest.errors import RowError, UploadError
from app.ingest.parse import (
    ARROW_TYPES,
    CSV_TYPES,
    NO_LIMITS,
    PARQUET_TYPES,
    SUPPORTED_TYPES,
    DecodeLimits,
    LimitExceeded,
    UnsupportedMediaType,
    _check_columns,
    _too_many_rows,
    media_type,
)
from app.ingest.spool import Body

CSV_BYTES_PER_ROW = 16  # CSV reader block = batch_rows x this (at least MIN_CSV_BLOCK): its text and the
# parsed string columns of a block in flight weigh several times the numbers of a batch
MIN_CSV_BLOCK = 1 << 16
MAX_CSV_BLOCK = 1 << 26
MAX_HEADER_BYTES = 1 << 20
WHOLE = 1 << 40  # batch_rows of parse_body: one batch (CSV: one per reader block)

Batches = Iterator[tuple[int, pa.Table]]


def iter_tables(body: Body, content_type: str | None, limits: DecodeLimits, batch_rows: int) -> Batches:
    """The upload as consecutive tables of at most ``batch_rows`` rows with the upload row of their first
    row; UnsupportedMediaType (415) at once, UploadError (422) or LimitExceeded (413) when reached."""
    kind = media_type(content_type)
    if kind not in SUPPORTED_TYPES:
        hint = ("; a text file in a mission format (GRACE-FO Level-1B ASCII, CCSDS OEM or AEM) is uploaded with the "
                "query parameter format= (gracefo-l1b, ccsds-oem, ccsds-aem: GET /api/v1/formats lists them)"
                if kind == "text/plain" else "")
        raise UnsupportedMediaType(
            f"Content-Type {kind or '(none)'!r} is not supported; use one of {', '.join(SUPPORTED_TYPES)}{hint}")
    if body.is_blank():
        raise UploadError([RowError(None, None, "the request body is empty")])
    if kind in CSV_TYPES:
        batches, what = _csv(body, limits, batch_rows), "CSV"
    elif kind in PARQUET_TYPES:
        batches, what = _parquet(body, limits, batch_rows), "Parquet"
    elif kind in ARROW_TYPES:
        batches, what = _arrow(body, limits, batch_rows), "an Arrow IPC stream"
    else:
        batches, what = _json(body, limits, batch_rows), "JSON"
    return _numbered(batches, what)


def parse_body(body: bytes, content_type: str | None, limits: DecodeLimits = NO_LIMITS) -> pa.Table:
    """The whole upload as one table (an upload whose times go back is validated at once, so that its 422 lists
    every such row); the errors of :func:`iter_tables`."""
    tables = [t for _, t in iter_tables(Body.from_bytes(body), content_type, limits, WHOLE)]
    if not tables:
        raise UploadError([RowError(None, None, "the upload has no rows")])
    return pa.concat_tables(tables)


def _numbered(tables: Iterator[pa.Table], what: str) -> Batches:
    """Number the rows; a decoding failure becomes an UploadError naming the format."""
    first = 0
    try:
        for table in tables:
            if table.num_rows:
                yield first, table
                first += table.num_rows
    except (UploadError, LimitExceeded):
        raise
    except RecursionError:
        raise UploadError([RowError(None, None, "the body is nested too deeply")]) from None
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise UploadError([RowError(None, None, f"the body is not readable as {what}: {exc}")]) from exc


def _sliced(batch: pa.RecordBatch | pa.Table, batch_rows: int) -> Iterator[pa.Table]:
    table = pa.Table.from_batches([batch]) if isinstance(batch, pa.RecordBatch) else batch
    for lo in range(0, table.num_rows, batch_rows):
        yield table.slice(lo, batch_rows)


def _csv(body: Body, limits: DecodeLimits, batch_rows: int) -> Iterator[pa.Table]:
    if body.lines - 1 > limits.max_rows:  # header included; quoted line ends overcount
        raise _too_many_rows(body.lines - 1, limits, "about ")
    first_line = body.reader().readline(MAX_HEADER_BYTES).decode("utf-8-sig", errors="replace").rstrip("\r\n")
    names = [h.strip() for h in next(csv.reader([first_line]), [])]
    if not any(names):
        raise UploadError([RowError(None, None, "the CSV has no header line")])
    _check_columns(len(names), limits)
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise UploadError([RowError(None, n, "column appears more than once in the header") for n in dup])
    reader = pacsv.open_csv(
        body.reader(),
        read_options=pacsv.ReadOptions(column_names=names, skip_rows=1, use_threads=True,
                                       block_size=min(MAX_CSV_BLOCK,
                                                      max(MIN_CSV_BLOCK, batch_rows * CSV_BYTES_PER_ROW))),
        convert_options=pacsv.ConvertOptions(column_types=dict.fromkeys(names, pa.string()),
                                             strings_can_be_null=False, quoted_strings_can_be_null=False),
    )
    for batch in reader:
        yield from _sliced(batch, batch_rows)


def _parquet(body: Body, limits: DecodeLimits, batch_rows: int) -> Iterator[pa.Table]:
    """Rows, columns and decoded size from the footer first: a small file of 2e8 constant rows is refused
    without decoding a row."""
    pf = pq.ParquetFile(body.reader(), pre_buffer=False)  # pre-buffering holds far more than a row group
    md = pf.metadata
    _check_columns(md.num_columns, limits)
    if md.num_rows > limits.max_rows:
        raise _too_many_rows(md.num_rows, limits)
    decoded = sum(md.row_group(i).total_byte_size for i in range(md.num_row_groups))
    if decoded > limits.max_decoded_bytes:
        raise LimitExceeded(f"the Parquet file decodes to {decoded} bytes; the limit is "
                            f"{limits.max_decoded_bytes} bytes per upload")
    for i in range(md.num_row_groups):
        # a row group of a few batches is read whole (iter_batches reads ahead and holds several times as
        # much); a larger one batch by batch
        if md.row_group(i).num_rows <= 2 * batch_rows:
            yield from _sliced(pf.read_row_group(i), batch_rows)
        else:
            for batch in pf.iter_batches(batch_size=batch_rows, row_groups=[i]):
                yield pa.Table.from_batches([batch])


def _arrow(body: Body, limits: DecodeLimits, batch_rows: int) -> Iterator[pa.Table]:
    """Batch by batch, stopping at the first batch that takes the upload past a limit."""
    rows = size = 0
    with ipc.open_stream(body.reader()) as reader:
        _check_columns(len(reader.schema), limits)
        for batch in reader:
            rows += batch.num_rows
            size += batch.nbytes
            if rows > limits.max_rows:
                raise _too_many_rows(rows, limits, "at least ")
            if size > limits.max_decoded_bytes:
                raise LimitExceeded(f"the Arrow stream decodes to more than {limits.max_decoded_bytes} bytes")
            yield from _sliced(batch, batch_rows)


def _json(body: Body, limits: DecodeLimits, batch_rows: int) -> Iterator[pa.Table]:
    if body.size > limits.max_json_bytes:
        raise LimitExceeded(f"JSON uploads are limited to {limits.max_json_bytes} bytes (got {body.size}); "
                            "send larger batches as CSV, Parquet or Arrow")
    data = json.loads(body.read())
    if isinstance(data, dict) and isinstance(data.get("records"), list):
        data = data["records"]
    if not isinstance(data, list) or not all(isinstance(r, dict) for r in data):
        raise UploadError([RowError(None, None,
                                    "JSON body must be a list of records (objects), or {\"records\": [...]}")])
    if not data:
        raise UploadError([RowError(None, None, "the upload has no rows")])
    if len(data) > limits.max_rows:
        raise _too_many_rows(len(data), limits)
    names: dict[str, None] = {}  # every key of every record, in order of appearance: the same columns per batch
    for rec in data:
        if len(rec) and not names.keys() >= rec.keys():
            names.update(dict.fromkeys(rec))
            _check_columns(len(names), limits, "distinct keys")
    for lo in range(0, len(data), batch_rows):
        records = data[lo:lo + batch_rows]
        arrays = {}
        for n in names:
            values = [rec.get(n) for rec in records]
            try:
                arrays[n] = pa.array(values)
            except (pa.ArrowException, OverflowError):
                arrays[n] = pa.array([None if v is None else str(v) for v in values], pa.string())
        yield pa.table(arrays)
