"""Files in and out of the API: upload bodies (bounded in size, inflated from gzip as they arrive) and
downloads of what the services hand out."""

from __future__ import annotations

import re
from collections.abc import AsyncIterator
from pathlib import Path

from fastapi import HTTPException, Request, Response, status

from app.ingest.inflate import GzipBodyError, GzipInflater, InflatedTooLarge
from app.ingest.spool import Body, BodySpool
from app.services.downloads import Download


async def _body_parts(request: Request, limit: int) -> AsyncIterator[bytes]:
    """The (inflated) request body in pieces, refusing (413) more than ``limit`` bytes without reading it all.

    ``Content-Encoding: gzip`` bodies are inflated as they arrive (every member; trailing bytes are a 422,
    :mod:`app.ingest.inflate`), and the inflated size is held to the same limit, so a small "gzip bomb"
    is refused early; other encodings are 415.
    """
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise HTTPException(413,
                            f"body of {declared} bytes exceeds the limit of {limit} bytes")
    encoding = request.headers.get("content-encoding", "identity").strip().lower()
    if encoding not in ("identity", "gzip"):
        raise HTTPException(status.HTTP_415_UNSUPPORTED_MEDIA_TYPE,
                            f"Content-Encoding {encoding!r} is not supported; use gzip or none")
    inflater = GzipInflater(limit) if encoding == "gzip" else None
    size = 0
    try:
        async for chunk in request.stream():
            parts = inflater.feed_parts(chunk) if inflater is not None else [chunk]
            size += sum(map(len, parts))
            if size > limit:
                raise HTTPException(413, f"body exceeds the limit of {limit} bytes")
            for part in parts:
                yield part
        if inflater is not None:
            inflater.close()
    except InflatedTooLarge as exc:
        raise HTTPException(413, str(exc)) from None
    except GzipBodyError as exc:
        raise HTTPException(422, str(exc)) from None


async def read_limited(request: Request, limit: int) -> bytes:
    """The request body as bytes (limits and gzip as :func:`_body_parts`)."""
    return b"".join([part async for part in _body_parts(request, limit)])


async def spool_limited(request: Request, limit: int, directory: Path) -> Body:
    """The request body in a temporary file in ``directory`` (limits and gzip as :func:`_body_parts`), its
    SHA-256 and line ends counted while it arrives: an upload is never held in memory whole. The caller
    closes the returned :class:`Body` (the file goes with it)."""
    spool = BodySpool(directory)
    try:
        async for part in _body_parts(request, limit):
            spool.write(part)
        return spool.finish()
    except BaseException:
        spool.discard()
        raise


def upload_filename(request: Request, explicit: str | None) -> str | None:
    """The upload's file name: ``explicit``, else the Content-Disposition filename (at most 255 characters)."""
    if explicit:
        return explicit[:255]
    disposition = request.headers.get("content-disposition", "")
    m = re.search(r'filename="?([^";]+)"?', disposition)
    return m.group(1)[:255] if m else None


def download_response(d: Download) -> Response:
    """A download as an attachment."""
    return Response(d.content, media_type=d.media_type,
                    headers={"Content-Disposition": f'attachment; filename="{d.filename}"'})
