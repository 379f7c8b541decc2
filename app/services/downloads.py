"""Stored tables as downloads (CSV, Parquet, JSON): the bytes, their media type and a file name."""

from __future__ import annotations

import io
import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from app.jobs.outputs import csv_safe, csv_text, jsonable
from processing.streams import TIME_COLUMN
from processing.time import timescales

FORMATS = {"csv": "text/csv", "parquet": "application/vnd.apache.parquet", "json": "application/json",
           "arrow": "application/vnd.apache.arrow.stream"}
BINARY_FORMATS = ("parquet", "arrow")  # typed columns: a timestamp ``time`` and the exact ``time_tai_ns``


@dataclass(frozen=True)
class Download:
    """A file to hand to the caller."""

    content: bytes
    media_type: str
    filename: str


def with_times(table: pa.Table, time_scale: str, time_format: str) -> pa.Table:
    """``time_tai_ns`` replaced by ``time``: ISO 8601 on ``time_scale`` (iso) or seconds since 1970 (seconds);
    tai_ns: the ISO ``time`` followed by the exact ``time_tai_ns``."""
    if TIME_COLUMN not in table.column_names:
        return table
    tai = table.column(TIME_COLUMN).to_numpy()
    if time_format == "tai_ns":
        iso = pa.array(timescales.tai_ns_to_iso(tai, time_scale), pa.string())
        rest = table.drop_columns([TIME_COLUMN])
        return rest.add_column(0, TIME_COLUMN, table.column(TIME_COLUMN)).add_column(0, "time", iso)
    if time_format == "iso":
        times = pa.array(timescales.tai_ns_to_iso(tai, time_scale), pa.string())
    else:
        times = pa.array(timescales.tai_ns_to_seconds(tai, time_scale), pa.float64())
    return table.drop_columns([TIME_COLUMN]).add_column(0, "time", times)


def with_timestamps(table: pa.Table, time_scale: str) -> pa.Table:
    """``time`` as a timestamp (ns; tz UTC on the UTC scale, naive readings of the other scales) in front of
    the exact ``time_tai_ns``. Inside a leap second the UTC timestamp holds at the following midnight (POSIX
    has no 23:59:60); ``time_tai_ns`` keeps the instant."""
    if TIME_COLUMN not in table.column_names:
        return table
    tai = table.column(TIME_COLUMN).to_numpy()
    epoch_ns = timescales.tai_ns_to_epoch_ns(tai, time_scale)
    kind = pa.timestamp("ns", tz="UTC") if time_scale == "utc" else pa.timestamp("ns")
    rest = table.drop_columns([TIME_COLUMN])
    return rest.add_column(0, TIME_COLUMN, table.column(TIME_COLUMN)).add_column(0, "time", pa.array(epoch_ns, kind))


def encode(table: pa.Table, fmt: str) -> bytes:
    """The table as CSV, Parquet, Arrow IPC stream or JSON records (compact JSON, non-finite numbers as null)."""
    if fmt == "json":
        return json.dumps(jsonable(table.to_pylist()), ensure_ascii=False, allow_nan=False, indent=None,
                          separators=(",", ":")).encode("utf-8")
    buf = io.BytesIO()
    if fmt == "csv":  # text cells that a spreadsheet would run as formulas are prefixed with '
        pacsv.write_csv(csv_safe(table), buf)
    elif fmt == "arrow":
        with pa.ipc.new_stream(buf, table.schema) as writer:
            writer.write_table(table)
    else:
        pq.write_table(table, buf)
    return buf.getvalue()


def table_download(table: pa.Table, fmt: str, time_scale: str, time_format: str, stem: str) -> Download:
    """A table as a ``<stem>.<fmt>`` download. CSV/JSON: ``time_tai_ns`` becomes ``time`` on the requested scale
    (ISO or seconds); Parquet/Arrow: a timestamp ``time`` on that scale beside ``time_tai_ns``."""
    timed = with_timestamps(table, time_scale) if fmt in BINARY_FORMATS else with_times(table, time_scale, time_format)
    return Download(encode(timed, fmt), FORMATS[fmt], f"{stem}.{fmt}")


STREAMED_FORMATS = ("csv", "json", "arrow", "parquet")
"""Formats written chunk by chunk as the rows are read (constant memory): Parquet one row group per chunk."""


class _Spool:
    """A write-only file for a streaming writer: the bytes written since the last :meth:`take`, and the position
    of everything written so far (Parquet records row-group offsets from ``tell``)."""

    def __init__(self) -> None:
        self._parts: list[bytes] = []
        self._position = 0
        self.closed = False

    def write(self, data: bytes | memoryview) -> int:
        chunk = bytes(data)
        self._parts.append(chunk)
        self._position += len(chunk)
        return len(chunk)

    def tell(self) -> int:
        return self._position

    def flush(self) -> None:
        pass

    def writable(self) -> bool:
        return True

    def close(self) -> None:
        self.closed = True

    def take(self) -> bytes:
        out = b"".join(self._parts)
        self._parts.clear()
        return out


TEXT_PIECE_ROWS = 65_536
"""CSV and JSON are encoded in pieces of this many rows (their text, and JSON's Python objects, are several
times the size of the Arrow rows), so the memory of a streamed text read is that of one chunk read plus one piece."""


def _pieces(chunks: Iterator[pa.Table], fmt: str) -> Iterator[pa.Table]:
    for table in chunks:
        if fmt in ("csv", "json") and table.num_rows > TEXT_PIECE_ROWS:
            for offset in range(0, table.num_rows, TEXT_PIECE_ROWS):
                yield table.slice(offset, TEXT_PIECE_ROWS)
        else:
            yield table


def stream_chunks(chunks: Iterator[pa.Table], fmt: str, time_scale: str, time_format: str) -> Iterator[bytes]:
    """The encoded download of consecutive tables: one CSV header, one JSON array, one Arrow IPC stream, one Parquet
    file (a row group per table)."""
    if fmt == "csv":
        yield from csv_text(with_times(table, time_scale, time_format) for table in _pieces(chunks, fmt))
        return
    first = True
    writer: Any = None
    sink = _Spool()
    for table in _pieces(chunks, fmt):
        timed = with_timestamps(table, time_scale) if fmt in BINARY_FORMATS else with_times(table, time_scale,
                                                                                             time_format)
        if fmt == "json":
            body = json.dumps(jsonable(timed.to_pylist()), ensure_ascii=False, allow_nan=False,
                              separators=(",", ":"))[1:-1]
            if body:
                yield (("[" if first else ",") + body).encode("utf-8")
                first = False
            continue
        else:
            if writer is None:
                writer = (pa.ipc.new_stream(pa.PythonFile(sink, mode="w"), timed.schema) if fmt == "arrow"
                          else pq.ParquetWriter(pa.PythonFile(sink, mode="w"), timed.schema))
            writer.write_table(timed)
            yield sink.take()
        first = False
    if fmt == "json":
        yield b"[]" if first else b"]"
    elif writer is not None:  # arrow: the end-of-stream marker; parquet: the footer
        writer.close()
        yield sink.take()


@dataclass(frozen=True)
class StoredFile:
    """A file of a store to hand to the caller as it is."""

    path: Path
    media_type: str
    filename: str
    csv_from_parquet: bool = False  # path is a Parquet table to hand out as CSV, converted on the fly
