"""A job summary (any JSON-able dict) laid out for people: scalars, per-axis vectors, statistics, tables.

Generic over job types: the layout follows the shapes of the values and the unit suffixes of their keys
(DESIGN.md: ``_rad``, ``_rad_s``, ``_arcsec``, ``_deg``, ``_tai_ns`` ...). Angles in rad and rates in
rad/s get a second row in arcsec and deg/h, the units engineers read.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from processing.time import timescales
from processing.units import ARCSEC_PER_RAD, DEG_H_PER_RAD_S

STAT_KEYS = ("mean", "std", "rms", "min", "max", "median", "mad", "p05", "p50", "p95", "p99", "n")
MAX_RECORDS = 200
AXES: tuple[str, str, str] = ("x", "y", "z")


def iso(tai_ns: int) -> str:
    """An exact ISO 8601 UTC reading of a TAI ns instant."""
    return str(timescales.tai_ns_to_iso(np.array([tai_ns], dtype=np.int64))[0])


def wall(value: str | None) -> str:
    """A wall-clock ISO timestamp (``2026-01-02T03:04:05.678+00:00``) as ``2026-01-02 03:04:05``."""
    return "—" if not value else value[:19].replace("T", " ")


def fmt(value: Any) -> str:
    if value is None:
        return "—"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, list) and all(_is_number(v) or v is None for v in value):
        return "[" + ", ".join(fmt(v) for v in value) + "]"
    if isinstance(value, list) and all(isinstance(v, str) for v in value):
        return ", ".join(value)
    if isinstance(value, (list, dict)):
        return str(value)
    return str(value)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_vector3(v: Any) -> bool:
    return isinstance(v, list) and len(v) == 3 and all(_is_number(x) or x is None for x in v)


def _is_stats(v: Any) -> bool:
    if not isinstance(v, Mapping) or len(v) < 2 or not set(v) <= set(STAT_KEYS):
        return False
    return all(_is_number(x) or x is None or _is_vector3(x) for x in v.values())


def _is_record_list(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, Mapping) for x in v)


def _is_scalar_like(v: Any) -> bool:
    return v is None or isinstance(v, (str, bool, int, float)) or (
        isinstance(v, list) and 0 < len(v) <= 6 and all(_is_number(x) or x is None or isinstance(x, str) for x in v))


def _is_keyed_table(v: Any) -> bool:
    """{name: {field: scalar}} with at least two names, e.g. per-criterion counts and thresholds."""
    return (isinstance(v, Mapping) and len(v) >= 2 and all(isinstance(x, Mapping) and x for x in v.values())
            and all(_is_scalar_like(y) for x in v.values() for y in x.values()))


def label(key: str) -> str:
    """A key with its time suffix spelled out (``first_tai_ns`` -> ``first (UTC)``)."""
    return key[: -len("_tai_ns")] + " (UTC)" if key.endswith("_tai_ns") else key


def cell(key: str, value: Any) -> str:
    if key.endswith("_tai_ns") and isinstance(value, int) and not isinstance(value, bool):
        return iso(value)
    if isinstance(value, (list, dict)) and not _is_scalar_like(value):
        return f"({len(value)} entries)"
    return fmt(value)


def _conversion(key: str) -> tuple[str, float] | None:
    """The name and factor of a second reading in engineers' units, for keys in rad or rad/s."""
    for suffix, unit, factor in (("_rad_s", "deg/h", DEG_H_PER_RAD_S), ("_rad", "arcsec", ARCSEC_PER_RAD)):
        if key.endswith(suffix):
            return f"{key[: -len(suffix)]} [{unit}]", factor
    return None


def _scale(value: Any, factor: float) -> Any:
    if isinstance(value, list):
        return [_scale(v, factor) for v in value]
    return value * factor if _is_number(value) else value


