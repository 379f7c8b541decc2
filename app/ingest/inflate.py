"""Inflating ``Content-Encoding: gzip`` request bodies as they arrive, whole and bounded.

RFC 1952 allows a gzip stream of several members (``cat a.gz b.gz``); all are inflated and joined.
Bytes after the last member that do not start another member are refused: silently ignoring them
(or, as zlib alone does, everything after the first member) would acknowledge an upload of which only
part was stored. The inflated size is held to a limit while inflating, so a small "gzip bomb" is
refused early.
"""

from __future__ import annotations

import zlib

GZIP_MAGIC = b"\x1f\x8b"
STEP = 1 << 20  # inflated bytes per zlib call: a bomb never holds more than the limit plus one step


class GzipBodyError(ValueError):
    """The body is not a complete gzip stream (bad data, truncated, or trailing bytes)."""


class InflatedTooLarge(ValueError):
    """The inflated body exceeds the limit."""


class GzipInflater:
    """Feed compressed chunks, get inflated bytes; :meth:`close` checks the stream ended cleanly."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.size = 0
        self.members = 0
        self._member: zlib._Decompress | None = None  # None: between members
        self._pending = b""

    def feed(self, data: bytes) -> bytes:
        return b"".join(self.feed_parts(data))

    def feed_parts(self, data: bytes) -> list[bytes]:
        """The inflated bytes of ``data`` in pieces of at most :data:`STEP` bytes (no joined copy)."""
        out: list[bytes] = []
        data = self._pending + data
        self._pending = b""
        while data:
            if self._member is None:
                if len(data) < len(GZIP_MAGIC):
                    self._pending = data
                    break
                if data[:2] != GZIP_MAGIC:
                    where = f"after gzip member {self.members}" if self.members else "at the start"
                    raise GzipBodyError(f"the body is not gzip data {where} (no gzip header; trailing bytes "
                                        "are refused so that nothing is silently dropped)")
                self._member = zlib.decompressobj(wbits=16 + zlib.MAX_WBITS)
            try:
                chunk = self._member.decompress(data, min(STEP, self.limit - self.size + 1))
            except zlib.error as exc:
                raise GzipBodyError(f"the body is not valid gzip (member {self.members + 1}): {exc}") from None
            self.size += len(chunk)
            if self.size > self.limit:
                raise InflatedTooLarge(f"inflated body exceeds the limit of {self.limit} bytes")
            out.append(chunk)
            if self._member.eof:
                data = self._member.unused_data
                self._member = None
                self.members += 1
            else:
                data = self._member.unconsumed_tail  # more of this member (the step was reached), or b""
        return out

    def close(self) -> None:
        """Raise GzipBodyError unless the data ended exactly at the end of a member."""
        if self._member is not None or self._pending or self.members == 0:
            raise GzipBodyError("the gzip body is truncated")
