"""Decode an upload body (CSV, Parquet, Arrow IPC stream, JSON records) into an Arrow table.

CSV columns are read as strings so that validation can report the row of every bad value;
Parquet/Arrow keep their types. Nothing here knows about streams.
"""

from __future__ import annotations

import csv
import io
import json

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


def media_type(content_type: str | None) -> str:
    return (content_type or "").split(";", 1)[0].strip().lower()


def parse_body(body: bytes, content_type: str | None) -> pa.Table:
    """Return the upload as an Arrow table; raise UploadError (422) or UnsupportedMediaType (415)."""
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
            return _parse_csv(body)
        if kind in PARQUET_TYPES:
            return pq.read_table(io.BytesIO(body))
        if kind in ARROW_TYPES:
            with ipc.open_stream(io.BytesIO(body)) as reader:
                return reader.read_all()
        return _parse_json(body)
    except UploadError:
        raise
    except RecursionError:
        raise UploadError([RowError(None, None, "the body is nested too deeply")]) from None
    except (pa.ArrowException, OSError, ValueError) as exc:
        what = {**dict.fromkeys(CSV_TYPES, "CSV"), **dict.fromkeys(PARQUET_TYPES, "Parquet"),
                **dict.fromkeys(ARROW_TYPES, "an Arrow IPC stream"), **dict.fromkeys(JSON_TYPES, "JSON")}
        raise UploadError([RowError(None, None, f"the body is not readable as {what[kind]}: {exc}")]) from exc


def _parse_csv(body: bytes) -> pa.Table:
    first_line = body.split(b"\n", 1)[0].decode("utf-8-sig", errors="replace")
    header = next(csv.reader([first_line]), [])
    names = [h.strip() for h in header]
    if not any(names):
        raise UploadError([RowError(None, None, "the CSV has no header line")])
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise UploadError([RowError(None, n, "column appears more than once in the header") for n in dup])
    return pacsv.read_csv(
        io.BytesIO(body),
        read_options=pacsv.ReadOptions(column_names=names, skip_rows=1, use_threads=True),
        convert_options=pacsv.ConvertOptions(column_types=dict.fromkeys(names, pa.string()),
                                             strings_can_be_null=False, quoted_strings_can_be_null=False),
    )


def _parse_json(body: bytes) -> pa.Table:
    data = json.loads(body)
    if isinstance(data, dict) and isinstance(data.get("records"), list):
        data = data["records"]
    if not isinstance(data, list) or not all(isinstance(r, dict) for r in data):
        raise UploadError([RowError(None, None,
                                    "JSON body must be a list of records (objects), or {\"records\": [...]}")])
    if not data:
        raise UploadError([RowError(None, None, "the upload has no rows")])
    names: list[str] = []
    seen: set[str] = set()
    for rec in data:
        for k in rec:
            if k not in seen:
                seen.add(k)
                names.append(k)
    columns: dict[str, list[object]] = {n: [rec.get(n) for rec in data] for n in names}
    arrays = {}
    for n, values in columns.items():
        try:
            arrays[n] = pa.array(values)
        except (pa.ArrowException, OverflowError):
            arrays[n] = pa.array([None if v is None else str(v) for v in values], pa.string())
    return pa.table(arrays)
