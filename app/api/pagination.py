"""Cursor pagination of listings, newest first, bounded by ``limit`` (pages: app/services/pages.py).

The body stays a plain JSON list; the next page is announced in the ``X-Next-Cursor`` header and a
``Link: <...>; rel="next"`` header (RFC 8288). The cursor is opaque (the position of the last item).
"""

from __future__ import annotations

from typing import TypeVar

from fastapi import Request, Response

from app.services.pages import Page

MAX_LIMIT = 500

T = TypeVar("T")


def announce_next(request: Request, response: Response, page: Page[T], limit: int) -> list[T]:
    """The page's items; if there is a next page, its cursor and link go into the headers."""
    if page.next_cursor is not None:
        response.headers["X-Next-Cursor"] = page.next_cursor
        url = request.url.include_query_params(cursor=page.next_cursor, limit=limit)
        response.headers["Link"] = f'<{url}>; rel="next"'
    return page.items


