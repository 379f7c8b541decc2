"""An upload body held in a temporary file while it is ingested, with what was learnt while receiving it.

The HTTP route writes the (inflated) body into an anonymous temporary file in the data directory's
``tmp`` area as it arrives (``O_TMPFILE`` where available: nothing is left behind by a crash), computing
its SHA-256 and counting its line ends on the way; decoding then reads the file in batches, so the body
is never held in memory whole. A body given as bytes (the web UI's form uploads) is wrapped the same way.
"""

from __future__ import annotations

import hashlib
import io
import tempfile
from pathlib import Path
from typing import IO


class Body:
    """A complete upload body: a seekable binary file, its size, SHA-256 and number of ``\\n``."""

    def __init__(self, file: IO[bytes], size: int, sha256: str, newlines: int, last_byte: bytes) -> None:
        self.file, self.size, self.sha256, self.newlines, self._last = file, size, sha256, newlines, last_byte

    @classmethod
    def from_bytes(cls, data: bytes) -> Body:
        return cls(io.BytesIO(data), len(data), hashlib.sha256(data).hexdigest(), data.count(b"\n"), data[-1:])

    @property
    def lines(self) -> int:
        """Lines of a text body (a last line without its line end counts)."""
        return self.newlines + (self.size > 0 and self._last != b"\n")

    def reader(self) -> IO[bytes]:
        """The file, positioned at its start."""
        self.file.seek(0)
        return self.file

    def read(self) -> bytes:
        """The whole body (for decoders that need it whole: the mission formats, JSON)."""
        return self.reader().read()

    def is_blank(self) -> bool:
        """Empty or only whitespace (checked on the first bytes: a longer body is not blank in practice,
        and if it were, decoding would refuse it)."""
        if self.size > 1 << 16:
            return False
        return not self.read().strip()

    def close(self) -> None:
        self.file.close()


class BodySpool:
    """Receives a body chunk by chunk into a temporary file in ``directory``; :meth:`finish` -> :class:`Body`."""

    def __init__(self, directory: Path) -> None:
        directory.mkdir(parents=True, exist_ok=True)
        self.file: IO[bytes] = tempfile.TemporaryFile(dir=directory, prefix="upload-")  # noqa: SIM115
        self.size = 0
        self.newlines = 0
        self._hash = hashlib.sha256()
        self._last = b""

    def write(self, chunk: bytes) -> None:
        if not chunk:
            return
        self.file.write(chunk)
        self._hash.update(chunk)
        self.newlines += chunk.count(b"\n")
        self.size += len(chunk)
        self._last = chunk[-1:]

    def finish(self) -> Body:
        self.file.flush()
        return Body(self.file, self.size, self._hash.hexdigest(), self.newlines, self._last)

    def discard(self) -> None:
        self.file.close()