@dataclass
class Layout:
    scalars: list[tuple[str, str]] = field(default_factory=list)
    vectors: list[tuple[str, list[str]]] = field(default_factory=list)  # per-axis rows: name, [x, y, z]
    stats: list[tuple[str, dict[str, str]]] = field(default_factory=list)
    stat_columns: list[str] = field(default_factory=list)
    tables: list[dict[str, Any]] = field(default_factory=list)
    axes: tuple[str, str, str] = AXES  # the summary's own axis names (``axes``), else x, y, z

    @property
    def empty(self) -> bool:
        return not (self.scalars or self.vectors or self.stats or self.tables)


MAX_TABLE_CHARS = 110
"""Widest table (in characters of its cells) shown as one piece; wider ones are split into parts that
repeat the first column, so that a table fits an A4 page (and a laptop screen) without wrapped cells."""


def split_columns(columns: list[str], rows: list[list[str]], max_chars: int = MAX_TABLE_CHARS,
                  keep: int = 1) -> list[dict[str, Any]]:
    """[{columns, rows}, ...]: the table in parts of at most ``max_chars`` characters wide, each part with
    the first ``keep`` columns (the row names) in front."""
    widths = [max([len(str(c))] + [len(str(r[i])) for r in rows if i < len(r)]) + 3 for i, c in enumerate(columns)]
    head = list(range(min(keep, len(columns))))
    base = sum(widths[i] for i in head)
    parts: list[list[int]] = []
    current: list[int] = []
    used = base
    for i in range(len(head), len(columns)):
        if current and used + widths[i] > max_chars:
            parts.append(current)
            current, used = [], base
        current.append(i)
        used += widths[i]
    if current or not parts:
        parts.append(current)
    return [{"columns": [columns[i] for i in head + part], "rows": [[r[i] for i in head + part] for r in rows]}
            for part in parts]


def _converted(name: str) -> tuple[str, float]:
    """A record column's heading and factor: rad and rad/s shown in arcsec and deg/h."""
    conv = _conversion(name)
    return (conv[0], conv[1]) if conv is not None else (label(name), 1.0)


def _records_table(name: str, records: list[Mapping[str, Any]]) -> dict[str, Any]:
    """Records as a table; a record with per-axis vectors becomes one row per axis."""
    shown = records[:MAX_RECORDS]
    columns: list[str] = []
    for r in shown:
        columns += [c for c, v in r.items() if c not in columns and _is_scalar_like(v)]
    columns = [c for c in columns if not (c.endswith("_tai_ns") and c[: -len("_tai_ns")] in columns)]
    vectors = [c for c in columns if any(_is_vector3(r.get(c)) for r in shown)]
    scalars = [c for c in columns if c not in vectors]
    headings = [label(c) for c in scalars]
    rows: list[list[str]] = []
    keep = 1
    if not vectors:
        rows = [[cell(c, r.get(c)) for c in scalars] for r in shown]
    else:  # the first column and the axis lead every part of a split table
        keep = min(2, len(scalars) + 1)
        factors = [_converted(c) for c in vectors]
        headings = headings[:1] + ["axis"] + headings[1:] + [h for h, _ in factors]
        for r in shown:
            for i, axis in enumerate(AXES):
                row = [cell(c, r.get(c)) if i == 0 else "" for c in scalars]
                row.insert(min(1, len(row)), axis)
                for c, (_, f) in zip(vectors, factors, strict=True):
                    v: Any = r.get(c)
                    row.append(fmt(_scale(v[i], f)) if _is_vector3(v) else "—" if i else cell(c, v))
                rows.append(row)
    return {"name": name, "columns": headings, "rows": rows, "parts": split_columns(headings, rows, keep=keep),
            "truncated": len(records) > MAX_RECORDS, "total": len(records)}


