"""Time arguments of requests: ISO 8601 or seconds since 1970 on a time scale, to TAI nanoseconds."""

from __future__ import annotations

import numpy as np

from app.services.errors import Invalid
from processing.time import timescales


def parse_bound(value: str | None, scale: str, field: str) -> int | None:
    """A window bound: None or "" -> None; a number -> seconds since 1970 on ``scale``; else ISO 8601.

    Raises Invalid("<field>: ...") for a time that does not parse or does not exist on the scale."""
    if value is None or value == "":
        return None
    try:
        try:
            seconds = float(value)
        except ValueError:
            return int(timescales.iso_to_tai_ns(np.array([value], dtype=object), scale)[0])
        return int(timescales.seconds_to_tai_ns(np.array([seconds]), scale)[0])
    except timescales.TimeValueError as exc:
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
