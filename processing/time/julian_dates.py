"""Two-part Julian dates for ERFA from and to tai_ns (the eraDtf2d "date & fraction" split).

jd1 is the Julian date of the preceding 0h on the scale (an integer + 0.5), jd2 the fraction of the
day, so jd1 + jd2 keeps the nanosecond. UTC follows ERFA's quasi-JD convention (a day ending in a leap
second has 86401 s); UT1 is UTC plus a given UT1-UTC. Scales, the leap-second table and the error
reporting are those of processing.time.timescales.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.time.leap_seconds import LeapTable
from processing.time.timescales import (
    NUMBER_LIMIT_S,
    READING_MINUS_TAI_NS,
    UNIX_EPOCH_JD,
    as_int_ns,
    check_scale,
    number_reason,
    report_codes,
    tai_to_utc_parts,
)
from processing.units import NS_PER_DAY, NS_PER_S, S_PER_DAY

__all__ = ["jd_from_reading_ns", "tai_ns_from_jd", "tai_ns_to_jd", "tai_ns_to_ut1_jd"]


def jd_from_reading_ns(reading_ns: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(jd1, jd2) of ns readings since 1970-01-01T00:00:00 on a scale of 86400 s days: 0h and fraction."""
    day = reading_ns // NS_PER_DAY
    return UNIX_EPOCH_JD + day.astype(np.float64), (reading_ns - day * NS_PER_DAY) / NS_PER_DAY


def tai_ns_to_jd(tai_ns: ArrayLike, scale: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two-part Julian date (jd1, jd2) on ``scale`` of tai_ns (int64, any shape).

    jd1 = JD of the preceding 0h on the scale (an integer + 0.5), jd2 = fraction of day in [0, 1),
    so jd1 + jd2 keeps the nanosecond (the ERFA/SOFA "date & fraction" split of eraDtf2d).
    For "utc" the fraction follows ERFA's quasi-JD convention: on a day ending in a leap second
    the day has 86401 s and jd2 = seconds of day / 86401, as in erfa.dtf2d("UTC", ...),
    erfa.utctai and erfa.taiutc. For "tai", "gps", "tt" ordinary 86400 s days.
    """
    scale = check_scale(scale)
    t = as_int_ns(tai_ns, "tai_ns")
    if scale != "utc":
        return jd_from_reading_ns(t + READING_MINUS_TAI_NS[scale])
    table = LeapTable()
    day, ns_of_day, k = tai_to_utc_parts(t, table)
    day_s = S_PER_DAY + np.where((day + 1) * NS_PER_DAY == table.next_start_ns[k], table.step_ns[k], 0) // NS_PER_S
    return UNIX_EPOCH_JD + day.astype(np.float64), ns_of_day / (day_s * NS_PER_S)


def tai_ns_to_ut1_jd(tai_ns: ArrayLike, dut1_s: ArrayLike = 0.0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two-part Julian date on UT1 of tai_ns (int64, any shape), with UT1-UTC = ``dut1_s``.

    dut1_s: UT1-UTC in s, scalar or an array broadcast with tai_ns (e.g. interpolated from an
    EOP table; 0 by default), rounded to the nanosecond. As in erfa.utcut1, UT1 = TAI - (TAI-UTC
    at 0h UTC of the day) + dut1, so inside a leap second UT1 runs on and the jump of UT1-UTC is
    the caller's dut1 series. Returns (jd1, jd2) with jd2 in [0, 1).
    """
    t, dut1 = np.broadcast_arrays(as_int_ns(tai_ns, "tai_ns"), np.asarray(dut1_s, dtype=np.float64))
    dut1_flat = dut1.reshape(-1)
    report_codes((~np.isfinite(dut1_flat)).astype(np.int8),
                  lambda i, c: f"dut1_s {float(dut1_flat[i])!r} is not finite", "finite UT1-UTC in seconds")
    table = LeapTable()
    _, _, k = tai_to_utc_parts(t, table)
    return jd_from_reading_ns(t - table.off_ns[k] + np.rint(dut1 * NS_PER_S).astype(np.int64))


def tai_ns_from_jd(jd1: ArrayLike, jd2: ArrayLike, scale: str) -> NDArray[np.int64]:
    """tai_ns (int64, rounded to the ns) of two-part Julian dates on ``scale``.

    jd1, jd2: float64 arrays (days), broadcast together; any split (jd1 + jd2 is the date). For
    "utc" the quasi-JD of ERFA (a leap-second day has 86401 s; see :func:`tai_ns_to_jd`) and dates
    before 1972-01-01 are rejected. NaN/Inf rows raise TimeValueError.
    """
    scale = check_scale(scale)
    a, b = np.broadcast_arrays(np.asarray(jd1, dtype=np.float64), np.asarray(jd2, dtype=np.float64))
    shape = a.shape
    a, b = a.reshape(-1), b.reshape(-1)
    codes = np.zeros(a.size, dtype=np.int8)
    codes[~(np.abs(a + b - UNIX_EPOCH_JD) <= NUMBER_LIMIT_S / S_PER_DAY)] = 2
    codes[np.isnan(a) | np.isnan(b)] = 1
    a, b = np.where(codes == 0, a, UNIX_EPOCH_JD), np.where(codes == 0, b, 0.0)
    x1 = a - UNIX_EPOCH_JD
    i1, i2 = np.floor(x1), np.floor(b)
    frac = (x1 - i1) + (b - i2)
    carry = np.floor(frac)
    frac -= carry
    day = (i1 + i2 + carry).astype(np.int64)
    if scale == "utc":
        table = LeapTable()
        k = table.utc_bucket(day * NS_PER_DAY)
        codes[(k < 0) & (codes == 0)] = 3
        kc = np.maximum(k, 0)
        ends_at_step = (day + 1) * NS_PER_DAY == table.next_start_ns[kc]
        day_ns = NS_PER_DAY + np.where(ends_at_step, table.step_ns[kc], 0)
        tai = day * NS_PER_DAY + np.rint(frac * day_ns).astype(np.int64) + table.off_ns[kc]
    else:
        tai = day * NS_PER_DAY + np.rint(frac * NS_PER_DAY).astype(np.int64) - READING_MINUS_TAI_NS[scale]
    report_codes(codes, lambda i, c: number_reason(float(a[i] + b[i]), c, "JD"),
                  f"finite two-part Julian dates on {scale.upper()}")
    return tai.reshape(shape)
