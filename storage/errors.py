"""Errors of the telemetry store that callers map to answers (the API: 503 and 507, JSON)."""

from __future__ import annotations


class DamagedFileError(Exception):
    """A catalogued telemetry file cannot be read (damaged, truncated or missing); it is quarantined.

    ``path`` relative to the store root, ``ingest_id`` of the upload that wrote it, ``stream``,
    ``reason`` what the reader said. Reads and ingests that need the file refuse rather than answer
    without it; the rest of the stream stays readable; an admin retracts the ingest or restores the file.
    """

    def __init__(self, path: str, reason: str, *, ingest_id: str | None = None, stream: str | None = None) -> None:
        self.path, self.reason, self.ingest_id, self.stream = path, reason, ingest_id, stream
        owner = f" (stream {stream}, ingest {ingest_id})" if ingest_id else ""
        super().__init__(f"telemetry file {path}{owner} is damaged and quarantined: {reason}. The rest of the "
                         "stream is readable; an admin can retract that ingest or restore the file")


class StorageFullError(Exception):
    """The telemetry or artifact store has no space left; nothing was stored."""
