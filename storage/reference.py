"""Reference data sets: raw file and parsed columns on disk, one catalog row each."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from sqlalchemy import or_, select
from sqlalchemy.orm import Session

from storage.jobs import ArtifactStore
from storage.models import ReferenceDataset, new_id


class ReferenceStore:
    """Files under ``<root>/<dataset id>/`` (``raw`` as received, ``data.parquet`` parsed).

    ``root`` is a local directory or a pyarrow/fsspec URL (written like job artifacts, see
    :class:`storage.jobs.ArtifactStore`).
    """

    def __init__(self, root: Path | str) -> None:
        self._files = ArtifactStore(root)
        self.root = self._files.root  # meaningful for local stores only

    def save(self, session: Session, *, kind: str, name: str, filename: str | None, raw: bytes,
             columns: dict[str, Any], start_tai_ns: int | None, end_tai_ns: int | None,
             details: dict[str, Any], api_key_id: str | None,
             spacecraft_id: int | None = None) -> ReferenceDataset:
        """Write both files (atomically), then add the catalog row; the caller commits. ``spacecraft_id``
        None: shared by every spacecraft."""
        dataset_id = new_id()
        table = pa.table({k: np.asarray(v) for k, v in columns.items()})
        buf = io.BytesIO()
        pq.write_table(table, buf)
        raw_file = self._files.write(dataset_id, "raw", raw, kind="raw", media_type="application/octet-stream")
        parsed = self._files.write(dataset_id, "data.parquet", buf.getvalue(), kind="table",
                                   media_type="application/vnd.apache.parquet")
        row = ReferenceDataset(id=dataset_id, kind=kind, name=name, filename=filename, size_bytes=len(raw),
                               checksum_sha256=raw_file.checksum_sha256, raw_path=raw_file.path,
                               parsed_path=parsed.path, rows=table.num_rows, start_tai_ns=start_tai_ns,
                               end_tai_ns=end_tai_ns, details=details, api_key_id=api_key_id,
                               spacecraft_id=spacecraft_id)
        session.add(row)
        session.flush()
        return row

    def columns(self, dataset: ReferenceDataset) -> dict[str, np.ndarray]:
        table = pq.read_table(pa.BufferReader(self._files.read_bytes(dataset.parsed_path)))
        return {c: table.column(c).to_numpy(zero_copy_only=False) for c in table.column_names}

    def raw_path(self, dataset: ReferenceDataset) -> Path:
        return self._files.file_path(dataset.raw_path)

    def remove(self, dataset_id: str) -> None:
        self._files.remove_job(dataset_id)


def usable_by(dataset: ReferenceDataset, spacecraft_id: int) -> bool:
    """Whether jobs of the spacecraft may use the data set: shared ones, or those scoped to it."""
    return dataset.spacecraft_id is None or dataset.spacecraft_id == spacecraft_id


def latest_covering(session: Session, kind: str, start_tai_ns: int, end_tai_ns: int, *,
                    spacecraft_id: int) -> ReferenceDataset | None:
    """Newest data set of ``kind`` overlapping [start, end] (or without a time span) that jobs of the
    spacecraft may use (shared, or scoped to it: never another spacecraft's)."""
    q = select(ReferenceDataset).where(ReferenceDataset.kind == kind).where(
        or_(ReferenceDataset.spacecraft_id.is_(None), ReferenceDataset.spacecraft_id == spacecraft_id)).where(
        or_(ReferenceDataset.start_tai_ns.is_(None),
            (ReferenceDataset.start_tai_ns <= end_tai_ns) & (ReferenceDataset.end_tai_ns >= start_tai_ns)))
    return session.scalar(q.order_by(ReferenceDataset.created_at.desc()).limit(1))
