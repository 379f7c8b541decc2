"""The contract between the job runner and the pure algorithms.

A job task receives the telemetry of its window as plain column arrays and the spacecraft
configuration, and returns a JSON-able summary plus named tables. It does no I/O; the runner (app/)
loads the inputs, stores the outputs and draws the figures.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

Columns = Mapping[str, NDArray[Any]]
Progress = Callable[[float, str], None]


class TaskError(ValueError):
    """The inputs or parameters do not allow the computation; the message says what and why."""


def no_progress(fraction: float, stage: str) -> None:
    """Default progress callback (does nothing)."""


@dataclass(frozen=True)
class ParsedReference:
    """A parsed reference file: equal-length columns (``time_tai_ns`` when time-tagged), the time span
    it covers (None when it has none) and JSON-able ``details`` (source, satellites, ...)."""

    columns: dict[str, NDArray[Any]]
    start_tai_ns: int | None = None
    end_tai_ns: int | None = None
    details: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ReferenceData:
    """A reference data set given to a task: catalog id and name (for reports) and its columns."""

    id: str
    name: str
    columns: Columns
    details: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class TaskInputs:
    """Telemetry of the job window.

    ``streams[name]`` maps column names to 1-D arrays of equal length: ``time_tai_ns`` (int64 ns since
    1970-01-01 TAI), ``sensor`` (str) and the canonical columns of processing.streams, sorted by
    (sensor, time). A stream without samples in the window is absent. ``config`` is the spacecraft
    configuration (DESIGN.md JSON shape) of the version the job was submitted with. ``reference``
    maps a reference kind (e.g. "eop_finals2000a") to the data set chosen at submission.
    """

    streams: Mapping[str, Columns]
    config: Mapping[str, Any]
    start_tai_ns: int
    end_tai_ns: int
    reference: Mapping[str, ReferenceData] = field(default_factory=dict)

    def stream(self, name: str, sensor: str | None = None) -> Columns:
        """One stream's columns, optionally restricted to one sensor; TaskError if absent/empty."""
        cols = self.streams.get(name)
        if cols is None or len(cols["time_tai_ns"]) == 0:
            raise TaskError(f"no {name} samples in the job window")
        if sensor is None:
            return cols
        mask = cols["sensor"] == sensor
        if not np.any(mask):
            present = ", ".join(sorted(set(np.asarray(cols["sensor"]).tolist())))
            raise TaskError(f"no {name} samples of sensor {sensor!r} in the window (present: {present})")
        return {k: np.asarray(v)[mask] for k, v in cols.items()}


@dataclass(frozen=True)
class TaskResult:
    """What a task returns: ``summary`` (JSON-able, units suffixed in key names), ``tables``
    (name -> equal-length column arrays; ``time_tai_ns`` columns are shown as UTC in exports) and
    ``files`` (file name -> (content, media type), e.g. a CCSDS AEM the task wrote)."""

    summary: dict[str, Any]
    tables: dict[str, dict[str, NDArray[Any]]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    files: dict[str, tuple[bytes, str]] = field(default_factory=dict)
