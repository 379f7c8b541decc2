"""Validate a decoded upload against a stream schema and build the canonical table.

All or nothing: every problem found is collected (row, column, reason) and one UploadError is raised;
otherwise the result is the canonical table (``time_tai_ns``, ``sensor``, value columns with fixed
types), sorted by the sample identity, plus the original row index of every output row.
Quaternions: columns q0..q3 (q0 scalar) or qw, qx, qy, qz; norms off by more than the tolerance are
errors, smaller deviations are normalised; the sign is made canonical (q0 >= 0).
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from app.ingest.errors import MAX_REPORTED, RowError, UploadError
from app.names import valid_name
from processing.attitude.rotations import quat_canonical, quat_conjugate
from processing.streams import GNSS_SYSTEMS, QUATERNION_COLUMNS, SENSOR_COLUMN, TIME_COLUMN, StreamSpec
from processing.time import timescales
from storage.telemetry import arrow_schema

ZONED_TIME = r"\d{2}:\d{2}:\d{2}(?:[.,]\d+)?\s*(?:[Zz]|[+-]\d{2}(?::?\d{2})?)\s*$"
"""An ISO 8601 time that ends in a zone designator ('Z', '+HH', '+HHMM', '+HH:MM' or '-'): a UTC time."""
UTC_ZONES = ("UTC", "utc", "Z", "+00:00", "Etc/UTC")
QUATERNION_ALIASES = {"qw": "q0", "qx": "q1", "qy": "q2", "qz": "q3"}
DIRECTIONS = ("sensor_to_inertial", "inertial_to_sensor")
SAME_TIME = "same time as an earlier row of the same sensor"
BACKWARDS = "time goes backwards (times must increase per sensor)"
ORDER_ERRORS = (SAME_TIME, BACKWARDS)


@dataclass(frozen=True)
class SensorPolicy:
    """Which sensor names the upload may use and which one applies when none is given."""

    allowed: tuple[str, ...] | None  # None: any valid name
    default: str | None  # None: the upload must say (ambiguous or nothing configured)
    why_no_default: str = ""


@dataclass(frozen=True)
class UploadOptions:
    time_scale: str = "utc"
    sensor: str | None = None
    norm_tolerance: float = 1e-3
    quaternion_direction: str = "sensor_to_inertial"
    n_panels: int | None = None
    notes: tuple[str, ...] = ()  # what a file-format decoder did, reported back to the uploader


@dataclass(frozen=True)
class Validated:
    table: pa.Table
    row_index: np.ndarray  # original upload row of each table row


def _plain(value: object) -> object:
    """numpy scalar -> Python scalar, so messages read 'nan', not 'np.float64(nan)'."""
    return value.item() if isinstance(value, np.generic) else value


class _Errors:
    def __init__(self) -> None:
        self.items: list[RowError] = []
        self.total = 0

    def add(self, row: int | None, column: str | None, message: str) -> None:
        self.total += 1
        if len(self.items) < MAX_REPORTED:
            self.items.append(RowError(row, column, message))

    def add_rows(self, rows: np.ndarray, column: str, message: str, values: np.ndarray | None = None) -> None:
        rows = np.asarray(rows)
        self.total += len(rows)
        for r in rows[: max(0, MAX_REPORTED - len(self.items))]:
            shown = "" if values is None else f" (got {_plain(values[r])!r})"
            self.items.append(RowError(int(r), column, message + shown))

    def raise_if_any(self) -> None:
        if self.total:
            raise UploadError(self.items, self.total)


def _to_float(col: pa.ChunkedArray, name: str, errors: _Errors) -> np.ndarray:
    t = col.type
    if pa.types.is_floating(t) or pa.types.is_integer(t):
        nulls = col.is_null().to_numpy(zero_copy_only=False)
        values = pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False).astype(np.float64)
    elif pa.types.is_string(t) or pa.types.is_large_string(t):
        try:
            values = pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False).astype(np.float64)
            nulls = np.zeros(len(values), dtype=bool)
        except pa.ArrowInvalid:  # Python strings only for a column with a bad value (to name its rows)
            raw = col.to_numpy(zero_copy_only=False)
            parsed = pd.to_numeric(pd.Series(raw, dtype=object), errors="coerce").to_numpy(np.float64)
            bad = np.isnan(parsed) & ~pd.Series(raw, dtype=object).str.strip().str.lower().isin(
                ["nan", "+nan", "-nan"]).to_numpy()
            errors.add_rows(np.flatnonzero(bad), name, "not a number", raw)
            values = np.where(bad, 0.0, parsed)
            nulls = np.zeros(len(values), dtype=bool)
    else:
        errors.add(None, name, f"expected a numeric column, got type {t}")
        return np.zeros(len(col))
    errors.add_rows(np.flatnonzero(nulls), name, "missing value")
    nonfinite = ~np.isfinite(values) & ~nulls
    errors.add_rows(np.flatnonzero(nonfinite), name, "value must be finite", values)
    return np.where(nulls | nonfinite, 0.0, values)


def _to_int(col: pa.ChunkedArray, name: str, errors: _Errors) -> np.ndarray:
    values = _to_float(col, name, errors)
    bad = values != np.round(values)
    errors.add_rows(np.flatnonzero(bad), name, "must be an integer", values)
    return np.where(bad, 0, values).astype(np.int64)


def _to_bool(col: pa.ChunkedArray, name: str, errors: _Errors) -> np.ndarray:
    if pa.types.is_boolean(col.type):
        nulls = col.is_null().to_numpy(zero_copy_only=False)
        errors.add_rows(np.flatnonzero(nulls), name, "missing value")
        return col.fill_null(False).to_numpy(zero_copy_only=False).astype(bool)
    raw = pd.Series(col.to_numpy(zero_copy_only=False), dtype=object).astype(str).str.strip().str.lower()
    truthy = raw.isin(["true", "1", "1.0", "yes"]).to_numpy()
    falsy = raw.isin(["false", "0", "0.0", "no"]).to_numpy()
    errors.add_rows(np.flatnonzero(~(truthy | falsy)), name, "expected true/false or 1/0",
                    raw.to_numpy())
    return truthy


def _to_str(col: pa.ChunkedArray, name: str, errors: _Errors) -> np.ndarray:
    nulls = col.is_null().to_numpy(zero_copy_only=False)
    trimmed = pc.utf8_trim_whitespace(pc.cast(col, pa.string()).fill_null(""))
    values = trimmed.to_numpy(zero_copy_only=False).astype(object)
    errors.add_rows(np.flatnonzero(nulls | (values == "")), name, "missing value")
    return values


def _times(col: pa.ChunkedArray, scale: str, errors: _Errors) -> np.ndarray:
    t = col.type
    n = len(col)
    nulls = col.is_null().to_numpy(zero_copy_only=False)
    if nulls.any():
        errors.add_rows(np.flatnonzero(nulls), "time", "missing time")
        return np.zeros(n, dtype=np.int64)
    try:
        if pa.types.is_timestamp(t):
            if t.tz is not None and scale != "utc":
                errors.add(None, "time", f"timestamps with time zone {t.tz} are UTC times, but time_scale={scale} "
                                         f"reads the times as {scale} readings: upload naive timestamps (no time "
                                         f"zone) read on {scale}, or use time_scale=utc")
                return np.zeros(n, dtype=np.int64)
            if t.tz not in (None, *UTC_ZONES):
                col = pc.cast(col, pa.timestamp("ns", tz="UTC"))
            ns = pc.cast(col, pa.timestamp("ns", tz=t.tz)).cast(pa.int64()).to_numpy(zero_copy_only=False)
            return timescales.epoch_ns_to_tai_ns(ns, scale)
        if pa.types.is_integer(t) or pa.types.is_floating(t):
            seconds = pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False)
            return timescales.seconds_to_tai_ns(seconds, scale)
        if pa.types.is_string(t) or pa.types.is_large_string(t):
            try:  # numbers written as text (CSV): seconds since 1970 on the scale
                seconds = pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False)
            except pa.ArrowInvalid:
                raw = col.to_numpy(zero_copy_only=False)
                if scale != "utc" and _zoned_rows(col, scale, raw, errors):
                    return np.zeros(n, dtype=np.int64)
                return timescales.iso_to_tai_ns(raw, scale)
            return timescales.seconds_to_tai_ns(seconds, scale)
    except timescales.TimeValueError as exc:
        for row, message in exc.rows:
            errors.add(row, "time", message)
        if not exc.rows:
            errors.add(None, "time", str(exc))
        return np.zeros(n, dtype=np.int64)
    errors.add(None, "time", f"expected ISO 8601 strings, numbers or timestamps, got type {t}")
    return np.zeros(n, dtype=np.int64)


def _zoned_rows(col: pa.ChunkedArray, scale: str, raw: np.ndarray, errors: _Errors) -> bool:
    """Report ISO times with an explicit zone ('Z', '+02:00') uploaded with a time_scale other than utc: a
    zone makes a time UTC (local time minus the offset), so reading it on another scale would silently move
    the sample by that scale's offset (since 2017: 18 s for GPS, 37 s for TAI, 69.184 s for TT). True when any
    was found."""
    zoned = pc.match_substring_regex(col, ZONED_TIME).fill_null(False).to_numpy(zero_copy_only=False)
    rows = np.flatnonzero(zoned)
    if rows.size == 0:
        return False
    errors.add_rows(rows, "time", f"has an explicit time zone, which makes it a UTC time, but time_scale={scale} "
                                  f"reads the times as {scale} readings: remove the zone ('Z', '+HH:MM') to give "
                                  f"{scale} readings, or upload with time_scale=utc", raw)
    return True


def _resolve_columns(table: pa.Table, spec: StreamSpec, errors: _Errors) -> dict[str, str]:
    """Map canonical column -> upload column; report missing and unexpected columns."""
    names = list(table.column_names)
    mapping: dict[str, str] = {}
    if spec.quaternion:
        has_q = [c for c in QUATERNION_COLUMNS if c in names]
        has_alias = [c for c in QUATERNION_ALIASES if c in names]
        if has_q and has_alias:
            errors.add(None, ",".join(has_q + has_alias),
                       "give the quaternion either as q0..q3 (q0 scalar) or as qw, qx, qy, qz, not both")
        elif has_alias:
            mapping.update({QUATERNION_ALIASES[a]: a for a in has_alias})
    expected = ["time", *spec.column_names]
    for c in expected:
        if c not in mapping and c in names:
            mapping[c] = c
    if TIME_COLUMN in names:  # exact TAI nanoseconds (as downloaded in Parquet/Arrow): the time, `time` optional
        mapping[TIME_COLUMN] = TIME_COLUMN
        expected = [c for c in expected if c != "time" or c in names]
    allowed = set(expected) | {SENSOR_COLUMN, TIME_COLUMN, "time"}
    if spec.quaternion:
        allowed |= set(QUATERNION_ALIASES)
    for c in names:
        if c not in allowed:
            close = difflib.get_close_matches(c, sorted(allowed), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            errors.add(None, c, f"unexpected column for stream {spec.name} (expected "
                                f"{', '.join(expected)} and optionally sensor){hint}")
    for c in expected:
        if c not in mapping:
            alias = " (or qw, qx, qy, qz)" if spec.quaternion and c in QUATERNION_COLUMNS else ""
            errors.add(None, c, f"missing required column{alias}")
    if SENSOR_COLUMN in names:
        mapping[SENSOR_COLUMN] = SENSOR_COLUMN
    return mapping


@dataclass(frozen=True)
class _Sensors:
    """The sensor of every row as dictionary codes into ``names`` (cheap for a constant sensor)."""

    codes: np.ndarray  # int32, one per row
    names: list[str]

    def arrow(self) -> pa.Array:
        n = len(self.codes)
        if len(self.names) == 1 and n:  # one sensor (the usual case): the string array built from its buffers
            name = self.names[0].encode()
            offsets = np.arange(n + 1, dtype=np.int64) * len(name)
            if offsets[-1] < 2**31:
                return pa.StringArray.from_buffers(n, pa.py_buffer(offsets.astype(np.int32)), pa.py_buffer(name * n))
        return pa.array(self.names, pa.string()).take(pa.array(self.codes, pa.int32()))


def _sensors(table: pa.Table, mapping: dict[str, str], policy: SensorPolicy, opts: UploadOptions,
             errors: _Errors) -> _Sensors:
    n = table.num_rows
    if opts.sensor is not None and not valid_name(opts.sensor):
        errors.add(None, "sensor", f"invalid sensor name {opts.sensor!r} (letters, digits, _ . -)")
    if SENSOR_COLUMN in mapping:
        column = table.column(mapping[SENSOR_COLUMN])
        encoded = pc.utf8_trim_whitespace(pc.cast(column, pa.string())).combine_chunks().dictionary_encode()
        nulls = encoded.is_null().to_numpy(zero_copy_only=False)
        codes = encoded.indices.fill_null(0).to_numpy(zero_copy_only=False).astype(np.int32)
        names = [str(x) for x in encoded.dictionary.to_pylist()] or [""]
        values = np.asarray(names, dtype=object)
        errors.add_rows(np.flatnonzero(nulls | (values[codes] == "")), SENSOR_COLUMN, "missing value")
        if opts.sensor is not None:
            for i, name in enumerate(names):
                if name != opts.sensor:
                    errors.add_rows(np.flatnonzero(codes == i), SENSOR_COLUMN,
                                    f"differs from the sensor={opts.sensor!r} query parameter (got {name!r})")
    elif opts.sensor is not None:
        codes, names = np.zeros(n, dtype=np.int32), [opts.sensor]
    elif policy.default is not None:
        codes, names = np.zeros(n, dtype=np.int32), [policy.default]
    else:
        errors.add(None, "sensor", policy.why_no_default)
        return _Sensors(np.zeros(n, dtype=np.int32), [""])
    for i, name in enumerate(names):
        if name == "":
            continue
        if not valid_name(name):
            errors.add_rows(np.flatnonzero(codes == i), SENSOR_COLUMN, f"invalid sensor name {name!r}")
        elif policy.allowed is not None and name not in policy.allowed:
            errors.add_rows(np.flatnonzero(codes == i), SENSOR_COLUMN,
                            f"unknown sensor {name!r}; configured: {', '.join(policy.allowed) or 'none'}")
    return _Sensors(codes, names)


def _group_codes(sensors: _Sensors, columns: dict[str, np.ndarray], spec: StreamSpec) -> np.ndarray | None:
    """One integer per row identifying its (sensor, *extra key) group; None when all rows share one."""
    if len(sensors.names) == 1 and not spec.key:
        return None
    codes = sensors.codes.astype(np.int64)
    for c in spec.key:
        c_codes, uniques = pd.factorize(columns[c])
        codes = codes * (len(uniques) + 1) + c_codes
    return codes


def _check_order(times: np.ndarray, groups: np.ndarray | None, errors: _Errors) -> None:
    """Within each identity group (sensor + extra key columns) times must strictly increase."""
    if groups is None:  # one group: rows in upload order
        equal = times[1:] == times[:-1]
        back = times[1:] < times[:-1]
        if equal.any() or back.any():
            errors.add_rows(np.flatnonzero(equal) + 1, "time", SAME_TIME)
            errors.add_rows(np.flatnonzero(back) + 1, "time", BACKWARDS)
        return
    order = np.argsort(groups, kind="stable")
    same_group = groups[order][1:] == groups[order][:-1]
    t = times[order]
    equal = same_group & (t[1:] == t[:-1])
    back = same_group & (t[1:] < t[:-1])
    errors.add_rows(order[1:][equal], "time", SAME_TIME)
    errors.add_rows(order[1:][back], "time", BACKWARDS)


def _exact_times(table: pa.Table, mapping: dict[str, str], scale: str, errors: _Errors) -> np.ndarray:
    """``time_tai_ns`` (integers, exact); a ``time`` column beside it must name the same instants on ``scale``
    (on UTC: the same POSIX count, which holds during a leap second)."""
    col = table.column(mapping[TIME_COLUMN])
    n = len(col)
    nulls = col.is_null().to_numpy(zero_copy_only=False)
    if nulls.any():
        errors.add_rows(np.flatnonzero(nulls), TIME_COLUMN, "missing time")
        return np.zeros(n, dtype=np.int64)
    try:  # integers, or integers as text (CSV)
        if not (pa.types.is_integer(col.type) or pa.types.is_string(col.type) or pa.types.is_large_string(col.type)):
            raise pa.ArrowInvalid(str(col.type))
        tai = pc.cast(pc.utf8_trim_whitespace(col) if not pa.types.is_integer(col.type) else col,
                      pa.int64()).to_numpy(zero_copy_only=False)
    except pa.ArrowInvalid:
        errors.add(None, TIME_COLUMN, f"expected integer nanoseconds of TAI, got {col.type} values that are not")
        return np.zeros(n, dtype=np.int64)
    if "time" in mapping:
        given = _times(table.column(mapping["time"]), scale, errors)
        if errors.total == 0:
            same = given == tai
            if scale == "utc" and not same.all():
                same |= timescales.tai_ns_to_epoch_ns(given, "utc") == timescales.tai_ns_to_epoch_ns(tai, "utc")
            errors.add_rows(np.flatnonzero(~same), "time", f"differs from time_tai_ns read on {scale} (give "
                                                           "the right time_scale, or only one of the two)")
    return np.asarray(tai, dtype=np.int64)


def validate(table: pa.Table, spec: StreamSpec, policy: SensorPolicy, opts: UploadOptions) -> Validated:
    """Check an upload and return the canonical, sorted table (see module docstring)."""
    errors = _Errors()
    if opts.time_scale not in timescales.SCALES:
        errors.add(None, "time_scale", f"expected one of {', '.join(timescales.SCALES)}, "
                                       f"got {opts.time_scale!r}")
    if spec.quaternion and opts.quaternion_direction not in DIRECTIONS:
        errors.add(None, "quaternion_direction", f"expected one of {', '.join(DIRECTIONS)}, "
                                                 f"got {opts.quaternion_direction!r}")
    if not (0 < opts.norm_tolerance < 0.5):
        errors.add(None, "norm_tolerance", f"expected 0 < norm_tolerance < 0.5, got {opts.norm_tolerance}")
    mapping = _resolve_columns(table, spec, errors)
    if table.num_rows == 0:
        errors.add(None, None, "the upload has no rows")
    errors.raise_if_any()

    if TIME_COLUMN in mapping:
        times = _exact_times(table, mapping, opts.time_scale, errors)
    else:
        times = _times(table.column(mapping["time"]), opts.time_scale, errors)
    out: dict[str, np.ndarray] = {TIME_COLUMN: times}
    sensors = _sensors(table, mapping, policy, opts, errors)
    for c in spec.columns:
        col = table.column(mapping[c.name])
        if c.kind == "float":
            out[c.name] = _to_float(col, c.name, errors)
        elif c.kind == "int":
            out[c.name] = _to_int(col, c.name, errors)
        elif c.kind == "bool":
            out[c.name] = _to_bool(col, c.name, errors)
        else:
            out[c.name] = _to_str(col, c.name, errors)
    _check_values(out, spec, opts, errors)
    groups = _group_codes(sensors, out, spec) if errors.total == 0 else None
    if errors.total == 0:
        _check_order(out[TIME_COLUMN], groups, errors)
    errors.raise_if_any()

    schema = arrow_schema(spec)
    arrays = [sensors.arrow() if f.name == SENSOR_COLUMN else pa.array(out[f.name], type=f.type)
              for f in schema]
    canonical = pa.Table.from_arrays(arrays, schema=schema)
    row_index = np.arange(table.num_rows, dtype=np.int64)
    if groups is not None:  # one group is already in identity order (times increase)
        canonical = canonical.append_column("_row", pa.array(row_index))
        canonical = canonical.sort_by([(k, "ascending") for k in spec.key_columns])
        row_index = canonical.column("_row").to_numpy()
        canonical = canonical.drop_columns(["_row"])
    return Validated(canonical, row_index)


def _check_values(out: dict[str, np.ndarray], spec: StreamSpec, opts: UploadOptions, errors: _Errors) -> None:
    if spec.quaternion:
        q = np.stack([out[c] for c in spec.quaternion], axis=-1)
        norm = np.linalg.norm(q, axis=-1)
        bad = np.abs(norm - 1.0) > opts.norm_tolerance
        errors.add_rows(np.flatnonzero(bad), ",".join(spec.quaternion),
                        f"quaternion norm differs from 1 by more than {opts.norm_tolerance:g}", norm)
        q = q / np.where(bad, 1.0, norm)[:, None]
        if opts.quaternion_direction == "inertial_to_sensor":
            q = quat_conjugate(q)
        q = quat_canonical(q)
        for i, c in enumerate(spec.quaternion):
            out[c] = np.ascontiguousarray(q[:, i])
    for group in spec.unit_vector:
        v = np.stack([out[c] for c in group], axis=-1)
        norm = np.linalg.norm(v, axis=-1)
        bad = np.abs(norm - 1.0) > opts.norm_tolerance
        errors.add_rows(np.flatnonzero(bad), ",".join(group),
                        f"unit vector norm differs from 1 by more than {opts.norm_tolerance:g}", norm)
        v = v / np.where(bad, 1.0, norm)[:, None]
        for i, c in enumerate(group):
            out[c] = np.ascontiguousarray(v[:, i])
    if "interval_s" in out:
        errors.add_rows(np.flatnonzero(out["interval_s"] <= 0), "interval_s", "must be positive",
                        out["interval_s"])
    if "system" in out:
        bad = ~np.isin(out["system"], GNSS_SYSTEMS)
        errors.add_rows(np.flatnonzero(bad), "system", f"expected one of {', '.join(GNSS_SYSTEMS)}",
                        out["system"])
    if "prn" in out:
        errors.add_rows(np.flatnonzero((out["prn"] < 1) | (out["prn"] > 999)), "prn",
                        "expected 1..999", out["prn"])
    if "panel" in out:
        limit = opts.n_panels
        bad = (out["panel"] < 0) | ((out["panel"] >= limit) if limit is not None else False)
        what = f"0..{limit - 1} (solar_panels configured)" if limit else "a non-negative index"
        errors.add_rows(np.flatnonzero(bad), "panel", f"expected {what}", out["panel"])
