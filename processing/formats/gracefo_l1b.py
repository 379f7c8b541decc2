"""GRACE-FO Level-1B ASCII products (release 04): SCA1B, GNV1B, IMU1B, MAG1B.

Each file is a YAML header ending with the line ``# End of YAML header`` and then blank-separated
rows whose columns are listed, in order, under ``header: variables:`` (e.g. ``gps_time``,
``GRACEFO_id``, ...). The header is parsed with PyYAML and the columns are looked up by name, so a
reordered or extended release still reads. What the headers state (2023-06-01 files, PO.DAAC,
doi:10.5067/GFJPL-L1B04), and how it is used here:

- time: ``gps_time`` "continuous seconds past 01-Jan-2000 11:59:47 UTC" (SCA1B, GNV1B), i.e. GPS
  seconds since 2000-01-01T12:00:00 GPS (``epoch_time`` 2000-01-01T12:00:00.00); IMU1B and MAG1B
  split it into an integer part and a fraction (``rcvtime_frac`` microseconds; MAG1B
  ``time_frac`` is declared "nanoseconds" but its values (83329, 583329 at 2 Hz) are microseconds:
  as nanoseconds the samples would be 0.5 ms apart and then 999.5 ms; the unit that gives a
  regular sampling is taken and a note says so). TAI = GPS + 19 s exactly.
- SCA1B: ``quatangle`` = cos(theta/2) FIRST, then i, j, k; the summary says "rotation quaternions
  from Inertial Frame to SRF": the rotation that takes the inertial axes into the Science
  Reference Frame axes, whose matrix has the SRF axes as columns in inertial coordinates -- our
  q_IS (SRF -> inertial coordinates). Checked on the data: with this reading the SRF +X axis of
  GRACE-FO C lies within 1 deg of the flight direction line and +Z near nadir, as the K-band
  ranging pointing requires (tests/app/test_job_orbital_attitude.py). qualflg bits are kept.
- GNV1B: ``coord_ref`` E = Earth-centred Earth-fixed (ITRF), I = inertial; position m, velocity
  m/s, with formal errors.
- IMU1B: one row per gyro axis (``gyro_id`` 1-3; 4 would be a fourth gyro), ``FiltAng`` = the
  low-pass filtered accumulated angle [deg] of that axis; axes are sampled at slightly different
  times (~1 ms apart). Rates and increments are derived in :func:`imu_rates` / :func:`imu_increments`.
- MAG1B: ``MfvX_RAW``.. = measured field in the SRF [microtesla]; magnetorquer currents [mA].
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from processing.time import timescales
from processing.units import NS_PER_S

END_OF_HEADER = "# End of YAML header"
GPS_EPOCH_2000_TAI_NS = int(timescales.iso_to_tai_ns(np.array(["2000-01-01T12:00:00"], dtype=object), "gps")[0])
"""tai_ns of 2000-01-01T12:00:00 GPS (= 11:59:47 UTC), the origin of GRACE-FO L1B times."""
PRODUCTS = ("SCA1B", "GNV1B", "IMU1B", "MAG1B")


class GraceFoFormatError(ValueError):
    """A file that is not a readable GRACE-FO Level-1B product; the message says where."""


@dataclass(frozen=True)
class L1bFile:
    """A parsed product: ``product`` (SCA1B, ...), ``satellite`` (C or D), header (the YAML mapping),
    ``columns`` (variable name -> array: floats, or str for character columns), ``notes``."""

    product: str
    satellite: str
    header: dict[str, Any]
    columns: dict[str, NDArray]
    notes: tuple[str, ...] = field(default=())

    @property
    def n_rows(self) -> int:
        return int(next(iter(self.columns.values())).size)


_SIGNATURE = {"quatangle": "SCA1B", "xpos": "GNV1B", "FiltAng": "IMU1B", "MfvX_RAW": "MAG1B"}
_TEXT_COLUMNS = {"GRACEFO_id", "coord_ref", "time_ref", "qualflg"}


def parse_l1b(raw: bytes) -> L1bFile:
    """Parse any of the four products (recognised by its variables). GraceFoFormatError if not."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise GraceFoFormatError(f"not a text file (byte {exc.start} is not UTF-8)") from None
    head, sep, body = text.partition(END_OF_HEADER)
    if not sep:
        raise GraceFoFormatError(f"no '{END_OF_HEADER}' line: not a GRACE-FO Level-1B ASCII file")
    try:
        meta = yaml.safe_load(head)
    except yaml.YAMLError as exc:
        raise GraceFoFormatError(f"the YAML header does not parse: {str(exc).splitlines()[0]}") from None
    if not isinstance(meta, dict) or not isinstance(meta.get("header"), dict):
        raise GraceFoFormatError("the YAML header has no 'header:' mapping")
    header = meta["header"]
    variables = header.get("variables")
    if not isinstance(variables, list) or not all(isinstance(v, dict) and len(v) == 1 for v in variables):
        raise GraceFoFormatError("the header lists no 'variables' (one mapping per column)")
    names = [next(iter(v)) for v in variables]
    product = next((_SIGNATURE[n] for n in names if n in _SIGNATURE), None)
    if product is None:
        raise GraceFoFormatError(f"unknown product: columns {', '.join(names[:8])}; expected one of "
                                 f"{', '.join(PRODUCTS)}")
    rows = [line.split() for line in body.splitlines()[1:] if line.strip()]
    if not rows:
        raise GraceFoFormatError(f"{product}: no data rows after the header")
    bad = next((i for i, r in enumerate(rows) if len(r) != len(names)), None)
    if bad is not None:
        raise GraceFoFormatError(f"{product}: data row {bad + 1} has {len(rows[bad])} fields, the header lists "
                                 f"{len(names)} ({', '.join(names)})")
    cols_text = list(zip(*rows, strict=True))
    columns: dict[str, NDArray] = {}
    for name, values in zip(names, cols_text, strict=True):
        if name in _TEXT_COLUMNS:
            columns[name] = np.array(values, dtype=object)
            continue
        try:
            columns[name] = np.array(values, dtype=np.float64)
        except ValueError:
            raise GraceFoFormatError(f"{product}: column {name} has a value that is not a number") from None
    sats = sorted(set(columns.get("GRACEFO_id", np.array(["?"], dtype=object)).tolist()))
    if len(sats) != 1:
        raise GraceFoFormatError(f"{product}: rows of several satellites ({', '.join(sats)}); upload one at a time")
    return L1bFile(product=product, satellite=sats[0], header=header, columns=columns)


