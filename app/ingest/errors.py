"""Errors of an upload, reported to the client as 422 with the row and column of each problem."""

from __future__ import annotations

from dataclasses import dataclass

MAX_REPORTED = 100


@dataclass(frozen=True)
class RowError:
    """``row`` is the 0-based index of the data record (CSV: header excluded); None = whole upload."""

    row: int | None
    column: str | None
    message: str

    def as_dict(self) -> dict[str, object]:
        return {"row": self.row, "column": self.column, "message": self.message}


class UploadError(ValueError):
    """The upload is invalid; nothing was stored."""

    def __init__(self, errors: list[RowError], total: int | None = None) -> None:
        self.errors = errors[:MAX_REPORTED]
        self.total = len(errors) if total is None else total
        first = errors[0] if errors else RowError(None, None, "invalid upload")
        where = "" if first.row is None else f"row {first.row}: "
        col = "" if first.column is None else f"{first.column}: "
        super().__init__(f"{self.total} error(s); first: {where}{col}{first.message}")
