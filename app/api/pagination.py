"""Cursor pagination of listings, newest first, bounded by ``limit``.

The body stays a plain JSON list; the next page is announced in the ``X-Next-Cursor`` header and a
``Link: <...>; rel="next"`` header (RFC 8288). The cursor is opaque (the position of the last item).
"""

from __future__ import annotations

import base64
import datetime as dt
from typing import Any

from fastapi import HTTPException, Request, Response
from sqlalchemy import Select, and_, or_
from sqlalchemy.orm import InstrumentedAttribute

MAX_LIMIT = 500


def encode_cursor(created_at: dt.datetime, item_id: str) -> str:
    return base64.urlsafe_b64encode(f"{created_at.isoformat()}|{item_id}".encode()).decode().rstrip("=")


def decode_cursor(cursor: str) -> tuple[dt.datetime, str]:
    try:
        raw = base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4)).decode()
        when, item_id = raw.split("|", 1)
        return dt.datetime.fromisoformat(when), item_id
    except (ValueError, UnicodeDecodeError):
        raise HTTPException(422, "invalid cursor; use the X-Next-Cursor value of the previous page") from None


def paginate(query: Select[Any, *tuple[Any, ...]], created_at: InstrumentedAttribute[dt.datetime],
             item_id: InstrumentedAttribute[str], cursor: str | None, limit: int) -> Any:
    """Order newest first and start after ``cursor``; fetches one extra row to detect a next page."""
    if cursor:
        when, last_id = decode_cursor(cursor)
        query = query.where(or_(created_at < when, and_(created_at == when, item_id < last_id)))
    return query.order_by(created_at.desc(), item_id.desc()).limit(limit + 1)


def announce_next(request: Request, response: Response, rows: list[Any], limit: int,
                  key: Any) -> list[Any]:
    """Trim the extra row and, if there was one, set the next-page headers. ``key(row)`` ->
    (created_at, id) of a row."""
    if len(rows) <= limit:
        return rows
    rows = rows[:limit]
    cursor = encode_cursor(*key(rows[-1]))
    response.headers["X-Next-Cursor"] = cursor
    url = request.url.include_query_params(cursor=cursor, limit=limit)
    response.headers["Link"] = f'<{url}>; rel="next"'
    return rows
