"""ERFA's leap-second table as nanosecond breakpoints, and the proleptic Gregorian calendar arithmetic on
int64 day counts it needs (building blocks of processing.time.timescales). Pure and vectorised."""

from __future__ import annotations

import erfa
import numpy as np
from numpy.typing import NDArray

from processing.units import NS_PER_DAY, NS_PER_S

__all__ = ["LeapTable", "civil_from_days", "days_from_civil", "days_in_month"]


def days_from_civil(y: NDArray[np.int64], m: NDArray[np.int64], d: NDArray[np.int64]) -> NDArray[np.int64]:
    """Days since 1970-01-01 of proleptic Gregorian dates (H. Hinnant, "chrono-Compatible
    Low-Level Date Algorithms", days_from_civil); arrays of int64."""
    y = y - (m <= 2)
    era = y // 400
    yoe = y - era * 400
    doy = (153 * ((m + 9) % 12) + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146097 + doe - 719468


def civil_from_days(z: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Inverse of :func:`days_from_civil` (Hinnant, civil_from_days): (year, month, day)."""
    z = z + 719468
    era = z // 146097
    doe = z - era * 146097
    yoe = (doe - doe // 1460 + doe // 36524 - doe // 146096) // 365
    doy = doe - (365 * yoe + yoe // 4 - yoe // 100)
    mp = (5 * doy + 2) // 153
    d = doy - (153 * mp + 2) // 5 + 1
    m = np.where(mp < 10, mp + 3, mp - 9)
    return yoe + era * 400 + (m <= 2), m, d


class LeapTable:
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
        days = days_from_civil(table["year"].astype(np.int64), table["month"].astype(np.int64), one)
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


def days_in_month(year: int, month: int) -> int:
    leap = year % 4 == 0 and (year % 100 != 0 or year % 400 == 0)
    return [31, 29 if leap else 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31][month - 1]
