"""What an upload body may be (media types) and how much work decoding it may cost (:class:`DecodeLimits`).

The decoding itself is :mod:`app.ingest.batches`: CSV columns are read as strings so that validation can
report the row of every bad value; Parquet/Arrow keep their types. The work is bounded before it is done:
the rows of a CSV are counted from its line ends, those of a Parquet file and its decoded size read from
its footer, an Arrow stream is read batch by batch; JSON bodies are limited in size and in distinct keys.
Beyond a limit :class:`LimitExceeded` is raised (413) before the table is built.
"""

from __future__ import annotations

from dataclasses import dataclass

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


def _too_many_rows(n: int, limits: DecodeLimits, how: str = "") -> LimitExceeded:
    return LimitExceeded(f"{how}{n} rows exceed the limit of {limits.max_rows} rows per upload; split the upload")


def _check_columns(n: int, limits: DecodeLimits, what: str = "columns") -> None:
    if n > limits.max_columns:
        raise UploadError([RowError(None, None, f"{n} {what}; at most {limits.max_columns} (no stream has more "
                                                f"than a dozen columns)")])
