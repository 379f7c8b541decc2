"""Time arguments of requests: ISO 8601 or seconds since 1970 on a time scale, to TAI nanoseconds."""

from __future__ import annotations

import numpy as np

from app.services.errors import Invalid
from processing.time import timescales

EARLIEST_ISO, LATEST_ISO = "1972-01-01T00:00:00Z", "2100-01-01T00:00:00Z"
EARLIEST_TAI_NS, LATEST_TAI_NS = (int(t) for t in timescales.iso_to_tai_ns(
    np.array([EARLIEST_ISO, LATEST_ISO], dtype=object), "utc"))
"""Request times (windows of reads and jobs) lie in [1972-01-01, 2100-01-01) UTC: before 1972 UTC had
no integer offset from TAI; a later bound only makes unbounded windows (and their work) possible."""


def check_bound(tai_ns: int, field: str) -> int:
    """``tai_ns`` if it lies in the supported range; Invalid("<field>: ...") otherwise."""
    if not EARLIEST_TAI_NS <= tai_ns < LATEST_TAI_NS:
        raise Invalid(f"{field}: times must lie between {EARLIEST_ISO} and {LATEST_ISO} (UTC)")
    return tai_ns


def parse_bound(value: str | None, scale: str, field: str) -> int | None:
    """A window bound: None or "" -> None; a number -> seconds since 1970 on ``scale``; else ISO 8601.

    Raises Invalid("<field>: ...") for a time that does not parse or does not exist on the scale."""
    if value is None or value == "":
        return None
    try:
        try:
            seconds = float(value)
        except ValueError:
            return check_bound(int(timescales.iso_to_tai_ns(np.array([value], dtype=object), scale)[0]), field)
        return check_bound(int(timescales.seconds_to_tai_ns(np.array([seconds]), scale)[0]), field)
    except (timescales.TimeValueError, OverflowError) as exc:
        raise Invalid(f"{field}: {exc}") from None


def parse_window(start: str | None, end: str | None, scale: str) -> tuple[int | None, int | None]:
    """Both bounds of a read window; Invalid when the end is before the start."""
    t0 = parse_bound(start, scale, "start")
    t1 = parse_bound(end, scale, "end")
    if t0 is not None and t1 is not None and t1 < t0:
        raise Invalid("end is before start")
    return t0, t1


def iso(tai_ns: int) -> str:
    """TAI ns as ISO 8601 UTC with a ``Z``."""
    return str(timescales.tai_ns_to_iso(np.array([tai_ns], dtype=np.int64))[0])
