"""The contract between the job runner and the pure algorithms.

A job task receives the telemetry of its window (column arrays, with typed per-sensor views from
processing.samples) and the spacecraft configuration (processing.spacecraft.Spacecraft), and returns a
JSON-able summary plus named tables. It does no I/O; the runner (app/) loads the inputs, stores the
outputs and draws the figures.

Errors: :class:`TaskError` (and its subclasses, e.g. processing.spacecraft.MissingMountingError) is the
deliberate input error -- the job fails with its message. Any other exception, a ValueError included,
is treated by the runner as an internal error (logged with its traceback).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from processing.errors import TaskError
from processing.samples import (
    GnssSamples,
    GnssVisibilitySamples,
    GyroIncrementSamples,
    GyroSamples,
    MagnetometerSamples,
    MagnetorquerSamples,
    PanelCurrentSamples,
    Samples,
    StarTrackerSamples,
    SunSensorSamples,
)

if TYPE_CHECKING:
    from processing.spacecraft import Spacecraft

Columns = Mapping[str, NDArray[Any]]
Progress = Callable[[float, str], None]
Mapper = Callable[[Callable[[Any], Any], Sequence[Any]], list[Any]]
"""``mapper(func, parts) == [func(p) for p in parts]``, perhaps in parallel: how a task splits independent work
(segments, streams) without knowing where it runs; the job layer passes app.jobs.partitions.map_partitions.
``func`` is a module-level pure function (a cluster pickles it by reference)."""
V = TypeVar("V", bound=Samples)


def no_progress(fraction: float, stage: str) -> None:
    """Default progress callback (does nothing)."""


def serial_map(func: Callable[[Any], Any], parts: Sequence[Any]) -> list[Any]:
    """The default :data:`Mapper`: in order, here."""
    return [func(p) for p in parts]


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
    (sensor, time). A stream without samples in the window is absent. ``spacecraft`` is the spacecraft
    configuration of the version the job was submitted with. ``reference`` maps a reference kind (e.g.
    "eop_finals2000a") to the data set chosen at submission.

    Typed views (processing.samples), one sensor in time order: ``star_tracker(sensor)``, ``gyro()``,
    ``gnss()``, ...; ``sensor=None`` means the only sensor of that stream in the window (TaskError when
    there are none or several). ``sensors(name)`` lists the sensors with samples.
    """

    streams: Mapping[str, Columns]
    spacecraft: Spacecraft
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

    def sensors(self, name: str) -> tuple[str, ...]:
        """Sensors of stream ``name`` with samples in the window, sorted (empty when none)."""
        cols = self.streams.get(name)
        if cols is None or len(cols["time_tai_ns"]) == 0:
            return ()
        names = set(np.asarray(cols["sensor"]).tolist())
        if not all(type(s) is str for s in names):  # bytes, numbers, numpy scalars: as their text
            names = set(np.asarray(cols["sensor"]).astype(str).tolist())
        return tuple(sorted(names))

    def _view(self, view: type[V], sensor: str | None) -> V:
        name = view.STREAM
        if sensor is None:
            present = self.sensors(name)
            if not present:
                raise TaskError(f"no {name} samples in the job window")
            if len(present) > 1:
                raise TaskError(f"several {name} sensors in the window ({', '.join(present)}): name the one to use")
            sensor = present[0]
        return view.from_columns(sensor, self.stream(name, sensor))

    def star_tracker(self, sensor: str | None = None) -> StarTrackerSamples:
        return self._view(StarTrackerSamples, sensor)

    def gyro(self, sensor: str | None = None) -> GyroSamples:
        return self._view(GyroSamples, sensor)

    def gyro_increments(self, sensor: str | None = None) -> GyroIncrementSamples:
        return self._view(GyroIncrementSamples, sensor)

    def gnss(self, sensor: str | None = None) -> GnssSamples:
        return self._view(GnssSamples, sensor)

    def magnetometer(self, sensor: str | None = None) -> MagnetometerSamples:
        return self._view(MagnetometerSamples, sensor)

    def sun_sensor(self, sensor: str | None = None) -> SunSensorSamples:
        return self._view(SunSensorSamples, sensor)

    def panel_currents(self, sensor: str | None = None) -> PanelCurrentSamples:
        return self._view(PanelCurrentSamples, sensor)

    def gnss_visibility(self, sensor: str | None = None) -> GnssVisibilitySamples:
        return self._view(GnssVisibilitySamples, sensor)

    def magnetorquer(self, sensor: str | None = None) -> MagnetorquerSamples:
        return self._view(MagnetorquerSamples, sensor)


@dataclass(frozen=True)
class TaskResult:
    """What a task returns: ``summary`` (JSON-able, units suffixed in key names), ``tables``
    (name -> equal-length column arrays; ``time_tai_ns`` columns are shown as UTC in exports),
    ``files`` (file name -> (content, media type), e.g. a CCSDS AEM the task wrote) and ``warnings``
    (:class:`ResultWarning`: what the data say about the result's own assumptions; the runner puts them
    first in the summary as ``warnings``)."""

    summary: dict[str, Any]
    tables: dict[str, dict[str, NDArray[Any]]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    files: dict[str, tuple[bytes, str]] = field(default_factory=dict)
    warnings: list[ResultWarning] = field(default_factory=list)


WARNING_CODES: dict[str, str] = {
    "quaternion_convention": "the star-tracker quaternions agree with the gyro only under another convention "
                             "(scalar-last order, the inverse direction or a transposed mounting)",
    "time_offset": "a significant time offset between two sensors' time tags",
    "correlated_residuals": "the residuals are not white: a sigma that assumes white noise would be too small",
    "outliers_removed": "samples were rejected as outliers before the estimate",
    "not_observable": "the data do not determine some parameters; they are reported as null",
    "bias_not_constant": "the gyro offsets change across the window: the constant-offset model does not hold",
    "filter_inconsistent": "the filter's innovations disagree with its own covariance (NIS or whiteness)",
    "implausible_input": "an input is far from what the sensor or the model can produce",
}
"""The stable warning codes of job results (README, "Warnings"): code -> what it means."""


@dataclass(frozen=True)
class ResultWarning:
    """A result's statement about itself: a stable ``code`` (:data:`WARNING_CODES`), a ``message`` that says
    what was found and what to do, and the ``evidence`` (JSON-able numbers: test statistics, thresholds)."""

    code: str
    message: str
    evidence: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.code not in WARNING_CODES:
            raise ValueError(f"unknown warning code {self.code!r}; codes: {', '.join(sorted(WARNING_CODES))}")

    def as_dict(self) -> dict[str, Any]:
        return {"code": self.code, "message": self.message, "evidence": dict(self.evidence)}
