"""Serialising the ingests of one stream across threads, processes and service instances.

De-duplication reads the stored samples of the upload's span and then writes the new ones; two ingests
of one stream must not interleave, or both would store the same samples (or both accept conflicting
values). The lock is taken before the stored samples are read and held until the catalog commit:

- within a process: a ``threading.Lock`` per (spacecraft, stream);
- SQLite (several processes may share one catalog file, always on one machine): an exclusive
  ``fcntl.flock`` on ``<catalog dir>/locks/sc-<id>-<stream>.lock`` (an in-memory catalog has one process);
- PostgreSQL (any number of instances): a transaction-level advisory lock, released by the commit.
"""

from __future__ import annotations

import fcntl
import hashlib
import threading
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sqlalchemy import text
from sqlalchemy.orm import Session

_locks: defaultdict[tuple[int, str], threading.Lock] = defaultdict(threading.Lock)
_locks_guard = threading.Lock()


def _thread_lock(spacecraft_id: int, stream: str) -> threading.Lock:
    with _locks_guard:
        return _locks[(spacecraft_id, stream)]


def _sqlite_lock_path(session: Session, spacecraft_id: int, stream: str) -> Path | None:
    database = session.get_bind().engine.url.database
    if not database or database == ":memory:" or database.startswith("file:"):
        return None
    directory = Path(database).resolve().parent / "locks"
    directory.mkdir(parents=True, exist_ok=True)
    return directory / f"sc-{spacecraft_id}-{stream}.lock"


@contextmanager
def stream_lock(session: Session, spacecraft_id: int, stream: str) -> Iterator[None]:
    """Hold the ingest lock of one stream for the body (see the module docstring)."""
    with _thread_lock(spacecraft_id, stream):
        dialect = session.get_bind().dialect.name
        if dialect == "postgresql":
            key = int.from_bytes(hashlib.sha256(f"{spacecraft_id}/{stream}".encode()).digest()[:8], "big",
                                 signed=True)
            session.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": key})
            yield
            return
        path = _sqlite_lock_path(session, spacecraft_id, stream) if dialect == "sqlite" else None
        if path is None:
            yield
            return
        with open(path, "a+b") as fh:
            fcntl.flock(fh, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(fh, fcntl.LOCK_UN)
