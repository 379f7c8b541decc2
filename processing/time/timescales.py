"""Time scales: UTC, TAI, GPS and TT readings to and from one continuous integer count.

Every time inside the service is ``tai_ns``: an int64 count of SI nanoseconds since
1970-01-01T00:00:00 TAI. TAI is continuous, so a leap second is an ordinary second of it and is
never lost. This module converts user input (ISO 8601 strings, float seconds, integer nanoseconds
read on a stated scale) into ``tai_ns`` and back, and gives two-part Julian dates for ERFA.

Rules (DESIGN.md, "Time"):

- TT = TAI + 32.184 s (IAU 1991 / IERS Conventions 2010, sec. 5.1).
- GPS = TAI - 19 s (GPS time was equal to UTC at 1980-01-06T00:00:00 UTC, when TAI-UTC was 19 s).
- UTC = TAI - (TAI-UTC), with TAI-UTC from ERFA's leap-second table (``erfa.leap_seconds.get()``,
  the IERS Bulletin C history), read at each call so a table updated through pyerfa is honoured.
  UTC before 1972-01-01, when TAI-UTC was not an integer number of seconds, is rejected.
  After the table's last entry the last offset applies, as in ERFA's ``eraDat``; this module never
  calls ``eraDat`` itself, so no "dubious year" warning is raised for any date.

A *reading* on a scale is the calendar date and clock time that scale shows. For TAI, GPS and TT a
reading is an exact affine function of ``tai_ns``. For UTC the reading of an instant inside a leap
second is 23:59:60.x, which no POSIX count can express: see :func:`tai_ns_to_seconds`.

All functions are vectorised (no Python loop over samples), keep the input's shape, and raise
:class:`TimeValueError` listing the bad rows (flattened indices) after checking the whole array.
"""

from __future__ import annotations

from typing import Any

import erfa
import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from processing.units import NS_PER_DAY, NS_PER_S, S_PER_DAY

SCALES = ("utc", "tai", "gps", "tt")
TT_MINUS_TAI_S = 32.184
TT_MINUS_TAI_NS = 32_184_000_000
TAI_MINUS_GPS_S = 19
TAI_MINUS_GPS_NS = TAI_MINUS_GPS_S * NS_PER_S
UNIX_EPOCH_JD = 2440587.5
"""Julian date of 1970-01-01T00:00:00 on the scale at hand."""
FIRST_INTEGER_UTC = "1972-01-01"
"""Earliest UTC accepted: from then on TAI-UTC is a whole number of seconds."""
YEAR_MIN, YEAR_MAX = 1678, 2261
"""Calendar years whose readings fit int64 nanoseconds (the datetime64[ns] range)."""

_MAX_REPORTED_ROWS = 100
_ROWS_IN_MESSAGE = 5
_ISO_EXPECTED = (
    "ISO 8601 'YYYY-MM-DDTHH:MM:SS[.fffffffff]' (T or space; up to 9 fractional digits) with 'Z', "
    "'+HH:MM' or no zone"
)
# Scale reading minus TAI, for the scales that are a fixed offset from TAI.
_READING_MINUS_TAI_NS = {"tai": 0, "gps": -TAI_MINUS_GPS_NS, "tt": TT_MINUS_TAI_NS}


class TimeValueError(ValueError):
    """Bad time input: the message names the first bad rows and what was expected.

    ``rows`` holds (flattened row index, reason) of the first 100 bad rows; it is empty when the
    whole argument is wrong (unknown scale, wrong dtype).
    """

    def __init__(self, message: str, rows: list[tuple[int, str]] | None = None) -> None:
        super().__init__(message)
        self.rows: list[tuple[int, str]] = list(rows or [])


# --------------------------------------------------------------------------------------------
# Helpers: calendar arithmetic, the leap-second table, error reporting.


