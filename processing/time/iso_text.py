"""ISO 8601 text at array speed: the fields of fixed-width strings (:func:`scan_iso`) and zero-padded
digits written into character-code arrays (:func:`put_digits`), for processing.time.timescales, which
checks the fields, applies the scale and reports bad rows."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["ISO_WIDTH", "digit_table", "put_digits", "scan_iso"]

ISO_WIDTH = 36  # longest valid string is 35 characters: 19 + '.' + 9 digits + '+HH:MM'


def scan_iso(text: NDArray[np.str_]) -> tuple[NDArray[np.bool_], NDArray[np.bool_], dict[str, NDArray[Any]]]:
    """Read the fields of ISO 8601 strings (a 1-D numpy array of dtype U36).

    Returns (syntax_ok, too_many_fraction_digits, fields); the fields are int32/int64 arrays,
    meaningless where syntax_ok is False: year, month, day, hour, minute, second (0-99 unchecked),
    frac_ns, zone hour, zone minute, zone_s (signed offset of the zone from the scale, s).
    """
    n = text.shape[0]
    wide = text.view(np.uint32).reshape(n, ISO_WIDTH)
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
    zone = chars.reshape(-1)[(np.arange(n, dtype=np.int64) * ISO_WIDTH + z0)[:, None] + np.arange(6)]
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


def digit_table(width: int) -> NDArray[np.uint32]:
    """(10**width, width) character codes of the zero-padded decimal numbers 0 .. 10**width - 1."""
    numbers = np.arange(10**width)
    return np.stack([ord("0") + numbers // 10 ** (width - 1 - j) % 10 for j in range(width)], axis=1).astype(
        np.uint32
    )


def put_digits(out: NDArray[np.uint32], col: int, value: NDArray[np.int64], width: int) -> None:
    """Write ``value`` (0 <= value < 10**width) zero-padded into columns col .. col+width-1."""
    pairs, three = digit_table(2), digit_table(3)
    while width:
        w = 3 if width % 2 else 2
        width -= w
        out[:, col + width:col + width + w] = (three if w == 3 else pairs)[value % 10**w]
        value = value // 10**w
