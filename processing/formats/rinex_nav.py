"""RINEX 2 and 3 navigation files (broadcast ephemerides) parsed into flat columns.

Supported: RINEX 2.x GPS ("N") and GLONASS ("G") navigation files, RINEX 3.0x navigation files of
any system mix (GPS G, Galileo E, QZSS J, BeiDou C, IRNSS I: Keplerian records of 7 orbit lines;
GLONASS R and SBAS S: state-vector records of 3 orbit lines; RINEX 3.05 GLONASS records with a
4th line are accepted). Formats: RINEX 2.11 and 3.04 specifications (IGS/RTCM), field layouts of
their tables A4/A10 (2.11) and A8/A10/A12/A14/A16 (3.04).

One row per broadcast record. Columns (``NAV_COLUMNS``; fields that do not apply are NaN):

- ``system`` (str, one letter), ``prn`` (int), ``sat`` (str, e.g. "G01"),
- ``time_tai_ns``: the record's epoch (toc for Keplerian systems, tb for GLONASS/SBAS) as tai_ns,
  read on the system's time scale: GPST, GST and QZSST = TAI - 19 s, BDT = TAI - 33 s, GLONASS and
  SBAS epochs in RINEX are UTC;
- ``ref_tai_ns``: the orbit reference time (toe for Keplerian systems, tb for state vectors);
- clock: ``af0_s``, ``af1_s_s``, ``af2_s_s2`` (GLONASS: ``af0_s`` = -TauN, ``af1_s_s`` = GammaN);
- Keplerian: ``iode``, ``crs_m``, ``delta_n_rad_s``, ``m0_rad``, ``cuc_rad``, ``e``, ``cus_rad``,
  ``sqrt_a_sqrt_m``, ``toe_s`` (seconds of the system week), ``cic_rad``, ``omega0_rad``, ``cis_rad``,
  ``i0_rad``, ``crc_m``, ``omega_rad``, ``omega_dot_rad_s``, ``idot_rad_s``, ``week``, ``health``;
- state vector (GLONASS, SBAS; converted from km to m): ``x_m``, ``y_m``, ``z_m``, ``vx_m_s``,
  ``vy_m_s``, ``vz_m_s``, ``ax_m_s2``, ``ay_m_s2``, ``az_m_s2``, ``health``, ``freq_channel``.

Pure: bytes in, arrays out. Malformed files raise :class:`RinexNavError` naming the line.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from processing.orbits.gnss_systems import DEFAULT_MAX_AGE_S, KEPLER_SYSTEMS
from processing.tasks import ParsedReference
from processing.time import timescales
from processing.units import NS_PER_S

GPS_MINUS_TAI_NS = -19 * NS_PER_S
BDT_MINUS_TAI_NS = -33 * NS_PER_S
_ORBIT_LINES = {"G": 7, "E": 7, "J": 7, "C": 7, "I": 7, "R": 3, "S": 3}
# Field order of the 7 Keplerian "broadcast orbit" lines (4 fields each, 28 in all).
_KEPLER_FIELDS = (
    "iode", "crs_m", "delta_n_rad_s", "m0_rad",
    "cuc_rad", "e", "cus_rad", "sqrt_a_sqrt_m",
    "toe_s", "cic_rad", "omega0_rad", "cis_rad",
    "i0_rad", "crc_m", "omega_rad", "omega_dot_rad_s",
    "idot_rad_s", "_codes_l2", "week", "_l2p",
    "_accuracy", "health", "_tgd", "_iodc",
    "_transmission_time", "_fit_interval", "_spare1", "_spare2",
)
_STATE_FIELDS = (
    "x_km", "vx_km_s", "ax_km_s2", "health",
    "y_km", "vy_km_s", "ay_km_s2", "freq_channel",
    "z_km", "vz_km_s", "az_km_s2", "_age",
)
NAV_COLUMNS = (
    "system", "prn", "sat", "time_tai_ns", "ref_tai_ns", "af0_s", "af1_s_s", "af2_s_s2",
    *(f for f in _KEPLER_FIELDS if not f.startswith("_") and f != "health"), "health",
    "x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s", "ax_m_s2", "ay_m_s2", "az_m_s2", "freq_channel",
)
_FLOAT_COLUMNS = tuple(c for c in NAV_COLUMNS if c not in ("system", "prn", "sat", "time_tai_ns", "ref_tai_ns"))


class RinexNavError(ValueError):
    """Not a RINEX navigation file, or a malformed record (the message names the line)."""


@dataclass(frozen=True)
class RinexNav:
    """Parsed navigation file: ``columns`` (see the module docstring) and header facts."""

    version: float
    file_system: str
    columns: dict[str, NDArray[Any]]
    leap_seconds: int | None

    @property
    def n_records(self) -> int:
        return int(self.columns["prn"].size)


def _num(text: str, line_no: int) -> float:
    s = text.strip()
    if not s:
        return float("nan")
    try:
        return float(s.replace("D", "E").replace("d", "e"))
    except ValueError:
        raise RinexNavError(f"line {line_no}: expected a number, got {s!r}") from None


def _fields(line: str, start: int, count: int, line_no: int) -> list[float]:
    return [_num(line[start + 19 * k: start + 19 * (k + 1)], line_no) for k in range(count)]


def _epoch_tai_ns(system: str, y: int, mo: int, d: int, h: int, mi: int, sec: float, line_no: int) -> int:
    whole = int(np.floor(sec))
    frac_ns = int(round((sec - whole) * NS_PER_S))
    try:
        stamp = np.datetime64(f"{y:04d}-{mo:02d}-{d:02d}T{h:02d}:{mi:02d}:00", "ns")
    except ValueError:
        raise RinexNavError(f"line {line_no}: bad epoch {y}-{mo}-{d} {h}:{mi}:{sec}") from None
    reading = int(stamp.astype(np.int64)) + whole * NS_PER_S + frac_ns
    if system in ("R", "S"):
        return int(timescales.epoch_ns_to_tai_ns(np.array([reading], np.int64), "utc")[0])
    if system == "C":
        return reading - BDT_MINUS_TAI_NS
    return reading - GPS_MINUS_TAI_NS


def week_seconds_to_tai_ns(system: str, week: NDArray[Any], seconds: NDArray[Any]) -> NDArray[np.int64]:
    """tai_ns of (week, seconds of week) on a system's scale: GPS/GAL/QZSS/IRNSS weeks count from
    1980-01-06 GPST (RINEX gives continuous GPS weeks for G, E, J, I), BeiDou weeks from 2006-01-01 BDT."""
    week = np.asarray(week, dtype=np.float64)
    seconds = np.asarray(seconds, dtype=np.float64)
    if system == "C":
        origin = int(np.datetime64("2006-01-01T00:00:00", "ns").astype(np.int64)) - BDT_MINUS_TAI_NS
    else:
        origin = int(np.datetime64("1980-01-06T00:00:00", "ns").astype(np.int64)) - GPS_MINUS_TAI_NS
    ns = origin + np.round(week * 604800.0 * NS_PER_S) + np.round(seconds * NS_PER_S)
    return ns.astype(np.int64)


def _header(lines: list[str]) -> tuple[float, str, int | None, int]:
    if not lines or "RINEX VERSION / TYPE" not in lines[0][60:]:
        raise RinexNavError("line 1: expected a RINEX header ('RINEX VERSION / TYPE' in columns 61-80)")
    first = lines[0]
    try:
        version = float(first[:9])
    except ValueError:
        raise RinexNavError(f"line 1: bad RINEX version {first[:9]!r}") from None
    file_type = first[20:21].upper()
    if file_type not in ("N", "G"):
        raise RinexNavError(f"line 1: file type {first[20]!r} is not navigation data (N or G)")
    if version < 3:
        system = "R" if file_type == "G" else "G"
    else:
        system = first[40:41].upper() or "M"
    leap = None
    for i, line in enumerate(lines):
        label = line[60:].strip()
        if label == "LEAP SECONDS":
            try:
                leap = int(line[:6])
            except ValueError:
                leap = None
        if label == "END OF HEADER":
            return version, system, leap, i + 1
    raise RinexNavError("no 'END OF HEADER' line")


def parse_rinex_nav(raw: bytes | str) -> RinexNav:
    """Parse a RINEX 2.x (GPS or GLONASS) or 3.x (any systems) navigation file.

    raw: file content (bytes, ASCII). Returns :class:`RinexNav` with one row per record, sorted by
    (sat, time). Records of unknown systems are skipped; a record with missing or garbled lines raises
    :class:`RinexNavError` naming the line.
    """
    text = raw.decode("ascii", errors="replace") if isinstance(raw, bytes) else raw
    lines = text.splitlines()
    version, file_system, leap, i = _header(lines)
    rows: list[dict[str, Any]] = []
    while i < len(lines):
        if not lines[i].strip():
            i += 1
            continue
        start = _record_start(lines[i], i + 1, version, file_system)
        values = _orbit_values(lines, i, start)
        i += start.n_lines + 1
        rows.append(_record_row(start, values))
    if not rows:
        raise RinexNavError("the file has a header but no navigation records")
    rows.sort(key=lambda r: (r["sat"], r["time_tai_ns"]))
    return RinexNav(version=version, file_system=file_system, columns=_columns(rows), leap_seconds=leap)


@dataclass(frozen=True)
class _RecordStart:
    """The first line of a record: system, PRN, epoch (year, month, day, hour, minute, second on the
    system's scale), the three clock fields, the column where the orbit lines' fields start, the number
    of orbit lines, and the line number (1-based)."""

    system: str
    prn: int
    epoch: tuple[int, int, int, int, int, float]
    clock: list[float]
    field_start: int
    n_lines: int
    line_no: int


def _record_start(line: str, line_no: int, version: float, file_system: str) -> _RecordStart:
    if version >= 3:
        system = line[0].upper()
        if system not in _ORBIT_LINES:
            raise RinexNavError(f"line {line_no}: expected a record start 'Snn YYYY MM DD ...', got {line[:23]!r}")
        try:
            prn = int(line[1:3])
            y, mo, d, h, mi, s = (int(line[4:8]), int(line[9:11]), int(line[12:14]), int(line[15:17]),
                                  int(line[18:20]), float(line[21:23]))
        except ValueError:
            raise RinexNavError(f"line {line_no}: bad record start {line[:23]!r}") from None
        clock = _fields(line, 23, 3, line_no)
        field_start = 4
    else:
        system = file_system
        try:
            prn = int(line[0:2])
            yy = int(line[2:5])
            y = yy + (1900 if yy >= 80 else 2000)
            mo, d, h, mi = int(line[5:8]), int(line[8:11]), int(line[11:14]), int(line[14:17])
            s = float(line[17:22])
        except ValueError:
            raise RinexNavError(f"line {line_no}: bad record start {line[:22]!r}") from None
        clock = _fields(line, 22, 3, line_no)
        field_start = 3
    n_lines = 4 if version >= 3.05 and system == "R" else _ORBIT_LINES[system]
    return _RecordStart(system, prn, (y, mo, d, h, mi, s), clock, field_start, n_lines, line_no)


def _orbit_values(lines: list[str], i: int, start: _RecordStart) -> list[float]:
    """The 4 fields of each orbit line after the record start at line index i."""
    values: list[float] = []
    for k in range(1, start.n_lines + 1):
        if i + k >= len(lines):
            raise RinexNavError(f"line {start.line_no}: record of {start.system}{start.prn:02d} is truncated "
                                f"(expected {start.n_lines} orbit lines)")
        values += _fields(lines[i + k].ljust(start.field_start + 76), start.field_start, 4, i + k + 1)
    return values


def _record_row(start: _RecordStart, values: list[float]) -> dict[str, Any]:
    """One row of the columns: Keplerian fields or the state vector (km -> m)."""
    system, clock = start.system, start.clock
    row: dict[str, Any] = {"system": system, "prn": start.prn, "sat": f"{system}{start.prn:02d}",
                           "time_tai_ns": _epoch_tai_ns(system, *start.epoch, start.line_no)}
    if system in KEPLER_SYSTEMS:
        row.update(af0_s=clock[0], af1_s_s=clock[1], af2_s_s2=clock[2])
        row.update({name: v for name, v in zip(_KEPLER_FIELDS, values, strict=False) if not name.startswith("_")})
        if not (np.isfinite(row["week"]) and np.isfinite(row["toe_s"]) and np.isfinite(row["sqrt_a_sqrt_m"])):
            raise RinexNavError(f"line {start.line_no}: record of {row['sat']} lacks toe, week or sqrt(A)")
        row["ref_tai_ns"] = int(week_seconds_to_tai_ns(system, np.array(row["week"]), np.array(row["toe_s"])))
        return row
    row.update(af0_s=clock[0], af1_s_s=clock[1], af2_s_s2=float("nan"))
    st = dict(zip(_STATE_FIELDS, values, strict=False))
    for axis in "xyz":
        row[f"{axis}_m"] = st[f"{axis}_km"] * 1e3
        row[f"v{axis}_m_s"] = st[f"v{axis}_km_s"] * 1e3
        row[f"a{axis}_m_s2"] = st[f"a{axis}_km_s2"] * 1e3
    row["health"] = st["health"]
    row["freq_channel"] = st["freq_channel"] if system == "R" else float("nan")
    row["ref_tai_ns"] = row["time_tai_ns"]
    return row


def _columns(rows: list[dict[str, Any]]) -> dict[str, NDArray[Any]]:
    columns: dict[str, NDArray[Any]] = {
        "system": np.array([r["system"] for r in rows], dtype=object),
        "prn": np.array([r["prn"] for r in rows], dtype=np.int64),
        "sat": np.array([r["sat"] for r in rows], dtype=object),
        "time_tai_ns": np.array([r["time_tai_ns"] for r in rows], dtype=np.int64),
        "ref_tai_ns": np.array([r["ref_tai_ns"] for r in rows], dtype=np.int64),
    }
    for name in _FLOAT_COLUMNS:
        columns[name] = np.array([float(r.get(name, np.nan)) for r in rows], dtype=np.float64)
    return columns


def parse_rinex_nav_reference(raw: bytes) -> ParsedReference:
    """Reference-data parser (kind "rinex_nav"): the columns of :func:`parse_rinex_nav` and the span
    they serve, from the first reference time minus to the last plus the validity of a record of the
    file's systems (processing.orbits.gnss_systems.DEFAULT_MAX_AGE_S)."""
    nav = parse_rinex_nav(raw)
    cols = nav.columns
    systems = sorted(set(cols["system"].tolist()))
    margin_ns = int(max(DEFAULT_MAX_AGE_S.get(s, 7200.0) for s in systems) * NS_PER_S)
    ref = cols["ref_tai_ns"]
    details = {"version": nav.version, "file_system": nav.file_system, "systems": systems,
               "n_records": nav.n_records, "n_satellites": len(set(cols["sat"].tolist())),
               "leap_seconds": nav.leap_seconds}
    return ParsedReference(columns=dict(cols), start_tai_ns=int(ref.min()) - margin_ns,
                           end_tai_ns=int(ref.max()) + margin_ns, details=details)
