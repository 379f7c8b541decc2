"""Time scales: UTC, TAI, GPS and TT readings to and from one continuous integer count.

Every time inside the service is ``tai_ns``: an int64 count of SI nanoseconds since
1970-01-01T00:00:00 TAI. TAI is continuous, so a leap second is an ordinary second of it and is
never lost. This module converts user input (ISO 8601 strings, float seconds, integer nanoseconds
read on a stated scale) into ``tai_ns`` and back. Siblings: processing.time.julian_dates (two-part
Julian dates for ERFA), processing.time.leap_seconds (calendar arithmetic, the leap-second table) and
processing.time.iso_text (ISO 8601 text scanning and formatting at array speed); the helpers here
without a leading underscore (check_scale, as_int_ns, report_codes, ...) are shared with them.

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

import functools
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.time.iso_text import ISO_WIDTH, put_digits, scan_iso
from processing.time.leap_seconds import LeapTable, civil_from_days, days_from_civil, days_in_month
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
READING_MINUS_TAI_NS = {"tai": 0, "gps": -TAI_MINUS_GPS_NS, "tt": TT_MINUS_TAI_NS}


class TimeValueError(ValueError):
    """Bad time input: the message names the first bad rows and what was expected.

    ``rows`` holds (flattened row index, reason) of the first 100 bad rows; it is empty when the
    whole argument is wrong (unknown scale, wrong dtype).
    """

    def __init__(self, message: str, rows: list[tuple[int, str]] | None = None) -> None:
        super().__init__(message)
        self.rows: list[tuple[int, str]] = list(rows or [])


# --------------------------------------------------------------------------------------------
# Helpers: error reporting and UTC <-> TAI with the leap-second table (processing.time.leap_seconds).


def check_scale(scale: str) -> str:
    """The scale name in lower case; TimeValueError unless one of SCALES."""
    s = str(scale).lower()
    if s not in SCALES:
        raise TimeValueError(f"unknown time scale {scale!r}; expected one of {', '.join(SCALES)}")
    return s


def as_int_ns(values: ArrayLike, what: str) -> NDArray[np.int64]:
    """values as int64 nanoseconds; TimeValueError (naming ``what``) for a non-integer dtype."""
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


def report_codes(codes: NDArray[np.int8], reason: Any, expected: str) -> None:
    """Raise one TimeValueError for all rows with a nonzero code; ``reason(i, code)`` -> str
    is called for the first 100 bad rows only."""
    bad = np.flatnonzero(codes)
    if bad.size:
        rows = [(int(i), reason(int(i), int(codes[i]))) for i in bad[:_MAX_REPORTED_ROWS]]
        _raise_rows(rows, int(bad.size), int(codes.size), expected)


def _utc_to_tai(
    utc_ns: NDArray[np.int64], table: LeapTable, codes: NDArray[np.int8], pre1972_code: int
) -> NDArray[np.int64]:
    """TAI of POSIX UTC readings (no leap seconds in ``utc_ns``); marks pre-1972 rows in codes."""
    k = table.utc_bucket(utc_ns)
    codes[(k < 0) & (codes == 0)] = pre1972_code
    return utc_ns + table.off_ns[np.maximum(k, 0)]


def tai_to_utc_parts(
    tai_ns: NDArray[np.int64], table: LeapTable
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.intp]]:
    """UTC (day since 1970, ns of day, table row) of TAI instants; ns of day >= 86400 s inside a
    leap second. Raises for instants before 1972-01-01 UTC."""
    k = table.tai_bucket(tai_ns)
    if np.any(k < 0):
        flat = np.ravel(k < 0)
        report_codes(
            flat.astype(np.int8),
            lambda i, c: f"tai_ns {int(np.ravel(tai_ns)[i])} is before {FIRST_INTEGER_UTC} UTC",
            f"instants from {FIRST_INTEGER_UTC}T00:00:00 UTC on (UTC before then is not supported)",
        )
    u = tai_ns - table.off_ns[k]
    in_leap = u >= table.next_start_ns[k]  # only possible when step > 0: the 23:59:60 second
    day = u // NS_PER_DAY - in_leap
    return day, u - day * NS_PER_DAY, k


# --------------------------------------------------------------------------------------------
# ISO 8601 strings.

_E_EMPTY, _E_MISSING, _E_SYNTAX, _E_DIGITS, _E_FIELD, _E_YEAR = 1, 2, 3, 4, 5, 6
_E_LEAP_SCALE, _E_PRE1972, _E_LEAP_TIME, _E_LEAP_DAY = 7, 8, 9, 10
_FIELD_LIMITS = (("month", 1, 12), ("day", 1, 31), ("hour", 0, 23), ("minute", 0, 59), ("second", 0, 60),
                 ("zone hour", 0, 23), ("zone minute", 0, 59))


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
                hi = days_in_month(int(f["year"][i]), int(f["month"][i]))
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
    y, m, d = civil_from_days(f["at59_ns"][i : i + 1] // NS_PER_DAY)
    return f"23:59:60 on {int(y[0]):04d}-{int(m[0]):02d}-{int(d[0]):02d} is not a leap second"


def _missing(raw: NDArray[Any]) -> NDArray[np.bool_]:
    """None, NaN, NaT and pandas.NA entries of an object array (pandas' own test, imported only then)."""
    if all(isinstance(v, str) for v in raw):
        return np.zeros(raw.size, dtype=bool)
    import pandas as pd

    return np.asarray(pd.isna(raw), dtype=bool)


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
    scale = check_scale(scale)
    is_str_array = isinstance(values, np.ndarray) and values.dtype.kind == "U"
    raw = np.asarray(values) if is_str_array else np.asarray(values, dtype=object)
    shape = raw.shape
    raw = raw.reshape(-1)
    n = raw.size
    missing = np.zeros(n, dtype=bool) if is_str_array else _missing(raw)
    text = raw
    if missing.any():
        text = raw.copy()
        text[missing] = ""
    ok, too_many, f = scan_iso(text.astype(f"U{ISO_WIDTH}"))
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
    month_start = days_from_civil(np.repeat(years, 12), np.tile(np.arange(1, 13), years.size), np.ones(1, int))
    days = month_start[(np.clip(y, YEAR_MIN, YEAR_MAX) - YEAR_MIN) * 12 + np.clip(mo, 1, 12) - 1] + d - 1
    sec_of_day = f["hour"] * 3600 + f["minute"] * 60 + np.minimum(f["second"], 59) - f["zone_s"]  # int32
    at59_ns = f["at59_ns"] = (days * S_PER_DAY + sec_of_day) * NS_PER_S + f["frac_ns"]
    good = ok & ~too_many & year_ok & fields_ok
    if scale == "utc":
        table = LeapTable()
        k = table.utc_bucket(at59_ns)
        kc = np.maximum(k, 0)
        tai = at59_ns + is60 * NS_PER_S + table.off_ns[kc]
        leap_ok = (table.step_ns[kc] > 0) & (at59_ns >= table.next_start_ns[kc] - NS_PER_S)
        good &= (k >= 0) & (~is60 | leap_ok)
    else:
        tai = at59_ns - READING_MINUS_TAI_NS[scale]
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
        report_codes(codes, lambda i, c: _iso_reason(i, c, raw, f, scale), f"{_ISO_EXPECTED} on scale {scale}")
    return tai.reshape(shape)


def tai_ns_to_iso(tai_ns: ArrayLike, scale: str = "utc") -> NDArray[np.object_]:
    """Format tai_ns as ISO 8601 readings on ``scale``.

    tai_ns: int64 array, any shape. Returns an object array of str of the same shape:
    'YYYY-MM-DDTHH:MM:SS[.fff|.ffffff|.fffffffff]' with the fewest of 0/3/6/9 fractional digits
    that renders every value of the array exactly (one width for the whole array). UTC strings end
    in 'Z' and read 23:59:60.x during a leap second; instants before 1972-01-01 UTC raise
    TimeValueError. TAI/GPS/TT strings carry no zone letter: the caller states the scale (e.g. in
    the column name or a 'time_scale' field), since ISO 8601 has no designator for them.
    """
    t = as_int_ns(tai_ns, "tai_ns")
    codes = tai_ns_to_iso_codes(t, scale)
    return codes.view(f"U{codes.shape[1]}").reshape(t.shape).astype(object)


def tai_ns_to_iso_codes(tai_ns: ArrayLike, scale: str = "utc", dtype: Any = np.uint32) -> NDArray[Any]:
    """The text of :func:`tai_ns_to_iso` as character codes, (N, width) ``dtype`` (uint32, or uint8 for byte
    strings; ASCII) for the N values of tai_ns flattened: for writers that build string columns without a Python
    object per value."""
    scale = check_scale(scale)
    t = as_int_ns(tai_ns, "tai_ns")
    t = t.reshape(-1)
    if scale == "utc":
        day, ns_of_day, _ = tai_to_utc_parts(t, LeapTable())
    else:
        reading = t + READING_MINUS_TAI_NS[scale]
        day = reading // NS_PER_DAY
        ns_of_day = reading - day * NS_PER_DAY
    sub_ns = ns_of_day % NS_PER_S
    n_frac = next(d for d in (0, 3, 6, 9) if not np.any(sub_ns % 10 ** (9 - d)))
    width = 19 + (n_frac + 1 if n_frac else 0) + (scale == "utc")
    out = np.zeros((t.size, width), dtype=dtype)
    sec_of_day = ns_of_day // NS_PER_S
    if t.size >= TABLE_MIN_ROWS and int(day.max()) - int(day.min()) < t.size and 0 <= sec_of_day.min() \
            and sec_of_day.max() <= _SECONDS_IN_LEAP_DAY:
        # long series: "YYYY-MM-DD" per distinct day and "hh:mm:ss" per second of the day, gathered per row
        first = int(day.min())
        dates = np.zeros((int(day.max()) - first + 1, 10), dtype=dtype)
        _put_date(dates, np.arange(first, first + dates.shape[0], dtype=np.int64))
        out[:, :10] = dates[day - first]
        out[:, 11:19] = _clock_table(np.dtype(dtype))[sec_of_day]
    else:
        _put_date(out, day)
        _put_clock(out, sec_of_day)
    out[:, 10] = ord("T")
    if n_frac:
        out[:, 19] = ord(".")
        put_digits(out, 20, sub_ns // 10 ** (9 - n_frac), n_frac)
    if scale == "utc":
        out[:, -1] = ord("Z")
    return out


TABLE_MIN_ROWS = 20_000
"""From this many values on, :func:`tai_ns_to_iso_codes` gathers dates and clock times from tables."""
_SECONDS_IN_LEAP_DAY = 86_400  # the last second of a day with a leap second reads 23:59:60


def _put_date(out: NDArray[Any], day: NDArray[np.int64]) -> None:
    """"YYYY-MM-DD" of the days since 1970-01-01 into columns 0-9."""
    y, m, d = civil_from_days(day)
    for col, value, w in ((0, y, 4), (5, m, 2), (8, d, 2)):
        put_digits(out, col, value, w)
    out[:, [4, 7]] = ord("-")


def _put_clock(out: NDArray[Any], sec_of_day: NDArray[np.int64]) -> None:
    """"hh:mm:ss" of the seconds of the day (86,400: the leap second, 23:59:60) into columns 11-18."""
    hour = np.minimum(sec_of_day // 3600, 23)  # the leap second reads 23:59:60
    minute = np.minimum((sec_of_day - hour * 3600) // 60, 59)
    for col, value, w in ((11, hour, 2), (14, minute, 2), (17, sec_of_day - hour * 3600 - minute * 60, 2)):
        put_digits(out, col, value, w)
    out[:, [13, 16]] = ord(":")


@functools.lru_cache(maxsize=4)
def _clock_table(dtype: np.dtype[Any]) -> NDArray[Any]:
    """(86,401, 8) codes of "hh:mm:ss" for every second of a day, the leap second last (a constant)."""
    table = np.zeros((_SECONDS_IN_LEAP_DAY + 1, 19), dtype=dtype)
    _put_clock(table, np.arange(_SECONDS_IN_LEAP_DAY + 1, dtype=np.int64))
    out = table[:, 11:19].copy()
    out.flags.writeable = False
    return out


# --------------------------------------------------------------------------------------------
# Numbers: float seconds and integer nanoseconds since 1970-01-01T00:00:00 on a scale.


def _reading_ns_to_tai(reading_ns: NDArray[np.int64], scale: str, codes: NDArray[np.int8]) -> NDArray[np.int64]:
    if scale == "utc":
        return _utc_to_tai(reading_ns, LeapTable(), codes, pre1972_code=3)
    return reading_ns - READING_MINUS_TAI_NS[scale]


def number_reason(value: Any, code: int, unit: str) -> str:
    """Why a numeric time is bad: code 1 NaN, 2 infinite or out of range, otherwise before 1972 UTC."""
    if code == 1:
        return "NaN time"
    if code == 2:
        return f"{value!r} {unit} is infinite or outside the supported years {YEAR_MIN}-{YEAR_MAX}"
    return f"{value!r} {unit} is before {FIRST_INTEGER_UTC} UTC, when TAI-UTC was not a whole number of seconds"


NUMBER_LIMIT_S = 9.0e9  # |seconds| beyond this (year ~2255) could overflow int64 nanoseconds
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
    scale = check_scale(scale)
    s = np.asarray(seconds, dtype=np.float64)
    shape = s.shape
    s = s.reshape(-1)
    codes = np.zeros(s.size, dtype=np.int8)
    codes[~(np.abs(s) <= NUMBER_LIMIT_S)] = 2
    codes[np.isnan(s)] = 1
    s_ok = np.where(codes == 0, s, 0.0)
    whole = np.floor(s_ok)
    ticks = np.rint((s_ok - whole) * (NS_PER_S // resolution_ns)).astype(np.int64)
    reading = whole.astype(np.int64) * NS_PER_S + ticks * resolution_ns
    tai = _reading_ns_to_tai(reading, scale, codes)
    report_codes(codes, lambda i, c: number_reason(float(s[i]), c, "s"),
                  f"finite seconds since 1970-01-01T00:00:00 {scale.upper()}")
    return tai.reshape(shape)


def epoch_ns_to_tai_ns(ns: ArrayLike, scale: str) -> NDArray[np.int64]:
    """Convert integer nanoseconds since 1970-01-01T00:00:00 on ``scale`` to tai_ns, exactly.

    ns: int64 array (ns), any shape, e.g. a Parquet/Arrow timestamp column; a numpy datetime64
    array is also accepted (NaT rows are reported). For "utc" the count is POSIX-style (leap
    seconds not counted) and must be from 1972-01-01 on; see :func:`seconds_to_tai_ns`.
    """
    scale = check_scale(scale)
    arr = np.asarray(ns)
    codes_nat = None
    if arr.dtype.kind == "M":
        codes_nat = np.isnat(arr).reshape(-1)
        arr = arr.astype("datetime64[ns]").view(np.int64)
    a = as_int_ns(arr, "ns")
    shape = a.shape
    a = a.reshape(-1)
    codes = np.zeros(a.size, dtype=np.int8)
    codes[(a > _NUMBER_LIMIT_NS) | (a < -_NUMBER_LIMIT_NS)] = 2
    if codes_nat is not None:
        codes[codes_nat] = 1
    tai = _reading_ns_to_tai(a, scale, codes)
    report_codes(codes, lambda i, c: "NaT time" if c == 1 else number_reason(int(a[i]), c, "ns"),
                  f"integer nanoseconds since 1970-01-01T00:00:00 {scale.upper()}")
    return tai.reshape(shape)


def tai_ns_to_epoch_ns(tai_ns: ArrayLike, scale: str) -> NDArray[np.int64]:
    """Integer nanoseconds since 1970-01-01T00:00:00 on ``scale`` (inverse of
    :func:`epoch_ns_to_tai_ns`). tai_ns: int64 array, any shape. For "utc" the POSIX count;
    during a leap second it holds at the following midnight (see :func:`tai_ns_to_seconds`)."""
    scale = check_scale(scale)
    t = as_int_ns(tai_ns, "tai_ns")
    if scale != "utc":
        return t + READING_MINUS_TAI_NS[scale]
    day, ns_of_day, _ = tai_to_utc_parts(t, LeapTable())
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
    t = as_int_ns(tai_ns, "tai_ns")
    table = LeapTable()
    _, _, k = tai_to_utc_parts(t, table)
    return table.off_ns[k] // NS_PER_S


def utc_leap_second_dates() -> NDArray[np.datetime64]:
    """UTC dates (datetime64[D]) whose last minute has a 23:59:60, from ERFA's table, 1972 on."""
    table = LeapTable()
    leap = table.step_ns > 0
    return (table.next_start_ns[leap] // NS_PER_DAY - 1).astype("datetime64[D]")
