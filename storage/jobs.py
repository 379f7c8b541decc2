"""Job state in the catalog, and job artifacts on disk or on an object store.

Every state change is a conditional UPDATE (``WHERE status IN (...)``), so two actors (a worker
finishing and a user cancelling, or two dispatchers claiming) can never both win.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import os
import shutil
import tempfile
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sqlalchemy import func, select, update
from sqlalchemy.orm import Session

from storage.fs import Location, resolve
from storage.models import Artifact, Job, utcnow

ACTIVE = ("queued", "running")
FINAL = ("succeeded", "failed", "cancelled")


def set_status(session: Session, job_id: str, new: str, *, allowed_from: tuple[str, ...],
               **values: Any) -> bool:
    """Move a job to ``new`` if it is in one of ``allowed_from``; True if this call did it."""
    now = utcnow()
    if new == "running":
        values.setdefault("started_at", now)
        values.setdefault("heartbeat_at", now)
    if new in FINAL:
        values.setdefault("finished_at", now)
    result = session.execute(update(Job).where(Job.id == job_id, Job.status.in_(allowed_from))
                             .values(status=new, **values))
    return bool(result.rowcount)  # type: ignore[attr-defined]


def claim(session: Session, job_id: str) -> bool:
    return set_status(session, job_id, "running", allowed_from=("queued",), stage="starting", progress=0.0)


def queued_ids(session: Session, limit: int) -> list[str]:
    return list(session.scalars(select(Job.id).where(Job.status == "queued")
                                .order_by(Job.created_at).limit(limit)))


def fair_queued_ids(session: Session, limit: int, per_key: int, window: int = 500) -> list[str]:
    """Up to ``limit`` queued jobs to claim next, sharing the job slots between API keys: each pick goes to
    the key with the fewest running (and already picked) jobs, oldest job first, and no key gets more than
    ``per_key`` running at once (counted over every instance sharing the catalog)."""
    if limit <= 0:
        return []
    counts: dict[str | None, int] = {
        k: int(n) for k, n in session.execute(select(Job.api_key_id, func.count()).where(Job.status == "running")
                                              .group_by(Job.api_key_id)).all()}
    queued = list(session.execute(select(Job.id, Job.api_key_id).where(Job.status == "queued")
                                  .order_by(Job.created_at, Job.id).limit(window)).all())
    picked: list[str] = []
    while len(picked) < limit and queued:
        eligible = [(counts.get(key, 0), i) for i, (_, key) in enumerate(queued) if counts.get(key, 0) < per_key]
        if not eligible:
            break
        _, i = min(eligible)
        job_id, key = queued.pop(i)
        counts[key] = counts.get(key, 0) + 1
        picked.append(job_id)
    return picked


def heartbeat(session: Session, job_ids: list[str]) -> None:
    if job_ids:
        session.execute(update(Job).where(Job.id.in_(job_ids), Job.status == "running")
                        .values(heartbeat_at=utcnow()))


def report_progress(session: Session, job_id: str, fraction: float, stage: str) -> bool:
    """Store progress; returns True when a cancel has been requested."""
    session.execute(update(Job).where(Job.id == job_id, Job.status == "running")
                    .values(progress=min(max(fraction, 0.0), 1.0), stage=stage[:200], heartbeat_at=utcnow()))
    return bool(session.scalar(select(Job.cancel_requested).where(Job.id == job_id)))


def fail_stale(session: Session, older_than_s: float, reason: str) -> list[str]:
    """Fail running jobs whose heartbeat stopped (their worker or service died)."""
    limit = utcnow() - dt.timedelta(seconds=older_than_s)
    ids = list(session.scalars(select(Job.id).where(Job.status == "running", Job.heartbeat_at < limit)))
    return [i for i in ids if set_status(session, i, "failed", allowed_from=("running",), error=reason,
                                         stage="failed")]


@dataclass(frozen=True)
class StoredArtifact:
    name: str
    kind: str
    media_type: str
    path: str  # relative to the artifact root
    size_bytes: int
    checksum_sha256: str
    description: str


class ArtifactStore:
    """Files of jobs under ``<root>/<job id>/``.

    Local roots: each file is written to a temporary name, fsynced and renamed. URL roots (any
    pyarrow/fsspec filesystem, see :mod:`storage.fs`): one whole upload under the final name; the
    artifact rows committed afterwards publish them. :meth:`path` gives a local file in both cases
    (remote files are fetched once into ``cache_dir``: artifacts never change once written).
    """

    def __init__(self, root: Path | str, cache_dir: Path | None = None) -> None:
        self.location: Location = resolve(root)
        self.root = Path(self.location.root)  # meaningful for local stores only
        if not self.location.local and cache_dir is None:
            digest = hashlib.sha256(self.location.url.encode()).hexdigest()[:16]
            cache_dir = Path(tempfile.gettempdir()) / "attitude-cache" / digest
        self.cache_dir = cache_dir

    def write(self, job_id: str, name: str, data: bytes, *, kind: str, media_type: str,
              description: str = "") -> StoredArtifact:
        if "/" in name or name.startswith("."):
            raise ValueError(f"artifact names are plain file names, got {name!r}")
        if self.location.local:
            self._write_local(self.root / job_id, name, data)
        else:
            try:
                self.location.write_bytes(f"{job_id}/{name}", data)
            except BaseException:
                self.location.delete(f"{job_id}/{name}")
                raise
        return StoredArtifact(name, kind, media_type, f"{job_id}/{name}", len(data),
                              hashlib.sha256(data).hexdigest(), description)

    @staticmethod
    def _write_local(directory: Path, name: str, data: bytes) -> None:
        directory.mkdir(parents=True, exist_ok=True)
        tmp = directory / f".tmp-{uuid.uuid4().hex}"
        try:
            with open(tmp, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, directory / name)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise

    def path(self, artifact: Artifact) -> Path:
        return self.file_path(artifact.path)

    def file_path(self, rel: str) -> Path:
        """A local file with the content of ``rel`` (a missing path when the file does not exist)."""
        if self.location.local:
            return self.root / rel
        assert self.cache_dir is not None
        cached = self.cache_dir / rel
        if not cached.is_file():
            try:
                data = self.location.read_bytes(rel)
            except FileNotFoundError:
                return cached
            self._write_local(cached.parent, cached.name, data)
        return cached

    def read_bytes(self, rel: str) -> bytes:
        if self.location.local:
            return (self.root / rel).read_bytes()
        return self.location.read_bytes(rel)

    def remove_job(self, job_id: str) -> None:
        if self.location.local:
            shutil.rmtree(self.root / job_id, ignore_errors=True)
            return
        self.location.delete_dir(job_id)
        if self.cache_dir is not None:
            shutil.rmtree(self.cache_dir / job_id, ignore_errors=True)


def add_artifacts(session: Session, job_id: str, artifacts: list[StoredArtifact]) -> None:
    for a in artifacts:
        session.add(Artifact(job_id=job_id, name=a.name, kind=a.kind, media_type=a.media_type, path=a.path,
                             size_bytes=a.size_bytes, checksum_sha256=a.checksum_sha256,
                             description=a.description))