def _keyed_table(name: str, value: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    columns: list[str] = []
    for inner in value.values():
        columns += [c for c in inner if c not in columns]
    rows = [[str(k)] + [cell(c, inner.get(c)) for c in columns] for k, inner in value.items()]
    headings = ["", *[label(c) for c in columns]]
    return {"name": name, "columns": headings, "rows": rows, "parts": split_columns(headings, rows),
            "truncated": False, "total": len(rows)}


def layout(summary: Mapping[str, Any] | None) -> Layout:
    """Sort the entries of a summary into scalar rows, per-axis rows, statistics rows and tables."""
    out = Layout()
    if summary:
        out.axes = axis_names(summary)
        _walk(summary, "", out)
    return out


def layouts(summary: Mapping[str, Any] | None) -> list[tuple[str, Layout]]:
    """The summary laid out, a pipeline's stages (``stages.<name>``) each on its own."""
    if not summary:
        return []
    stages = summary.get("stages")
    if not isinstance(stages, Mapping) or not all(isinstance(v, Mapping) for v in stages.values()):
        lay = layout(summary)
        return [] if lay.empty else [("", lay)]
    out = [("Pipeline", layout({k: v for k, v in summary.items() if k != "stages"}))]
    for name, stage in stages.items():
        inner = stage.get("summary")
        rest = {k: v for k, v in stage.items() if k != "summary"}
        out.append((f"Stage {name}", layout({**rest, **(inner if isinstance(inner, Mapping) else {})})))
    return [(t, lay) for t, lay in out if not lay.empty]


def axis_names(summary: Mapping[str, Any]) -> tuple[str, str, str]:
    """The names a summary gives its vector components (``"axes": ["x1", "x2", "x3"]``), else x, y, z."""
    axes = summary.get("axes")
    if isinstance(axes, list) and len(axes) == 3 and all(isinstance(a, str) for a in axes):
        return axes[0], axes[1], axes[2]
    return AXES


SHOWN_APART = ("warnings",)
"""Summary keys the reports show in their own section (warnings come first), not in the layout."""


def _walk(obj: Mapping[str, Any], prefix: str, out: Layout) -> None:
    for key, value in obj.items():
        if key in SHOWN_APART:
            continue
        name = f"{prefix}{key}"
        conv = _conversion(str(key))
        if _is_vector3(value):
            out.vectors.append((name, [fmt(v) for v in value]))
            if conv is not None:
                out.vectors.append((f"{prefix}{conv[0]}", [fmt(v) for v in _scale(value, conv[1])]))
        elif _is_stats(value):
            _add_stats(name, value, out)
            if conv is not None:
                _add_stats(f"{prefix}{conv[0]}", {s: _scale(v, conv[1]) for s, v in value.items() if s != "n"}, out)
        elif _is_record_list(value):
            out.tables.append(_records_table(name, value))
        elif _is_keyed_table(value):
            out.tables.append(_keyed_table(name, value))
        elif isinstance(value, Mapping):
            _walk(value, f"{name}.", out)
        else:
            out.scalars.append((label(name), cell(str(key), value)))
            if conv is not None and _is_number(value):
                out.scalars.append((f"{prefix}{conv[0]}", fmt(_scale(value, conv[1]))))


def _add_stats(name: str, value: Mapping[str, Any], out: Layout) -> None:
    for s in value:
        if s not in out.stat_columns:
            out.stat_columns.append(s)
    out.stat_columns.sort(key=STAT_KEYS.index)
    if any(isinstance(v, list) for v in value.values()):
        for i, axis in enumerate(AXES):
            out.stats.append((f"{name}[{axis}]", {s: fmt(v[i] if isinstance(v, list) else v)
                                                  for s, v in value.items()}))
    else:
        out.stats.append((name, {s: fmt(v) for s, v in value.items()}))


def flatten_numbers(summary: Mapping[str, Any], prefix: str = "") -> dict[str, list[float | None]]:
    """Every number and numeric vector (up to 3 components) of a summary by dotted key (for trends)."""
    out: dict[str, list[float | None]] = {}
    for key, value in summary.items():
        name = f"{prefix}{key}"
        if str(key).endswith("_tai_ns"):
            continue
        if _is_number(value):
            out[name] = [float(value) if math.isfinite(value) else None]
        elif isinstance(value, list) and 1 <= len(value) <= 3 and all(_is_number(v) or v is None for v in value):
            out[name] = [None if v is None or not math.isfinite(v) else float(v) for v in value]
        elif isinstance(value, Mapping):
            out.update(flatten_numbers(value, f"{name}."))
    return out