def _whole_and_fraction_ns(whole_s: NDArray, frac: NDArray, frac_unit_ns: int) -> NDArray[np.int64]:
    return (GPS_EPOCH_2000_TAI_NS + whole_s.astype(np.int64) * NS_PER_S
            + np.rint(frac * frac_unit_ns).astype(np.int64))


def times_tai_ns(f: L1bFile) -> tuple[NDArray[np.int64], tuple[str, ...]]:
    """tai_ns of every row and notes (MAG1B fraction unit; rows not on GPS time are rejected)."""
    c = f.columns
    if "time_ref" in c and np.any(c["time_ref"] != "G"):
        n = int(np.sum(c["time_ref"] != "G"))
        raise GraceFoFormatError(f"{f.product}: {n} rows are on receiver/OBC time (time_ref R), not GPS time")
    if "gps_time" in c:
        s = c["gps_time"]
        whole = np.floor(s)
        return _whole_and_fraction_ns(whole, s - whole, NS_PER_S), ()
    if "rcvtime_intg" in c:
        return _whole_and_fraction_ns(c["rcvtime_intg"], c["rcvtime_frac"], 1_000), ()
    if "time_intg" in c:
        frac = c["time_frac"]
        if np.all(frac < 1_000_000) and f.n_rows > 2:
            as_us = _whole_and_fraction_ns(c["time_intg"], frac, 1_000)
            as_ns = _whole_and_fraction_ns(c["time_intg"], frac, 1)
            if np.std(np.diff(as_us)) < np.std(np.diff(as_ns)):
                return as_us, (f"{f.product}: time_frac is declared in nanoseconds but its values only make a "
                               "regular sampling as microseconds; read as microseconds",)
        return _whole_and_fraction_ns(c["time_intg"], frac, 1), ()
    raise GraceFoFormatError(f"{f.product}: no time column (gps_time, rcvtime_intg or time_intg)")


def sca_quaternions(f: L1bFile) -> tuple[NDArray[np.int64], NDArray]:
    """SCA1B: tai_ns (N,) and q_IS (N, 4) scalar first (SRF -> inertial; module docstring)."""
    if f.product != "SCA1B":
        raise GraceFoFormatError(f"expected SCA1B, got {f.product}")
    t, _ = times_tai_ns(f)
    c = f.columns
    q = np.stack([c["quatangle"], c["quaticoeff"], c["quatjcoeff"], c["quatkcoeff"]], axis=-1)
    return t, q