def _days_from_civil(y: NDArray[np.int64], m: NDArray[np.int64], d: NDArray[np.int64]) -> NDArray[np.int64]:
    """Days since 1970-01-01 of proleptic Gregorian dates (H. Hinnant, "chrono-Compatible
    Low-Level Date Algorithms", days_from_civil); arrays of int64."""
    y = y - (m <= 2)
    era = y // 400
    yoe = y - era * 400
    doy = (153 * ((m + 9) % 12) + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146097 + doe - 719468


def _civil_from_days(z: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Inverse of :func:`_days_from_civil` (Hinnant, civil_from_days): (year, month, day)."""
    z = z + 719468
    era = z // 146097
    doe = z - era * 146097
    yoe = (doe - doe // 1460 + doe // 36524 - doe // 146096) // 365
    doy = doe - (365 * yoe + yoe // 4 - yoe // 100)
    mp = (5 * doy + 2) // 153
    d = doy - (153 * mp + 2) // 5 + 1
    m = np.where(mp < 10, mp + 3, mp - 9)
    return yoe + era * 400 + (m <= 2), m, d


class _LeapTable:
    """ERFA's leap-second table from 1972 on, as nanosecond breakpoints.

    ``start_ns[k]``: UTC reading (POSIX ns) at which TAI-UTC becomes ``off_ns[k]``;
    ``tai_start_ns[k]``: the same instant as tai_ns; ``next_start_ns[k]``/``step_ns[k]``: the next
    breakpoint (int64 max after the last) and the change of TAI-UTC there (a leap second if > 0).
    """

    def __init__(self) -> None:
        table = erfa.leap_seconds.get()
        table = table[table["year"] >= 1972]
        off_s = table["tai_utc"]
        if np.any(off_s != np.round(off_s)):
            raise RuntimeError("ERFA leap-second table has a non-integer TAI-UTC after 1972")
        one = np.ones(len(table), dtype=np.int64)
        days = _days_from_civil(table["year"].astype(np.int64), table["month"].astype(np.int64), one)
        self.start_ns = days * NS_PER_DAY
        self.off_ns = np.round(off_s).astype(np.int64) * NS_PER_S
        self.tai_start_ns = self.start_ns + self.off_ns
        self.next_start_ns = np.append(self.start_ns[1:], np.iinfo(np.int64).max)
        self.step_ns = np.append(np.diff(self.off_ns), 0)

    def utc_bucket(self, utc_ns: NDArray[np.int64]) -> NDArray[np.intp]:
        """Index of the table row in force at UTC readings (POSIX ns); -1 before 1972."""
        return np.searchsorted(self.start_ns, utc_ns, side="right") - 1

    def tai_bucket(self, tai_ns: NDArray[np.int64]) -> NDArray[np.intp]:
        """Index of the row in force at TAI instants; inside a leap second, the row before it."""
        return np.searchsorted(self.tai_start_ns, tai_ns, side="right") - 1


def _check_scale(scale: str) -> str:
    s = str(scale).lower()
    if s not in SCALES:
        raise TimeValueError(f"unknown time scale {scale!r}; expected one of {', '.join(SCALES)}")
    return s


def _as_int_ns(values: ArrayLike, what: str) -> NDArray[np.int64]:
    arr = np.asarray(values)
    if arr.dtype.kind not in "iu":
        raise TimeValueError(f"{what} must be integer nanoseconds (int64); got dtype {arr.dtype}")
    return arr.astype(np.int64, copy=False)


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _raise_rows(rows: list[tuple[int, str]], n_bad: int, n_total: int, expected: str) -> None:
    shown = "; ".join(f"row {i}: {reason}" for i, reason in rows[:_ROWS_IN_MESSAGE])
    more = f"; and {n_bad - _ROWS_IN_MESSAGE} more" if n_bad > _ROWS_IN_MESSAGE else ""
    raise TimeValueError(f"{n_bad} of {n_total} time values invalid: {shown}{more}. Expected {expected}.", rows)


def _report_codes(codes: NDArray[np.int8], reason: Any, expected: str) -> None:
    """Raise one TimeValueError for all rows with a nonzero code; ``reason(i, code)`` -> str
    is called for the first 100 bad rows only."""
    bad = np.flatnonzero(codes)
    if bad.size:
        rows = [(int(i), reason(int(i), int(codes[i]))) for i in bad[:_MAX_REPORTED_ROWS]]
        _raise_rows(rows, int(bad.size), int(codes.size), expected)


def _utc_to_tai(
    utc_ns: NDArray[np.int64], table: _LeapTable, codes: NDArray[np.int8], pre1972_code: int
) -> NDArray[np.int64]:
    """TAI of POSIX UTC readings (no leap seconds in ``utc_ns``); marks pre-1972 rows in codes."""
    k = table.utc_bucket(utc_ns)
    codes[(k < 0) & (codes == 0)] = pre1972_code
    return utc_ns + table.off_ns[np.maximum(k, 0)]


def _tai_to_utc_parts(
    tai_ns: NDArray[np.int64], table: _LeapTable
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.intp]]:
    """UTC (day since 1970, ns of day, table row) of TAI instants; ns of day >= 86400 s inside a
    leap second. Raises for instants before 1972-01-01 UTC."""
    k = table.tai_bucket(tai_ns)
    if np.any(k < 0):
        flat = np.ravel(k < 0)
        _report_codes(
            flat.astype(np.int8),
            lambda i, c: f"tai_ns {int(np.ravel(tai_ns)[i])} is before {FIRST_INTEGER_UTC} UTC",
            f"instants from {FIRST_INTEGER_UTC}T00:00:00 UTC on (UTC before then is not supported)",
        )
    u = tai_ns - table.off_ns[k]
    in_leap = u >= table.next_start_ns[k]  # only possible when step > 0: the 23:59:60 second
    day = u // NS_PER_DAY - in_leap
    return day, u - day * NS_PER_DAY, k


def _jd_from_ns(reading_ns: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    day = reading_ns // NS_PER_DAY
    return UNIX_EPOCH_JD + day.astype(np.float64), (reading_ns - day * NS_PER_DAY) / NS_PER_DAY


# --------------------------------------------------------------------------------------------
# ISO 8601 strings.

_E_EMPTY, _E_MISSING, _E_SYNTAX, _E_DIGITS, _E_FIELD, _E_YEAR = 1, 2, 3, 4, 5, 6
_E_LEAP_SCALE, _E_PRE1972, _E_LEAP_TIME, _E_LEAP_DAY = 7, 8, 9, 10
_WIDTH = 36  # longest valid string is 35 characters: 19 + '.' + 9 digits + '+HH:MM'
_FIELD_LIMITS = (("month", 1, 12), ("day", 1, 31), ("hour", 0, 23), ("minute", 0, 59), ("second", 0, 60),
                 ("zone hour", 0, 23), ("zone minute", 0, 59))


def _scan_iso(text: NDArray[np.str_]) -> tuple[NDArray[np.bool_], NDArray[np.bool_], dict[str, NDArray[Any]]]:
    """Read the fields of ISO 8601 strings (a 1-D numpy array of dtype U36).

    Returns (syntax_ok, too_many_fraction_digits, fields); the fields are int32/int64 arrays,
    meaningless where syntax_ok is False: year, month, day, hour, minute, second (0-99 unchecked),
    frac_ns, zone hour, zone minute, zone_s (signed offset of the zone from the scale, s).
    """
    n = text.shape[0]
    wide = text.view(np.uint32).reshape(n, _WIDTH)
    ok = wide.max(axis=1, initial=0) < 128
    chars = wide.astype(np.uint8)  # rows with non-ASCII characters are already rejected above
    length = np.char.str_len(text)  # counts embedded NULs, which then fail the checks below
    zero = np.uint8(ord("0"))

    def digit(c: int) -> NDArray[np.uint8]:
        return chars[:, c] - zero  # wraps to >= 10 for non-digits

    def pair(a: int, b: int) -> NDArray[np.int32]:
        return digit(a).astype(np.int32) * 10 + digit(b)

    def is_(c: int, *options: str) -> NDArray[np.bool_]:
        hit = chars[:, c] == ord(options[0])
        for o in options[1:]:
            hit |= chars[:, c] == ord(o)
        return hit

    for c in (0, 1, 2, 3, 5, 6, 8, 9, 11, 12, 14, 15, 17, 18):
        ok &= digit(c) < 10
    ok &= is_(4, "-") & is_(7, "-") & is_(10, "T", "t", " ") & is_(13, ":") & is_(16, ":") & (length >= 19)
    # Fraction: '.' or ',' then 1-9 digits.
    has_frac = is_(19, ".", ",")
    running = has_frac.copy()
    n_frac = np.zeros(n, dtype=np.int8)
    frac_ns = np.zeros(n, dtype=np.int32)
    for j in range(9):
        d = digit(20 + j)
        running &= d < 10
        n_frac += running
        frac_ns += np.where(running, d, zero - zero) * np.int32(10 ** (8 - j))
    too_many = running & (digit(29) < 10)
    ok &= ~has_frac | (n_frac >= 1)
    # Zone after the fraction: '', 'Z', '+HH', '+HHMM', '+HH:MM' (or '-'); z0 + 5 <= 34 always.
    z0 = 19 + np.where(has_frac, 1 + n_frac, 0)
    zlen = length - z0
    zone = chars.reshape(-1)[(np.arange(n, dtype=np.int64) * _WIDTH + z0)[:, None] + np.arange(6)]
    zd = zone - zero
    zdig = zd < 10
    is_z = (zlen == 1) & ((zone[:, 0] == ord("Z")) | (zone[:, 0] == ord("z")))
    minus = zone[:, 0] == ord("-")
    signed = ((zone[:, 0] == ord("+")) | minus) & zdig[:, 1] & zdig[:, 2]
    hhmm = signed & (zlen == 5) & zdig[:, 3] & zdig[:, 4]
    hh_mm = signed & (zlen == 6) & (zone[:, 3] == ord(":")) & zdig[:, 4] & zdig[:, 5]
    ok &= (zlen == 0) | is_z | (signed & (zlen == 3)) | hhmm | hh_mm
    zd = zd.astype(np.int32)
    zone_h = np.where(signed, zd[:, 1] * 10 + zd[:, 2], 0)
    zone_m = np.where(hhmm, zd[:, 3] * 10 + zd[:, 4], 0) + np.where(hh_mm, zd[:, 4] * 10 + zd[:, 5], 0)
    zone_s = (zone_h * 3600 + zone_m * 60) * np.where(minus, -1, 1)
    fields = {"year": pair(0, 1) * 100 + pair(2, 3), "month": pair(5, 6), "day": pair(8, 9),
              "hour": pair(11, 12), "minute": pair(14, 15), "second": pair(17, 18),
              "zone hour": zone_h, "zone minute": zone_m, "zone_s": zone_s, "frac_ns": frac_ns, "length": length}
    return ok, too_many, fields


def _days_in_month(year: int, month: int) -> int:
    leap = year % 4 == 0 and (year % 100 != 0 or year % 400 == 0)
    return [31, 29 if leap else 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31][month - 1]


def _iso_reason(i: int, code: int, raw: NDArray[Any], f: dict[str, NDArray[np.int64]], scale: str) -> str:
    v = raw[i]
    if code == _E_EMPTY:
        return "empty time"
    if code == _E_MISSING:
        return "NaN time" if isinstance(v, float) else f"missing time ({_short(v)})"
    text = _short(str(v))
    if code == _E_SYNTAX:
        return f"{text} is not an ISO 8601 time"
    if code == _E_DIGITS:
        return f"{text} has more than 9 fractional digits"
    if code == _E_FIELD:
        for name, lo, hi in _FIELD_LIMITS:
            if name == "day" and 1 <= f["month"][i] <= 12:
                hi = _days_in_month(int(f["year"][i]), int(f["month"][i]))
            if not lo <= f[name][i] <= hi:
                return f"{text} is not an ISO 8601 time ({name} {int(f[name][i])} out of range {lo}-{hi})"
        return f"{text} is not an ISO 8601 time"
    if code == _E_YEAR:
        return f"{text} is outside the supported years {YEAR_MIN}-{YEAR_MAX}"
    if code == _E_LEAP_SCALE:
        return f"{text} has second 60, which only UTC has (scale {scale} has no leap seconds)"
    if code == _E_PRE1972:
        return f"{text} is before {FIRST_INTEGER_UTC} UTC, when TAI-UTC was not a whole number of seconds"
    if code == _E_LEAP_TIME:
        return f"{text} has second 60 outside 23:59:60 UTC"
    y, m, d = _civil_from_days(f["at59_ns"][i : i + 1] // NS_PER_DAY)
    return f"23:59:60 on {int(y[0]):04d}-{int(m[0]):02d}-{int(d[0]):02d} is not a leap second"


def iso_to_tai_ns(values: ArrayLike, scale: str = "utc") -> NDArray[np.int64]:
    """Parse ISO 8601 times read on ``scale`` into tai_ns.

    values: array-like of str, any shape (list, numpy str/object array, pandas Series).
    Format 'YYYY-MM-DDTHH:MM:SS[.fffffffff]' (1 to 9 fractional digits; 'T', 't' or a space between
    date and time; '.' or ',' before the fraction) followed by 'Z', '+HH:MM', '+HHMM', '+HH' (or '-')
    or nothing. No zone means the scale itself; a zone offset is subtracted (local time minus
    offset = reading on the scale). For scale "utc", 23:59:60[.f] is accepted exactly during a leap
    second of the ERFA table (checked after applying the zone), and dates before 1972-01-01 are
    rejected. For "tai", "gps", "tt" the string is a calendar reading on that scale (no second 60).
    Years 1678-2261 (the int64-nanosecond range).

    Returns int64 tai_ns of the input's shape. Every bad row (empty, missing, garbage, out-of-range
    field, a second 60 that is not a leap second, ...) is collected and reported in one
    :class:`TimeValueError`; row indices are into the flattened input.
    """
    scale = _check_scale(scale)
    is_str_array = isinstance(values, np.ndarray) and values.dtype.kind == "U"
    raw = values if is_str_array else np.asarray(values, dtype=object)
    shape = raw.shape
    raw = raw.reshape(-1)
    n = raw.size
    missing = np.zeros(n, dtype=bool) if is_str_array else np.asarray(pd.isna(raw), dtype=bool)
    text = raw
    if missing.any():
        text = raw.copy()
        text[missing] = ""
    ok, too_many, f = _scan_iso(text.astype(f"U{_WIDTH}"))
    y, mo, d = f["year"], f["month"], f["day"]
    year_ok = (y >= YEAR_MIN) & (y <= YEAR_MAX)
    dim = np.array([31, 29, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31])[np.clip(mo - 1, 0, 11)]
    fields_ok = (mo >= 1) & (mo <= 12) & (d >= 1) & (d <= dim) & (f["hour"] <= 23) & (f["minute"] <= 59)
    fields_ok &= (f["second"] <= 60) & (f["zone hour"] <= 23) & (f["zone minute"] <= 59)
    feb29 = np.flatnonzero((mo == 2) & (d == 29))
    fy = y[feb29]
    fields_ok[feb29[(fy % 4 != 0) | ((fy % 100 == 0) & (fy % 400 != 0))]] = False
    is60 = f["second"] == 60

    # The reading as POSIX-like ns (days of 86400 s), with second 60 read as second 59.
    years = np.arange(YEAR_MIN, YEAR_MAX + 1, dtype=np.int64)
    month_start = _days_from_civil(np.repeat(years, 12), np.tile(np.arange(1, 13), years.size), np.ones(1, int))
    days = month_start[(np.clip(y, YEAR_MIN, YEAR_MAX) - YEAR_MIN) * 12 + np.clip(mo, 1, 12) - 1] + d - 1
    sec_of_day = f["hour"] * 3600 + f["minute"] * 60 + np.minimum(f["second"], 59) - f["zone_s"]  # int32
    at59_ns = f["at59_ns"] = (days * S_PER_DAY + sec_of_day) * NS_PER_S + f["frac_ns"]
    good = ok & ~too_many & year_ok & fields_ok
    if scale == "utc":
        table = _LeapTable()
        k = table.utc_bucket(at59_ns)
        kc = np.maximum(k, 0)
        tai = at59_ns + is60 * NS_PER_S + table.off_ns[kc]
        leap_ok = (table.step_ns[kc] > 0) & (at59_ns >= table.next_start_ns[kc] - NS_PER_S)
        good &= (k >= 0) & (~is60 | leap_ok)
    else:
        tai = at59_ns - _READING_MINUS_TAI_NS[scale]
        good &= ~is60
    if not good.all():
        codes = np.where(is60, _E_LEAP_DAY, 0).astype(np.int8)
        if scale == "utc":
            codes[is60 & leap_ok] = 0
            codes[is60 & (at59_ns % NS_PER_DAY < (S_PER_DAY - 1) * NS_PER_S)] = _E_LEAP_TIME
            codes[k < 0] = _E_PRE1972
        else:
            codes[is60] = _E_LEAP_SCALE
        codes[~year_ok] = _E_YEAR
        codes[~fields_ok] = _E_FIELD
        codes[too_many] = _E_DIGITS
        codes[~ok & ~too_many] = _E_SYNTAX
        codes[f["length"] == 0] = _E_EMPTY
        codes[missing] = _E_MISSING
        _report_codes(codes, lambda i, c: _iso_reason(i, c, raw, f, scale), f"{_ISO_EXPECTED} on scale {scale}")
    return tai.reshape(shape)


def _digit_table(width: int) -> NDArray[np.uint32]:
    """(10**width, width) character codes of the zero-padded decimal numbers 0 .. 10**width - 1."""
    numbers = np.arange(10**width)
    return np.stack([ord("0") + numbers // 10 ** (width - 1 - j) % 10 for j in range(width)], axis=1).astype(
        np.uint32
    )


def _put_digits(out: NDArray[np.uint32], col: int, value: NDArray[np.int64], width: int) -> None:
    """Write ``value`` (0 <= value < 10**width) zero-padded into columns col .. col+width-1."""
    pairs, three = _digit_table(2), _digit_table(3)
    while width:
        w = 3 if width % 2 else 2
        width -= w
        out[:, col + width:col + width + w] = (three if w == 3 else pairs)[value % 10**w]
        value = value // 10**w


def tai_ns_to_iso(tai_ns: ArrayLike, scale: str = "utc") -> NDArray[np.object_]:
    """Format tai_ns as ISO 8601 readings on ``scale``.

    tai_ns: int64 array, any shape. Returns an object array of str of the same shape:
    'YYYY-MM-DDTHH:MM:SS[.fff|.ffffff|.fffffffff]' with the fewest of 0/3/6/9 fractional digits
    that renders every value of the array exactly (one width for the whole array). UTC strings end
    in 'Z' and read 23:59:60.x during a leap second; instants before 1972-01-01 UTC raise
    TimeValueError. TAI/GPS/TT strings carry no zone letter: the caller states the scale (e.g. in
    the column name or a 'time_scale' field), since ISO 8601 has no designator for them.
    """
    scale = _check_scale(scale)
    t = _as_int_ns(tai_ns, "tai_ns")
    shape = t.shape
    t = t.reshape(-1)
    if scale == "utc":
        day, ns_of_day, _ = _tai_to_utc_parts(t, _LeapTable())
    else:
        reading = t + _READING_MINUS_TAI_NS[scale]
        day = reading // NS_PER_DAY
        ns_of_day = reading - day * NS_PER_DAY
    sub_ns = ns_of_day % NS_PER_S
    n_frac = next(d for d in (0, 3, 6, 9) if not np.any(sub_ns % 10 ** (9 - d)))
    width = 19 + (n_frac + 1 if n_frac else 0) + (scale == "utc")
    out = np.zeros((t.size, width), dtype=np.uint32)
    y, m, d = _civil_from_days(day)
    sec_of_day = ns_of_day // NS_PER_S
    hour = np.minimum(sec_of_day // 3600, 23)  # the leap second reads 23:59:60
    minute = np.minimum((sec_of_day - hour * 3600) // 60, 59)
    for col, value, w in ((0, y, 4), (5, m, 2), (8, d, 2), (11, hour, 2), (14, minute, 2),
                          (17, sec_of_day - hour * 3600 - minute * 60, 2)):
        _put_digits(out, col, value, w)
    out[:, [4, 7]] = ord("-")
    out[:, 10] = ord("T")
    out[:, [13, 16]] = ord(":")
    if n_frac:
        out[:, 19] = ord(".")
        _put_digits(out, 20, sub_ns // 10 ** (9 - n_frac), n_frac)
    if scale == "utc":
        out[:, -1] = ord("Z")
    return out.view(f"U{width}").reshape(shape).astype(object)


# --------------------------------------------------------------------------------------------
# Numbers: float seconds and integer nanoseconds since 1970-01-01T00:00:00 on a scale.


def _reading_ns_to_tai(reading_ns: NDArray[np.int64], scale: str, codes: NDArray[np.int8]) -> NDArray[np.int64]:
    if scale == "utc":
        return _utc_to_tai(reading_ns, _LeapTable(), codes, pre1972_code=3)
    return reading_ns - _READING_MINUS_TAI_NS[scale]


def _number_reason(value: Any, code: int, unit: str) -> str:
    if code == 1:
        return "NaN time"
    if code == 2:
        return f"{value!r} {unit} is infinite or outside the supported years {YEAR_MIN}-{YEAR_MAX}"
    return f"{value!r} {unit} is before {FIRST_INTEGER_UTC} UTC, when TAI-UTC was not a whole number of seconds"


_NUMBER_LIMIT_S = 9.0e9  # |seconds| beyond this (year ~2255) could overflow int64 nanoseconds
_NUMBER_LIMIT_NS = 9 * 10**18


def seconds_to_tai_ns(seconds: ArrayLike, scale: str, resolution_ns: int = 1_000) -> NDArray[np.int64]:
    """Convert float seconds since 1970-01-01T00:00:00 on ``scale`` to tai_ns.

    seconds: float64 array (s), any shape. For "utc" this is the POSIX count (Unix time): days of
    exactly 86400 s, leap seconds not counted, so 23:59:60 cannot be expressed and the value is
    read with the TAI-UTC in force at that UTC reading; values before 1972-01-01 are rejected. For
    "tai", "gps", "tt" it is elapsed SI seconds since 1970-01-01T00:00:00 read on that scale.
    The float is split into whole and fractional seconds and the fraction rounded to the nearest
    multiple of ``resolution_ns`` (default 1 µs: a float64 count of seconds since 1970 resolves only
    about 0.24 µs at present-day epochs, so finer digits are representation noise; with the default,
    a 10 Hz series 1.7e9 + 0.1 k reads back as exact tenths). Use ``resolution_ns=1`` for the
    nanosecond nearest to the float's exact value. NaN, infinite and out-of-range (|s| > 9e9) rows
    raise TimeValueError.
    """
    if resolution_ns < 1 or NS_PER_S % resolution_ns:
        raise TimeValueError(f"resolution_ns must divide 1e9, got {resolution_ns}")
    scale = _check_scale(scale)
    s = np.asarray(seconds, dtype=np.float64)
    shape = s.shape
    s = s.reshape(-1)
    codes = np.zeros(s.size, dtype=np.int8)
    codes[~(np.abs(s) <= _NUMBER_LIMIT_S)] = 2
    codes[np.isnan(s)] = 1
    s_ok = np.where(codes == 0, s, 0.0)
    whole = np.floor(s_ok)
    ticks = np.rint((s_ok - whole) * (NS_PER_S // resolution_ns)).astype(np.int64)
    reading = whole.astype(np.int64) * NS_PER_S + ticks * resolution_ns
    tai = _reading_ns_to_tai(reading, scale, codes)
    _report_codes(codes, lambda i, c: _number_reason(float(s[i]), c, "s"),
                  f"finite seconds since 1970-01-01T00:00:00 {scale.upper()}")
    return tai.reshape(shape)


def epoch_ns_to_tai_ns(ns: ArrayLike, scale: str) -> NDArray[np.int64]:
    """Convert integer nanoseconds since 1970-01-01T00:00:00 on ``scale`` to tai_ns, exactly.

    ns: int64 array (ns), any shape, e.g. a Parquet/Arrow timestamp column; a numpy datetime64
    array is also accepted (NaT rows are reported). For "utc" the count is POSIX-style (leap
    seconds not counted) and must be from 1972-01-01 on; see :func:`seconds_to_tai_ns`.
    """
    scale = _check_scale(scale)
    arr = np.asarray(ns)
    codes_nat = None
    if arr.dtype.kind == "M":
        codes_nat = np.isnat(arr).reshape(-1)
        arr = arr.astype("datetime64[ns]").view(np.int64)
    a = _as_int_ns(arr, "ns")
    shape = a.shape
    a = a.reshape(-1)
    codes = np.zeros(a.size, dtype=np.int8)
    codes[(a > _NUMBER_LIMIT_NS) | (a < -_NUMBER_LIMIT_NS)] = 2
    if codes_nat is not None:
        codes[codes_nat] = 1
    tai = _reading_ns_to_tai(a, scale, codes)
    _report_codes(codes, lambda i, c: "NaT time" if c == 1 else _number_reason(int(a[i]), c, "ns"),
                  f"integer nanoseconds since 1970-01-01T00:00:00 {scale.upper()}")
    return tai.reshape(shape)


def tai_ns_to_epoch_ns(tai_ns: ArrayLike, scale: str) -> NDArray[np.int64]:
    """Integer nanoseconds since 1970-01-01T00:00:00 on ``scale`` (inverse of
    :func:`epoch_ns_to_tai_ns`). tai_ns: int64 array, any shape. For "utc" the POSIX count;
    during a leap second it holds at the following midnight (see :func:`tai_ns_to_seconds`)."""
    scale = _check_scale(scale)
    t = _as_int_ns(tai_ns, "tai_ns")
    if scale != "utc":
        return t + _READING_MINUS_TAI_NS[scale]
    day, ns_of_day, _ = _tai_to_utc_parts(t, _LeapTable())
    return day * NS_PER_DAY + np.minimum(ns_of_day, NS_PER_DAY)


def tai_ns_to_seconds(tai_ns: ArrayLike, scale: str) -> NDArray[np.float64]:
    """Seconds since 1970-01-01T00:00:00 on ``scale`` (float64, s) of tai_ns (int64, any shape).

    For "utc" this is the POSIX count (leap seconds not counted). During a leap second
    (23:59:60.x UTC) POSIX has no value; this returns the count of the following midnight
    00:00:00, i.e. the clock holds for one second: the result is non-decreasing and never repeats
    an earlier value. Instants before 1972-01-01 UTC raise TimeValueError. The float is the one
    nearest to the exact nanosecond count.
    """
    ns = tai_ns_to_epoch_ns(tai_ns, scale)
    whole = ns // NS_PER_S
    return whole.astype(np.float64) + (ns - whole * NS_PER_S) / NS_PER_S


# --------------------------------------------------------------------------------------------
# Leap-second table queries.


def tai_minus_utc_s(tai_ns: ArrayLike) -> NDArray[np.int64]:
    """TAI-UTC (whole s, int64) at TAI instants (tai_ns int64, any shape), from ERFA's table.

    Inside a leap second the value before it applies (36 s during 2016-12-31T23:59:60 UTC), since
    the UTC reading 23:59:60.x = TAI - 36 s. After the table's last entry its offset applies.
    Instants before 1972-01-01 UTC raise TimeValueError.
    """
    t = _as_int_ns(tai_ns, "tai_ns")
    table = _LeapTable()
    _, _, k = _tai_to_utc_parts(t, table)
    return table.off_ns[k] // NS_PER_S


def utc_leap_second_dates() -> NDArray[np.datetime64]:
    """UTC dates (datetime64[D]) whose last minute has a 23:59:60, from ERFA's table, 1972 on."""
    table = _LeapTable()
    leap = table.step_ns > 0
    return (table.next_start_ns[leap] // NS_PER_DAY - 1).astype("datetime64[D]")


# --------------------------------------------------------------------------------------------
# Two-part Julian dates for ERFA.


def tai_ns_to_jd(tai_ns: ArrayLike, scale: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two-part Julian date (jd1, jd2) on ``scale`` of tai_ns (int64, any shape).

    jd1 = JD of the preceding 0h on the scale (an integer + 0.5), jd2 = fraction of day in [0, 1),
    so jd1 + jd2 keeps the nanosecond (the ERFA/SOFA "date & fraction" split of eraDtf2d).
    For "utc" the fraction follows ERFA's quasi-JD convention: on a day ending in a leap second
    the day has 86401 s and jd2 = seconds of day / 86401, as in erfa.dtf2d("UTC", ...),
    erfa.utctai and erfa.taiutc. For "tai", "gps", "tt" ordinary 86400 s days.
    """
    scale = _check_scale(scale)
    t = _as_int_ns(tai_ns, "tai_ns")
    if scale != "utc":
        return _jd_from_ns(t + _READING_MINUS_TAI_NS[scale])
    table = _LeapTable()
    day, ns_of_day, k = _tai_to_utc_parts(t, table)
    day_s = S_PER_DAY + np.where((day + 1) * NS_PER_DAY == table.next_start_ns[k], table.step_ns[k], 0) // NS_PER_S
    return UNIX_EPOCH_JD + day.astype(np.float64), ns_of_day / (day_s * NS_PER_S)


def tai_ns_to_ut1_jd(tai_ns: ArrayLike, dut1_s: ArrayLike = 0.0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two-part Julian date on UT1 of tai_ns (int64, any shape), with UT1-UTC = ``dut1_s``.

    dut1_s: UT1-UTC in s, scalar or an array broadcast with tai_ns (e.g. interpolated from an
    EOP table; 0 by default), rounded to the nanosecond. As in erfa.utcut1, UT1 = TAI - (TAI-UTC
    at 0h UTC of the day) + dut1, so inside a leap second UT1 runs on and the jump of UT1-UTC is
    the caller's dut1 series. Returns (jd1, jd2) with jd2 in [0, 1).
    """
    t, dut1 = np.broadcast_arrays(_as_int_ns(tai_ns, "tai_ns"), np.asarray(dut1_s, dtype=np.float64))
    dut1_flat = dut1.reshape(-1)
    _report_codes((~np.isfinite(dut1_flat)).astype(np.int8),
                  lambda i, c: f"dut1_s {float(dut1_flat[i])!r} is not finite", "finite UT1-UTC in seconds")
    table = _LeapTable()
    _, _, k = _tai_to_utc_parts(t, table)
    return _jd_from_ns(t - table.off_ns[k] + np.rint(dut1 * NS_PER_S).astype(np.int64))


def tai_ns_from_jd(jd1: ArrayLike, jd2: ArrayLike, scale: str) -> NDArray[np.int64]:
    """tai_ns (int64, rounded to the ns) of two-part Julian dates on ``scale``.

    jd1, jd2: float64 arrays (days), broadcast together; any split (jd1 + jd2 is the date). For
    "utc" the quasi-JD of ERFA (a leap-second day has 86401 s; see :func:`tai_ns_to_jd`) and dates
    before 1972-01-01 are rejected. NaN/Inf rows raise TimeValueError.
    """
    scale = _check_scale(scale)
    a, b = np.broadcast_arrays(np.asarray(jd1, dtype=np.float64), np.asarray(jd2, dtype=np.float64))
    shape = a.shape
    a, b = a.reshape(-1), b.reshape(-1)
    codes = np.zeros(a.size, dtype=np.int8)
    codes[~(np.abs(a + b - UNIX_EPOCH_JD) <= _NUMBER_LIMIT_S / S_PER_DAY)] = 2
    codes[np.isnan(a) | np.isnan(b)] = 1
    a, b = np.where(codes == 0, a, UNIX_EPOCH_JD), np.where(codes == 0, b, 0.0)
    x1 = a - UNIX_EPOCH_JD
    i1, i2 = np.floor(x1), np.floor(b)
    frac = (x1 - i1) + (b - i2)
    carry = np.floor(frac)
    frac -= carry
    day = (i1 + i2 + carry).astype(np.int64)
    if scale == "utc":
        table = _LeapTable()
        k = table.utc_bucket(day * NS_PER_DAY)
        codes[(k < 0) & (codes == 0)] = 3
        kc = np.maximum(k, 0)
        ends_at_step = (day + 1) * NS_PER_DAY == table.next_start_ns[kc]
        day_ns = NS_PER_DAY + np.where(ends_at_step, table.step_ns[kc], 0)
        tai = day * NS_PER_DAY + np.rint(frac * day_ns).astype(np.int64) + table.off_ns[kc]
    else:
        tai = day * NS_PER_DAY + np.rint(frac * NS_PER_DAY).astype(np.int64) - _READING_MINUS_TAI_NS[scale]
    _report_codes(codes, lambda i, c: _number_reason(float(a[i] + b[i]), c, "JD"),
                  f"finite two-part Julian dates on {scale.upper()}")
    return tai.reshape(shape)
