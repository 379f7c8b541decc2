"""Upload formats beyond the generic tables: CCSDS messages, mission Level-1 files, ...

A decoder turns a file of a known format into a table of the stream's canonical upload columns
(``time`` plus the stream's columns), stating the time scale and quaternion direction it used; the
generic validation then applies unchanged. Decoders live in ``app/ingest/decoders/<module>.py``, each
module exposing ``DECODERS: dict[str, Decoder]``; they are discovered here, so adding a format means
adding a module. The parsing itself belongs in ``processing/formats/`` (pure).
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache

import pyarrow as pa

from app.ingest import decoders as _decoders_pkg


@dataclass(frozen=True)
class Decoded:
    """``table``: ``time`` (ISO strings, numbers or timestamps on ``time_scale``) + canonical columns."""

    table: pa.Table
    time_scale: str = "utc"
    quaternion_direction: str = "sensor_to_inertial"
    sensor: str | None = None
    notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class Decoder:
    name: str
    streams: tuple[str, ...]
    decode: Callable[[bytes, str], Decoded]  # (body, stream) -> Decoded; raise ValueError with the reason
    description: str = ""
    media_types: tuple[str, ...] = field(default=())


@cache
def decoders() -> dict[str, Decoder]:
    found: dict[str, Decoder] = {}
    for info in pkgutil.iter_modules(_decoders_pkg.__path__):
        module = importlib.import_module(f"{_decoders_pkg.__name__}.{info.name}")
        for name, decoder in getattr(module, "DECODERS", {}).items():
            if name in found:
                raise RuntimeError(f"upload format {name!r} defined twice")
            found[name] = decoder
    return found
