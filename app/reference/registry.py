"""Kinds of reference data (Earth orientation, GNSS navigation, reference orbits, ...).

Each kind lives in ``app/reference/kinds/<module>.py`` exposing ``KINDS: dict[str, ReferenceKind]``,
with its parser (pure) in ``processing/formats/``. Discovered here, like the upload decoders.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache

from app.reference import kinds as _kinds_pkg
from processing.tasks import ParsedReference


@dataclass(frozen=True)
class ReferenceKind:
    name: str
    parse: Callable[[bytes], ParsedReference]  # raise ValueError with the reason for bad files
    description: str = ""


@cache
def reference_kinds() -> dict[str, ReferenceKind]:
    found: dict[str, ReferenceKind] = {}
    for info in pkgutil.iter_modules(_kinds_pkg.__path__):
        module = importlib.import_module(f"{_kinds_pkg.__name__}.{info.name}")
        for name, kind in getattr(module, "KINDS", {}).items():
            if name in found:
                raise RuntimeError(f"reference kind {name!r} defined twice")
            found[name] = kind
    return found