def gnv_states(f: L1bFile) -> tuple[NDArray[np.int64], NDArray, NDArray, str]:
    """GNV1B: tai_ns (N,), r (N, 3) [m], v (N, 3) [m/s] and the frame ("E" Earth-fixed, "I" inertial)."""
    if f.product != "GNV1B":
        raise GraceFoFormatError(f"expected GNV1B, got {f.product}")
    t, _ = times_tai_ns(f)
    c = f.columns
    frames = sorted(set(c["coord_ref"].tolist()))
    if len(frames) != 1 or frames[0] not in ("E", "I"):
        raise GraceFoFormatError(f"GNV1B: coord_ref must be E or I throughout, got {', '.join(frames)}")
    r = np.stack([c["xpos"], c["ypos"], c["zpos"]], axis=-1)
    v = np.stack([c["xvel"], c["yvel"], c["zvel"]], axis=-1)
    return t, r, v, frames[0]


def imu_angles(f: L1bFile) -> tuple[NDArray[np.int64], NDArray, tuple[str, ...]]:
    """IMU1B: common times (N,) (those of gyro 1) and the filtered angles (N, 3) [rad] of gyros 1-3,
    axes 2 and 3 interpolated linearly to gyro 1's time tags (they lag by ~1-2 ms; at orbital rates
    of ~0.06 deg/s the interpolation error is below 1e-9 rad). Samples beyond the other axes' spans
    are dropped."""
    if f.product != "IMU1B":
        raise GraceFoFormatError(f"expected IMU1B, got {f.product}")
    t, notes = times_tai_ns(f)
    gid = f.columns["gyro_id"].astype(int)
    ang = np.radians(f.columns["FiltAng"])
    present = sorted(set(gid.tolist()))
    if not {1, 2, 3} <= set(present):
        raise GraceFoFormatError(f"IMU1B: gyros 1, 2 and 3 are needed, found {present}")
    if any(g not in (1, 2, 3) for g in present):
        notes = notes + (f"IMU1B: gyro ids {[g for g in present if g not in (1, 2, 3)]} ignored (only 1-3 are "
                         "the three axes)",)
    t1 = t[gid == 1]
    if np.any(np.diff(t1) <= 0):
        raise GraceFoFormatError("IMU1B: gyro 1 times are not increasing")
    keep = np.ones(t1.size, dtype=bool)
    out = np.empty((t1.size, 3))
    out[:, 0] = ang[gid == 1]
    for k in (2, 3):
        tk, ak = t[gid == k], ang[gid == k]
        keep &= (t1 >= tk[0]) & (t1 <= tk[-1])
        out[:, k - 1] = np.interp((t1 - t1[0]).astype(float), (tk - t1[0]).astype(float), ak)
    return t1[keep], out[keep], notes


def imu_rates(t: NDArray[np.int64], angles_rad: NDArray) -> tuple[NDArray[np.int64], NDArray]:
    """Angular rates [rad/s] at the interior samples by central differences of the angles,
    w(t_k) = (a_{k+1} - a_{k-1}) / (t_{k+1} - t_{k-1}) (second order for regular sampling; the
    instrument's own 2nd-order low-pass filter stays in the data)."""
    if t.size < 3:
        raise GraceFoFormatError(f"IMU1B: need at least 3 samples per axis for rates, got {t.size}")
    dt = (t[2:] - t[:-2]).astype(np.float64) / NS_PER_S
    return t[1:-1], (angles_rad[2:] - angles_rad[:-2]) / dt[:, None]


def imu_increments(t: NDArray[np.int64], angles_rad: NDArray) -> tuple[NDArray[np.int64], NDArray, NDArray]:
    """Angle increments [rad] over each interval ending at t_k (k >= 1) and the intervals [s]."""
    if t.size < 2:
        raise GraceFoFormatError(f"IMU1B: need at least 2 samples for increments, got {t.size}")
    return t[1:], np.diff(angles_rad, axis=0), np.diff(t).astype(np.float64) / NS_PER_S


def mag_field_nt(f: L1bFile) -> tuple[NDArray[np.int64], NDArray, tuple[str, ...]]:
    """MAG1B: tai_ns (N,), measured field (N, 3) in the SRF [nT] (the file's microtesla x 1000), notes."""
    if f.product != "MAG1B":
        raise GraceFoFormatError(f"expected MAG1B, got {f.product}")
    t, notes = times_tai_ns(f)
    c = f.columns
    b = np.stack([c["MfvX_RAW"], c["MfvY_RAW"], c["MfvZ_RAW"]], axis=-1) * 1000.0
    return t, b, notes
