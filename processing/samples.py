"""Typed views of the telemetry streams (processing.streams): one frozen dataclass per stream.

A view holds one sensor's samples in time order (stable sort of the stored rows): ``time_tai_ns``
int64 (N,) and the value columns stacked into arrays whose names carry frame and unit, e.g.
``StarTrackerSamples.q_IS`` (N, 4) from q0..q3 (scalar first, as stored: not renormalised),
``GyroSamples.w_G_rad_s`` (N, 3) from wx, wy, wz. :class:`processing.tasks.TaskInputs` builds them
(``inputs.star_tracker(sensor)``, ``inputs.gyro()``, ...); ``from_columns`` builds one from a stream's
columns. Arrays are read-only.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, ClassVar, TypeVar

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

Columns = Mapping[str, NDArray[Any]]
S = TypeVar("S", bound="Samples")


def sensor_index(values: ArrayLike) -> tuple[list[str], NDArray[np.intp]]:
    """The distinct names in a ``sensor`` column, sorted, and each row's position among them.

    One hash pass over the column (``pandas.factorize``) instead of converting every row to a numpy string:
    a day of 10 Hz gyro rows took ~0.1 s per conversion, and several steps of a job did one each."""
    codes, uniques = pd.factorize(np.asarray(values, dtype=object), use_na_sentinel=False)
    names = [str(u) for u in uniques]
    order = sorted(range(len(names)), key=names.__getitem__)
    rank = np.empty(len(names), dtype=np.intp)
    rank[order] = np.arange(len(names), dtype=np.intp)
    return [names[i] for i in order], rank[codes]


class SamplesError(ValueError):
    """Stream columns that do not make a view (a missing column or unequal lengths)."""


@dataclass(frozen=True, eq=False)
class Samples:
    """Base of the views: ``sensor`` and ``time_tai_ns`` (N,); subclasses declare ``COLUMNS``:
    field -> (stored columns, dtype); one stored column gives an (N,) field, several an (N, k) one."""

    STREAM: ClassVar[str] = ""
    COLUMNS: ClassVar[dict[str, tuple[tuple[str, ...], Any]]] = {}

    sensor: str
    time_tai_ns: NDArray[np.int64]

    def __post_init__(self) -> None:
        n = np.shape(self.time_tai_ns)[0] if np.ndim(self.time_tai_ns) == 1 else -1
        if n < 0:
            raise SamplesError(f"{self.STREAM}: time_tai_ns must be 1-D, got shape {np.shape(self.time_tai_ns)}")
        for f in fields(self):
            if f.name == "sensor":
                continue
            dtype = np.int64 if f.name == "time_tai_ns" else self.COLUMNS[f.name][1]
            value = np.array(getattr(self, f.name), dtype=dtype)
            if value.shape[:1] != (n,):
                raise SamplesError(f"{self.STREAM}: {f.name} has shape {value.shape}, expected {n} rows")
            value.setflags(write=False)
            object.__setattr__(self, f.name, value)

    def __len__(self) -> int:
        return int(self.time_tai_ns.shape[0])

    @classmethod
    def from_columns(cls: type[S], sensor: str, columns: Columns) -> S:
        """The view of one sensor's rows of a stream (``columns`` already restricted to that sensor)."""
        missing = [c for names, _ in cls.COLUMNS.values() for c in names if c not in columns]
        if "time_tai_ns" not in columns or missing:
            raise SamplesError(f"{cls.STREAM} columns lack {', '.join(missing or ['time_tai_ns'])}")
        t = np.asarray(columns["time_tai_ns"], dtype=np.int64)
        order = np.argsort(t, kind="stable")
        values: dict[str, Any] = {}
        for name, (stored, dtype) in cls.COLUMNS.items():
            cols = [np.asarray(columns[c], dtype=dtype)[order] for c in stored]
            values[name] = cols[0] if len(cols) == 1 else np.stack(cols, axis=1)
        return cls(sensor=sensor, time_tai_ns=t[order], **values)


_F = np.float64


