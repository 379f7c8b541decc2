"""Canonical telemetry stream schemas (DESIGN.md, "Telemetry streams").

Pure data: column names, dtypes and units of every stream the service ingests. Storage, the API and
the simulators all use these names, so they are public API. Inside the service every stream table
carries ``time_tai_ns`` (int64 nanoseconds since 1970-01-01T00:00:00 TAI, see
``processing.time.timescales``) and ``sensor`` besides the columns listed here; the HTTP edge calls the
time column ``time``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

ColumnKind = Literal["float", "int", "str", "bool"]

TIME_COLUMN = "time_tai_ns"
SENSOR_COLUMN = "sensor"


@dataclass(frozen=True)
class Column:
    """One value column: name, kind and unit (``""`` when dimensionless)."""

    name: str
    kind: ColumnKind = "float"
    unit: str = ""
    description: str = ""


@dataclass(frozen=True)
class StreamSpec:
    """Schema of one telemetry stream.

    ``key`` lists the columns besides (sensor, time) that identify a sample (e.g. the panel of a
    panel-current reading); ``sensor_kind`` names the spacecraft-configuration entry that lists the
    sensors of this stream (``None``: the stream has one implicit sensor named after the stream);
    ``unit_vector`` names column groups that must have unit norm (checked, then normalised).
    """

    name: str
    columns: tuple[Column, ...]
    description: str
    key: tuple[str, ...] = ()
    sensor_kind: str | None = None
    unit_vector: tuple[tuple[str, ...], ...] = field(default=())
    quaternion: tuple[str, ...] | None = None

    @property
    def column_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.columns)

    @property
    def key_columns(self) -> tuple[str, ...]:
        """Identity of a sample: (sensor, *key, time)."""
        return (SENSOR_COLUMN, *self.key, TIME_COLUMN)

    def column(self, name: str) -> Column:
        for c in self.columns:
            if c.name == name:
                return c
        raise KeyError(name)


QUATERNION_COLUMNS = ("q0", "q1", "q2", "q3")

STREAMS: dict[str, StreamSpec] = {
    s.name: s
    for s in (
        StreamSpec(
            "star_tracker",
            tuple(Column(c, "float", "", "q_IS, scalar first") for c in QUATERNION_COLUMNS),
            "star-tracker attitude quaternion q_IS (sensor -> inertial), scalar first, unit norm",
            sensor_kind="star_trackers",
            quaternion=QUATERNION_COLUMNS,
        ),
        StreamSpec(
            "gyro",
            tuple(Column(c, "float", "rad/s", "angular rate in the gyro frame") for c in ("wx", "wy", "wz")),
            "gyro angular rates, rad/s, gyro frame",
            sensor_kind="gyro",
        ),
        StreamSpec(
            "gyro_increments",
            (
                *(Column(c, "float", "rad", "angle increment") for c in ("dax", "day", "daz")),
                Column("interval_s", "float", "s", "integration interval ending at time"),
            ),
            "gyro angle increments, rad, over interval_s ending at the sample time",
            sensor_kind="gyro",
        ),
        StreamSpec(
            "gnss",
            (
                *(Column(c, "float", "m", "ITRF position") for c in ("x", "y", "z")),
                *(Column(c, "float", "m/s", "ITRF velocity") for c in ("vx", "vy", "vz")),
            ),
            "GNSS position and velocity, m and m/s, ITRF",
        ),
        StreamSpec(
            "magnetometer",
            tuple(Column(c, "float", "nT", "magnetic field, magnetometer frame") for c in ("bx", "by", "bz")),
            "magnetic field, nT, magnetometer frame",
            sensor_kind="magnetometer",
        ),
        StreamSpec(
            "sun_sensor",
            tuple(Column(c, "float", "", "sun direction, sensor frame") for c in ("sx", "sy", "sz")),
            "sun direction unit vector, sun-sensor frame",
            sensor_kind="sun_sensor",
            unit_vector=(("sx", "sy", "sz"),),
        ),
        StreamSpec(
            "panel_currents",
            (Column("panel", "int", "", "index into solar_panels"), Column("current_a", "float", "A")),
            "solar-panel currents, A, one row per panel and time",
            key=("panel",),
        ),
        StreamSpec(
            "gnss_visibility",
            (
                Column("system", "str", "", "navigation system letter (G, R, E, C, J, I, S)"),
                Column("prn", "int", "", "satellite number within the system"),
                Column("visible", "bool", "", "tracked by the receiver"),
            ),
            "which navigation satellites the GNSS receiver tracks",
            key=("system", "prn"),
        ),
        StreamSpec(
            "magnetorquer",
            tuple(Column(c, "float", "A m^2", "commanded dipole, body frame") for c in ("mx", "my", "mz")),
            "magnetorquer dipoles, A m^2",
        ),
    )
}

GNSS_SYSTEMS = ("G", "R", "E", "C", "J", "I", "S")
