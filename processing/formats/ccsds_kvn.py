"""Shared pieces of the CCSDS Navigation Data Messages in KVN ('Keyword = Value' Notation).

Used by :mod:`processing.formats.ccsds_adm` (AEM) and :mod:`processing.formats.ccsds_odm` (OEM).
Rules (CCSDS 504.0-B-2 §6, 502.0-B-3 §7, the same for both): one item per line; blank lines and
leading/trailing blanks are ignored; ``COMMENT`` lines carry free text; ``KEY = VALUE`` lines may end
with a unit in square brackets; keywords are upper case; block delimiters (META_START, DATA_START,
COVARIANCE_START, ...) stand alone on their lines; data lines are blank-separated numbers led by an
epoch. Epochs (§6.8.9 / §7.5.10): ``YYYY-MM-DDThh:mm:ss[.d...][Z]`` or ``YYYY-DDDThh:mm:ss[.d...][Z]``
on the message's TIME_SYSTEM; UTC may read 23:59:60 inside a leap second.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.time import timescales

TIME_SYSTEMS = {"UTC": "utc", "TAI": "tai", "TT": "tt", "GPS": "gps"}
"""CCSDS TIME_SYSTEM values this service converts (to our scales); TDB, TCB, UT1, MET, ... are not."""

_KV = re.compile(r"^([A-Z][A-Z0-9_]*)\s*=\s*(.*?)\s*$")
_UNIT = re.compile(r"\s*\[[^\]]*\]\s*$")
_DOY = re.compile(r"^(\d{4})-(\d{3})T(.*)$")
_CAL = re.compile(r"^\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2}(\.\d+)?Z?$")


class KvnError(ValueError):
    """A KVN message that does not follow the CCSDS syntax; the message names the line."""


@dataclass(frozen=True)
class Line:
    """One non-blank line: 1-based number, kind ("kv", "comment", "marker", "data"), key/value."""

    number: int
    kind: str
    key: str
    value: str
    text: str


def tokenize(text: str | bytes) -> Iterator[Line]:
    """Non-blank lines of a KVN message, classified. Bytes are decoded as UTF-8 (ASCII in practice)."""
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise KvnError(f"not a text file: byte {exc.start} is not UTF-8") from None
    for number, raw in enumerate(text.splitlines(), start=1):
        s = raw.strip()
        if not s:
            continue
        if s == "COMMENT" or s.startswith("COMMENT ") or s.startswith("COMMENT\t"):
            yield Line(number, "comment", "COMMENT", s[7:].strip(), s)
            continue
        m = _KV.match(s)
        if m:
            value = _UNIT.sub("", m.group(2)).strip()
            yield Line(number, "kv", m.group(1), value, s)
        elif re.fullmatch(r"[A-Z][A-Z0-9_]*_(START|STOP)", s):
            yield Line(number, "marker", s, "", s)
        else:
            yield Line(number, "data", "", s, s)


@dataclass
class Block:
    """The keyword lines of a header or metadata block: values, the line of each keyword, comments."""

    values: dict[str, str]
    line_of: dict[str, int]
    comments: list[str]


def read_block(lines: list[Line], i: int, stop: str, keys: Iterable[str], what: str,
               error: type[ValueError], *, unique: bool) -> tuple[Block, int]:
    """Read ``KEY = VALUE`` and COMMENT lines from ``lines[i]`` up to the line whose key is ``stop``.

    Returns the block and the index of the ``stop`` line (``len(lines)`` when it never comes). A line
    that is neither a comment nor one of ``keys`` raises ``error`` naming the line and ``what`` (e.g.
    "the OEM header"); with ``unique`` a keyword given twice does too (else the last one counts)."""
    allowed = set(keys)
    block = Block({}, {}, [])
    while i < len(lines) and lines[i].key != stop:
        ln = lines[i]
        if ln.kind == "comment":
            block.comments.append(ln.value)
        elif ln.kind == "kv" and ln.key in allowed:
            if unique and ln.key in block.values:
                raise error(f"line {ln.number}: {ln.key} given twice in {what}")
            block.values[ln.key] = ln.value
            block.line_of[ln.key] = ln.number
        else:
            raise error(f"line {ln.number}: unexpected {ln.text[:60]!r} in {what}")
        i += 1
    return block, i


def time_scale(time_system: str, where: str) -> str:
    """Our scale name of a CCSDS TIME_SYSTEM; KvnError for the ones not supported."""
    key = time_system.strip().upper()
    if key not in TIME_SYSTEMS:
        raise KvnError(f"{where}: TIME_SYSTEM {time_system!r} is not supported; use one of "
                       f"{', '.join(TIME_SYSTEMS)}")
    return TIME_SYSTEMS[key]


def _calendar(epoch: str) -> str:
    """'YYYY-DDDThh:mm:ss...' -> 'YYYY-MM-DDThh:mm:ss...'; calendar form unchanged."""
    m = _DOY.match(epoch)
    if not m:
        return epoch
    year, doy = int(m.group(1)), int(m.group(2))
    days = 366 if (year % 4 == 0 and year % 100 != 0) or year % 400 == 0 else 365
    if not 1 <= doy <= days:
        raise KvnError(f"day of year {doy} out of range in epoch {epoch!r}")
    date = np.datetime64(f"{year:04d}-01-01") + np.timedelta64(doy - 1, "D")
    return f"{date}T{m.group(3)}"


def parse_epochs(epochs: Iterable[str], scale: str, where: str) -> NDArray[np.int64]:
    """tai_ns of CCSDS epoch strings on ``scale`` (utc, tai, tt, gps). Fractions beyond 9 digits are
    cut to the nanosecond; a trailing Z is accepted. KvnError names the first bad epoch."""
    out = []
    for e in epochs:
        s = _calendar(e.strip())
        if not _CAL.match(s):
            raise KvnError(f"{where}: epoch {e!r} is not YYYY-MM-DDThh:mm:ss[.d] or YYYY-DDDThh:mm:ss[.d]")
        s = s.rstrip("Z")
        if "." in s:
            head, frac = s.split(".")
            s = f"{head}.{frac[:9]}"
        out.append(s)
    try:
        return timescales.iso_to_tai_ns(np.array(out, dtype=object), scale)
    except timescales.TimeValueError as exc:
        raise KvnError(f"{where}: {exc}") from None


def format_epochs(tai_ns: ArrayLike, scale: str) -> list[str]:
    """CCSDS epoch strings 'YYYY-MM-DDThh:mm:ss[.fff...]' (no zone letter) of tai_ns on ``scale``;
    exact to the nanosecond (the fewest of 0/3/6/9 digits that do), so they parse back identically."""
    iso = timescales.tai_ns_to_iso(np.asarray(tai_ns, dtype=np.int64), scale)
    return [str(x).rstrip("Z") for x in iso]


def format_float(x: float) -> str:
    """Shortest text that reads back as the same float64, always with a decimal point ('1.0e-05')."""
    f = float(x)
    if not np.isfinite(f):
        raise KvnError(f"cannot write the non-finite number {f!r} in a CCSDS message")
    r = repr(f)
    mantissa, _, exponent = r.partition("e")
    if "." not in mantissa:
        mantissa += ".0"
    return mantissa + ("e" + exponent if exponent else "")


def parse_floats(fields: list[str], line: Line, what: str) -> list[float]:
    try:
        return [float(x) for x in fields]
    except ValueError:
        raise KvnError(f"line {line.number}: {what} must be numbers, got {line.text[:80]!r}") from None
