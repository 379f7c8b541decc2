"""Earth orientation parameters from an IERS ``finals2000A`` file, interpolated to any time.

The IERS Rapid Service/Prediction Centre publishes daily polar motion (x_p, y_p), UT1-UTC, LOD and
celestial-pole offsets (dX, dY w.r.t. IAU 2000A) in fixed-width lines, one per UTC midnight
(``readme.finals2000A``, USNO; columns below, 1-based as in that readme):

    1-2 year (2 digits), 3-4 month, 5-6 day, 8-15 MJD (UTC, F8.2), 17 flag of Bulletin A polar
    motion (I = IERS final, P = prediction), 19-27 PM-x [arcsec], 28-36 its error, 38-46 PM-y,
    47-55 its error, 58 flag of Bulletin A UT1-UTC, 59-68 UT1-UTC [s], 69-78 its error,
    80-86 LOD [ms], 87-93 its error, 96 nutation flag, 98-106 dX [mas], 107-115 error,
    117-125 dY [mas], 126-134 error, 135-144 Bulletin B PM-x [arcsec], 145-154 Bulletin B PM-y,
    155-165 Bulletin B UT1-UTC [s], 166-175 Bulletin B dX [mas], 176-185 Bulletin B dY [mas].

Bulletin B values are used where present (they are the final ones), Bulletin A otherwise (as
astropy's IERS_A table does); the ``pm_source``/``ut1_source`` columns say which (B, I or P). Rows
without UT1-UTC (the far future) are dropped.

Interpolation (IERS Conventions 2010 §5.5.1 and the IERS ``interp.f`` routine): 4-point Lagrange
(cubic) in time over the daily values; UT1-UTC jumps by 1 s at a leap second, so UT1-TAI (which is
continuous) is interpolated and UT1-UTC rebuilt with the TAI-UTC in force at each instant. The
diurnal and sub-diurnal tidal and libration terms of UT1 and polar motion (< 0.1 ms, < 0.1 mas)
are not added. Times are int64 ``tai_ns``; angles in the result are radians.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.frames.earth_orientation import EarthOrientation
from processing.tasks import ParsedReference
from processing.time import timescales
from processing.units import NS_PER_S, RAD_PER_ARCSEC

MJD_UNIX_EPOCH = 40587.0
MIN_LINE_LENGTH = 68  # through the Bulletin A UT1-UTC field

COLUMNS = ("time_tai_ns", "mjd_utc", "xp_arcsec", "yp_arcsec", "dut1_s", "ut1_minus_tai_s", "lod_ms",
           "dx_mas", "dy_mas", "pm_source", "ut1_source")
"""Columns of a parsed finals2000A table (see :func:`parse_finals2000a`)."""


class EopFormatError(ValueError):
    """A finals2000A file that cannot be read; the message names the line and field."""


class EopCoverageError(ValueError):
    """Times outside the span of the EOP table."""


def _field(line: str, first: int, last: int) -> str:
    """Columns first..last (1-based, inclusive) of a fixed-width line, stripped."""
    return line[first - 1:last].strip()


def _number(line: str, first: int, last: int, lineno: int, name: str) -> float:
    text = _field(line, first, last)
    if not text:
        return float("nan")
    try:
        return float(text)
    except ValueError:
        raise EopFormatError(f"line {lineno}: {name} (columns {first}-{last}) should be a number, "
                             f"got {text!r}") from None


@dataclass(frozen=True)
class _Row:
    mjd: float
    xp: float
    yp: float
    dut1: float
    lod: float
    dx: float
    dy: float
    pm_source: str
    ut1_source: str


def _parse_line(line: str, lineno: int) -> _Row | None:
    mjd = _number(line, 8, 15, lineno, "MJD")
    if not np.isfinite(mjd):
        raise EopFormatError(f"line {lineno}: no MJD in columns 8-15: {line[:20]!r}")
    if mjd != np.floor(mjd):
        raise EopFormatError(f"line {lineno}: MJD {mjd} is not at 0h UTC (finals2000A has daily rows)")
    ymd = (_field(line, 1, 2), _field(line, 3, 4), _field(line, 5, 6))
    if not all(x.isdigit() for x in ymd):
        raise EopFormatError(f"line {lineno}: columns 1-6 should be the date YYMMDD, got {line[:6]!r}")
    dut1_a = _number(line, 59, 68, lineno, "UT1-UTC")
    dut1_b = _number(line, 155, 165, lineno, "Bulletin B UT1-UTC")
    if not np.isfinite(dut1_a) and not np.isfinite(dut1_b):
        return None  # a future row with the date only
    xp_a, yp_a = _number(line, 19, 27, lineno, "PM-x"), _number(line, 38, 46, lineno, "PM-y")
    xp_b, yp_b = _number(line, 135, 144, lineno, "Bulletin B PM-x"), _number(line, 145, 154, lineno, "Bulletin B PM-y")
    use_b_pm = np.isfinite(xp_b) and np.isfinite(yp_b)
    pm_flag = _field(line, 17, 17) or "?"
    ut1_flag = _field(line, 58, 58) or "?"
    if not use_b_pm and not (np.isfinite(xp_a) and np.isfinite(yp_a)):
        raise EopFormatError(f"line {lineno} (MJD {mjd:.0f}): UT1-UTC without polar motion")
    for flag, what in ((pm_flag, "polar-motion"), (ut1_flag, "UT1-UTC")):
        if flag not in ("I", "P", "?"):
            raise EopFormatError(f"line {lineno}: the {what} flag should be I or P, got {flag!r}")
    dx_b, dy_b = _number(line, 166, 175, lineno, "Bulletin B dX"), _number(line, 176, 185, lineno, "Bulletin B dY")
    dx_a, dy_a = _number(line, 98, 106, lineno, "dX"), _number(line, 117, 125, lineno, "dY")
    return _Row(
        mjd=mjd,
        xp=xp_b if use_b_pm else xp_a,
        yp=yp_b if use_b_pm else yp_a,
        dut1=dut1_b if np.isfinite(dut1_b) else dut1_a,
        lod=_number(line, 80, 86, lineno, "LOD"),
        dx=dx_b if np.isfinite(dx_b) else dx_a,
        dy=dy_b if np.isfinite(dy_b) else dy_a,
        pm_source="B" if use_b_pm else pm_flag,
        ut1_source="B" if np.isfinite(dut1_b) else ut1_flag,
    )


def mjd_utc_to_tai_ns(mjd_utc: ArrayLike) -> NDArray[np.int64]:
    """tai_ns of UTC midnights given as whole MJD (UTC) values (int64, same shape)."""
    mjd = np.asarray(mjd_utc, dtype=np.float64)
    days = np.rint(mjd - MJD_UNIX_EPOCH).astype(np.int64)
    return timescales.epoch_ns_to_tai_ns(days * 86_400 * NS_PER_S, "utc")


def parse_finals2000a(raw: bytes) -> dict[str, NDArray[Any]]:
    """Parse an IERS finals2000A file (``finals2000A.all``/``.data``/``.daily``) into columns.

    raw: the file's bytes (ASCII). Returns the :data:`COLUMNS`: time_tai_ns (int64, the UTC
    midnight of each row), mjd_utc, xp_arcsec, yp_arcsec, dut1_s (UT1-UTC), ut1_minus_tai_s, lod_ms,
    dx_mas, dy_mas (float; NaN where the file has none) and pm_source/ut1_source ("B" Bulletin B,
    "I" Bulletin A final, "P" Bulletin A prediction), sorted by time. Blank lines are skipped;
    any other unreadable line raises :class:`EopFormatError` naming it.
    """
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError as exc:
        raise EopFormatError(f"finals2000A files are ASCII; byte {exc.start} is not") from None
    rows: list[_Row] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        if len(line.rstrip()) < 15:
            raise EopFormatError(f"line {lineno}: too short for a finals2000A row ({len(line.rstrip())} "
                                 f"characters, the MJD ends in column 15)")
        row = _parse_line(line, lineno)
        if row is not None:
            rows.append(row)
    if len(rows) < 2:
        raise EopFormatError(f"need at least 2 daily rows with UT1-UTC, found {len(rows)}")
    mjd = np.array([r.mjd for r in rows])
    order = np.argsort(mjd, kind="stable")
    mjd = mjd[order]
    if np.any(np.diff(mjd) <= 0):
        dup = mjd[1:][np.diff(mjd) <= 0][0]
        raise EopFormatError(f"MJD {dup:.0f} appears twice")
    t = mjd_utc_to_tai_ns(mjd)
    dut1 = np.array([r.dut1 for r in rows])[order]
    tai_minus_utc = timescales.tai_minus_utc_s(t).astype(np.float64)
    return {
        "time_tai_ns": t,
        "mjd_utc": mjd,
        "xp_arcsec": np.array([r.xp for r in rows])[order],
        "yp_arcsec": np.array([r.yp for r in rows])[order],
        "dut1_s": dut1,
        "ut1_minus_tai_s": dut1 - tai_minus_utc,
        "lod_ms": np.array([r.lod for r in rows])[order],
        "dx_mas": np.array([r.dx for r in rows])[order],
        "dy_mas": np.array([r.dy for r in rows])[order],
        "pm_source": np.array([r.pm_source for r in rows], dtype=object)[order],
        "ut1_source": np.array([r.ut1_source for r in rows], dtype=object)[order],
    }


def parse_finals2000a_reference(raw: bytes) -> ParsedReference:
    """:func:`parse_finals2000a` as a reference data set: columns, covered span and details."""
    cols = parse_finals2000a(raw)
    predicted = cols["ut1_source"] == "P"
    details: dict[str, Any] = {
        "format": "IERS finals2000A",
        "rows": int(cols["mjd_utc"].size),
        "first_mjd_utc": float(cols["mjd_utc"][0]),
        "last_mjd_utc": float(cols["mjd_utc"][-1]),
        "bulletin_b_rows": int(np.sum(cols["ut1_source"] == "B")),
        "predicted_rows": int(np.sum(predicted)),
        "first_predicted_mjd_utc": float(cols["mjd_utc"][predicted][0]) if np.any(predicted) else None,
    }
    return ParsedReference(columns=dict(cols), start_tai_ns=int(cols["time_tai_ns"][0]),
                           end_tai_ns=int(cols["time_tai_ns"][-1]), details=details)


def lagrange4(x: NDArray, y: NDArray, xq: NDArray) -> NDArray:
    """4-point Lagrange interpolation (IERS interp.f) of y(x) at xq; linear with 2-3 points.

    x (N,) strictly increasing (float, any unit), y (N,) or (N, K), xq (M,) inside [x0, x_{N-1}].
    The 4 nodes are the two on each side of xq (shifted inwards at the ends).
    """
    n = x.size
    yy = y if y.ndim == 2 else y[:, None]
    if n < 4:
        out = np.stack([np.interp(xq, x, yy[:, k]) for k in range(yy.shape[1])], axis=-1)
        return out if y.ndim == 2 else out[:, 0]
    j = np.clip(np.searchsorted(x, xq, side="right") - 2, 0, n - 4)
    nodes = j[:, None] + np.arange(4)
    xn = x[nodes]  # (M, 4)
    w = np.ones_like(xn)
    for a in range(4):
        for b in range(4):
            if a != b:
                w[:, a] *= (xq - xn[:, b]) / (xn[:, a] - xn[:, b])
    out = np.einsum("ma,mak->mk", w, yy[nodes])
    return out if y.ndim == 2 else out[:, 0]


def interpolate_eop(columns: Mapping[str, ArrayLike], tai_ns: ArrayLike, source: str = "IERS finals2000A"
                    ) -> EarthOrientation:
    """EarthOrientation at the times ``tai_ns`` (...) from parsed finals2000A ``columns``.

    Lagrange 4-point interpolation of x_p, y_p and UT1-TAI (module docstring); UT1-UTC = UT1-TAI +
    (TAI-UTC at each instant). Times outside the table raise :class:`EopCoverageError`. Returns
    per-sample arrays shaped like tai_ns; ``source`` is carried into the result for reports.
    """
    t = np.asarray(tai_ns, dtype=np.int64)
    shape = t.shape
    tq = t.reshape(-1)
    t_tab = np.asarray(columns["time_tai_ns"], dtype=np.int64)
    if t_tab.size < 2:
        raise EopCoverageError(f"an EOP table needs at least 2 rows, got {t_tab.size}")
    if tq.size and (tq.min() < t_tab[0] or tq.max() > t_tab[-1]):
        lo, hi = timescales.tai_ns_to_iso(np.array([t_tab[0], t_tab[-1]]))
        first, last = timescales.tai_ns_to_iso(np.array([tq.min(), tq.max()]))
        raise EopCoverageError(f"EOP table covers {lo} .. {hi}, the times span {first} .. {last}")
    x = (t_tab - t_tab[0]).astype(np.float64) / NS_PER_S / 86_400.0
    xq = (tq - t_tab[0]).astype(np.float64) / NS_PER_S / 86_400.0
    y = np.stack([np.asarray(columns["xp_arcsec"], float), np.asarray(columns["yp_arcsec"], float),
                  np.asarray(columns["ut1_minus_tai_s"], float)], axis=-1)
    if not np.all(np.isfinite(y)):
        raise EopCoverageError("the EOP table has rows without polar motion or UT1")
    v = lagrange4(x, y, xq)
    dut1 = v[:, 2] + timescales.tai_minus_utc_s(tq).astype(np.float64)
    return EarthOrientation(
        dut1_s=dut1.reshape(shape),
        xp_rad=(v[:, 0] * RAD_PER_ARCSEC).reshape(shape),
        yp_rad=(v[:, 1] * RAD_PER_ARCSEC).reshape(shape),
        source=source,
    )