@dataclass(frozen=True, eq=False)
class StarTrackerSamples(Samples):
    """q_IS (N, 4): sensor -> inertial, scalar first."""

    STREAM: ClassVar[str] = "star_tracker"
    COLUMNS: ClassVar[dict[str, tuple[tuple[str, ...], Any]]] = {"q_IS": (("q0", "q1", "q2", "q3"), _F)}
    q_IS: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class GyroSamples(Samples):
    """w_G_rad_s (N, 3): angular rate in the gyro frame."""

    STREAM: ClassVar[str] = "gyro"
    COLUMNS: ClassVar[dict[str, tuple[tuple[str, ...], Any]]] = {"w_G_rad_s": (("wx", "wy", "wz"), _F)}
    w_G_rad_s: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class GyroIncrementSamples(Samples):
    """da_G_rad (N, 3): angle increments in the gyro frame over interval_s (N,) ending at the time."""

    STREAM: ClassVar[str] = "gyro_increments"
    COLUMNS: ClassVar[dict[str, tuple[tuple[str, ...], Any]]] = {"da_G_rad": (("dax", "day", "daz"), _F),
                                                                 "interval_s": (("interval_s",), _F)}
    da_G_rad: NDArray[np.float64]
    interval_s: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class GnssSamples(Samples):
    """r_E_m, v_E_m_s (N, 3): ITRF position and velocity."""

    STREAM: ClassVar[str] = "gnss"
    COLUMNS: ClassVar[dict[str, tuple[tuple[str, ...], Any]]] = {"r_E_m": (("x", "y", "z"), _F),
                                                                 "v_E_m_s": (("vx", "vy", "vz"), _F)}
    r_E_m: NDArray[np.float64]
    v_E_m_s: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class MagnetometerSamples(Samples):
    """b_M_nT (N, 3): magnetic field in the magnetometer frame."""

    STREAM: ClassVar[str] = "magnetometer"
    COLUMNS: ClassVar[dict[str, tuple[tuple[str, ...], Any]]] = {"b_M_nT": (("bx", "by", "bz"), _F)}
    b_M_nT: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SunSensorSamples(Samples):
    """s_S (N, 3): unit sun direction in the sun-sensor frame."""

    STREAM: ClassVar[str] = "sun_sensor"
    COLUMNS: ClassVar[dict[str, tuple[tuple[str, ...], Any]]] = {"s_S": (("sx", "sy", "sz"), _F)}
    s_S: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class PanelCurrentSamples(Samples):
    """panel (N,) index into the configured solar panels, current_a (N,)."""

    STREAM: ClassVar[str] = "panel_currents"
    COLUMNS: ClassVar[dict[str, tuple[tuple[str, ...], Any]]] = {"panel": (("panel",), np.int64),
                                                                 "current_a": (("current_a",), _F)}
    panel: NDArray[np.int64]
    current_a: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class GnssVisibilitySamples(Samples):
    """system (N,) str, prn (N,) int, visible (N,) bool: which navigation satellites are tracked."""

    STREAM: ClassVar[str] = "gnss_visibility"
    COLUMNS: ClassVar[dict[str, tuple[tuple[str, ...], Any]]] = {"system": (("system",), object),
                                                                 "prn": (("prn",), np.int64),
                                                                 "visible": (("visible",), np.bool_)}
    system: NDArray[np.object_]
    prn: NDArray[np.int64]
    visible: NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class MagnetorquerSamples(Samples):
    """m_B_A_m2 (N, 3): commanded dipole in the body frame."""

    STREAM: ClassVar[str] = "magnetorquer"
    COLUMNS: ClassVar[dict[str, tuple[tuple[str, ...], Any]]] = {"m_B_A_m2": (("mx", "my", "mz"), _F)}
    m_B_A_m2: NDArray[np.float64]


VIEWS: dict[str, type[Samples]] = {v.STREAM: v for v in (
    StarTrackerSamples, GyroSamples, GyroIncrementSamples, GnssSamples, MagnetometerSamples, SunSensorSamples,
    PanelCurrentSamples, GnssVisibilitySamples, MagnetorquerSamples)}
"""Stream name -> view class (every stream of processing.streams)."""
