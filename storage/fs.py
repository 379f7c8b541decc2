"""Where the stores keep their files: a local directory or any pyarrow/fsspec filesystem.

``resolve("s3://bucket/prefix")`` gives the filesystem and the root path inside it. Schemes pyarrow
implements natively (``s3``, ``gs``, ``hdfs``, ``abfs``, ``file``) use pyarrow's C++ filesystems;
any other fsspec protocol (``memory://``, ``az://`` with adlfs, ...) is wrapped with
:class:`pyarrow.fs.FSSpecHandler`. Credentials and endpoints come from the usual environment of each
filesystem (for S3: ``AWS_ACCESS_KEY_ID``, ``AWS_SECRET_ACCESS_KEY``, ``AWS_REGION``,
``AWS_ENDPOINT_URL``) or from URL query options pyarrow understands (``?endpoint_override=...``).

Publishing: on a local directory a file is written under a temporary name, fsynced and renamed (an
atomic publish). Object stores have no atomic rename, but a single PUT (or a completed multipart
upload) makes an object visible whole or not at all; the stores write the complete file in one
upload under its final name, and — as everywhere — readers open only files the catalog lists, and the
catalog row is committed after the upload returned. A crash between the two leaves an unlisted object
that :func:`storage.telemetry.sweep_orphans` deletes at the next start-up.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa
import pyarrow.fs as pafs


class StorageURLError(ValueError):
    """A data URL that names no usable filesystem."""


@dataclass(frozen=True)
class Location:
    """A root directory on a filesystem; ``local`` roots support fsync and atomic rename."""

    fs: pafs.FileSystem
    root: str  # path of the root inside ``fs``, without a trailing slash
    url: str  # as configured (a local path or a URL)
    local: bool

    def path(self, rel: str) -> str:
        """The full path inside ``fs`` of ``rel`` (a '/'-separated path below the root)."""
        return f"{self.root}/{rel}" if rel else self.root

    def relative(self, full: str) -> str:
        return full[len(self.root) + 1:] if full.startswith(self.root + "/") else full

    def write_bytes(self, rel: str, data: bytes | pa.Buffer) -> None:
        """One complete upload under the final name (object stores publish whole objects)."""
        full = self.path(rel)
        parent = full.rsplit("/", 1)[0]
        self.fs.create_dir(parent, recursive=True)
        with self.fs.open_output_stream(full) as out:
            out.write(data)

    def read_bytes(self, rel: str) -> bytes:
        with self.fs.open_input_stream(self.path(rel)) as f:
            return bytes(f.read())

    def exists(self, rel: str) -> bool:
        return self.fs.get_file_info(self.path(rel)).type == pafs.FileType.File

    def delete(self, rel: str) -> None:
        try:
            self.fs.delete_file(self.path(rel))
        except FileNotFoundError:
            pass

    def delete_dir(self, rel: str) -> None:
        try:
            self.fs.delete_dir(self.path(rel))
        except FileNotFoundError:
            pass

    def list_files(self, suffix: str = "") -> list[tuple[str, dt.datetime | None]]:
        """Every file below the root (relative path, modification time when the filesystem has one)."""
        infos = self.fs.get_file_info(pafs.FileSelector(self.root, recursive=True, allow_not_found=True))
        return [(self.relative(i.path), i.mtime) for i in infos
                if i.type == pafs.FileType.File and i.path.endswith(suffix)]


def is_url(root: str | Path) -> bool:
    return isinstance(root, str) and "://" in root and not root.startswith("file://")


def resolve(root: str | Path) -> Location:
    """The filesystem and root path of a local directory or a pyarrow/fsspec URL."""
    if not is_url(root):
        local = Path(str(root).removeprefix("file://")).resolve()
        return Location(pafs.LocalFileSystem(), local.as_posix(), str(root), local=True)
    url = str(root)
    try:
        fs, found = pafs.FileSystem.from_uri(url)
        path = str(found)
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError, ValueError):
        fs, path = _from_fsspec(url)
    if not path.strip("/"):
        raise StorageURLError(f"a data URL needs a bucket or directory, got {url!r}")
    return Location(fs, path.rstrip("/"), url, local=False)


def _from_fsspec(url: str) -> tuple[pafs.FileSystem, str]:
    try:
        import fsspec
    except ImportError:  # pragma: no cover - fsspec is a dependency
        raise StorageURLError(f"{url!r}: pyarrow does not know this scheme and fsspec is not installed") from None
    try:
        fs, path = fsspec.core.url_to_fs(url)
    except (ImportError, ValueError) as exc:
        raise StorageURLError(f"{url!r}: no filesystem for this URL ({exc}); install the fsspec "
                              f"implementation of its scheme") from None
    return pafs.PyFileSystem(pafs.FSSpecHandler(fs)), str(path)
