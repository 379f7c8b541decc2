"""Cursor pages of catalog listings, newest first: ``limit`` items and the cursor of the next page.

The cursor is opaque (the creation time and id of the last item of the page); the API announces it
in headers (app/api/pagination.py).
"""

from __future__ import annotations

import base64
import datetime as dt
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from sqlalchemy import Select, and_, or_
from sqlalchemy.orm import InstrumentedAttribute

from app.services.errors import Invalid

T = TypeVar("T")


@dataclass(frozen=True)
class Page(Generic[T]):
    """One page of a listing; ``next_cursor`` is None on the last page."""

    items: list[T]
    next_cursor: str | None


def encode_cursor(created_at: dt.datetime, item_id: str) -> str:
    return base64.urlsafe_b64encode(f"{created_at.isoformat()}|{item_id}".encode()).decode().rstrip("=")


MAX_CURSOR_CHARS = 200


def decode_cursor(cursor: str) -> tuple[dt.datetime, str]:
    """The (creation time, id) in a cursor; Invalid for anything :func:`encode_cursor` cannot have made
    (garbage, a naive or out-of-range date, an id that is not one of ours)."""
    bad = Invalid("invalid cursor; use the X-Next-Cursor value of the previous page")
    if len(cursor) > MAX_CURSOR_CHARS:
        raise bad
    try:
        raw = base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4)).decode()
        when_text, item_id = raw.split("|", 1)
        when = dt.datetime.fromisoformat(when_text)
    except (ValueError, UnicodeDecodeError):
        raise bad from None
    if when.tzinfo is None or not item_id or len(item_id) > 64 or not item_id.isascii() or not item_id.isalnum():
        raise bad
    return when.astimezone(dt.UTC), item_id


def paginate(query: Select[Any, *tuple[Any, ...]], created_at: InstrumentedAttribute[dt.datetime],
             item_id: InstrumentedAttribute[str], cursor: str | None, limit: int) -> Any:
    """Order newest first and start after ``cursor``; fetches one extra row to detect a next page."""
    if cursor:
        when, last_id = decode_cursor(cursor)
        query = query.where(or_(created_at < when, and_(created_at == when, item_id < last_id)))
    return query.order_by(created_at.desc(), item_id.desc()).limit(limit + 1)


def page_of(rows: list[T], limit: int, key: Callable[[T], tuple[dt.datetime, str]]) -> Page[T]:
    """The rows of a :func:`paginate` query as a page: the extra row, if any, becomes the next cursor.
    ``key(row)`` -> (created_at, id) of a row."""
    if len(rows) <= limit:
        return Page(rows, None)
    rows = rows[:limit]
    return Page(rows, encode_cursor(*key(rows[-1])))
