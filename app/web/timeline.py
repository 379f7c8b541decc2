"""The coverage timeline of a spacecraft page: the SVG geometry of app/services/coverage.py's spans and gaps.

Drawn by the template (spacecraft.html) in viewBox units: a row per stream and sensor, green spans,
red gaps, UTC ticks.
"""

from __future__ import annotations

from typing import Any

from app.reports.summary import iso
from app.services.coverage import Timeline
from processing.time import timescales
from processing.units import NS_PER_S

WIDTH = 1000
LABEL_W = 190
PLOT_W = WIDTH - LABEL_W - 40  # room for the last tick label
ROW_H = 26
TOP = 8
AXIS_H = 34
TICK_STEPS_S = (1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 900, 1800, 3600, 7200, 3 * 3600, 6 * 3600, 12 * 3600,
                86400, 2 * 86400, 7 * 86400, 14 * 86400, 30 * 86400, 91 * 86400, 182 * 86400, 365 * 86400)


def _x(t: int, tl: Timeline) -> float:
    return LABEL_W + (t - tl.start_tai_ns) / (tl.end_tai_ns - tl.start_tai_ns) * PLOT_W


def _ticks(tl: Timeline) -> list[dict[str, Any]]:
    span_s = (tl.end_tai_ns - tl.start_tai_ns) / NS_PER_S
    step = next((s for s in TICK_STEPS_S if span_s / s <= 8), TICK_STEPS_S[-1])
    epoch = int(timescales.tai_ns_to_epoch_ns([tl.start_tai_ns], "utc")[0])
    first = -(-epoch // (step * NS_PER_S)) * step * NS_PER_S  # first UTC multiple of the step in the view
    offset = tl.start_tai_ns - epoch  # TAI - UTC in ns (constant enough over a view for placing ticks)
    out = []
    t = first
    while t + offset <= tl.end_tai_ns:
        text = iso(t + offset)
        label = text[:10] if step >= 86400 else text[5:16].replace("T", " ") if step >= 60 else text[11:19]
        out.append({"x": round(_x(t + offset, tl), 1), "label": label})
        t += step * NS_PER_S
    return out


def geometry(tl: Timeline) -> dict[str, Any]:
    """SVG coordinates (viewBox units) of the rows, spans, gaps and axis ticks."""
    rows = []
    for i, r in enumerate(tl.rows):
        y = TOP + i * ROW_H
        spans = []
        for a, b in r.spans:
            a, b = max(a, tl.start_tai_ns), min(b, tl.end_tai_ns)
            if b >= a:
                x0 = _x(a, tl)
                spans.append({"x": round(x0, 2), "w": round(max(1.5, _x(b, tl) - x0), 2),
                              "title": f"{r.stream}/{r.sensor}: {iso(a)} – {iso(b)}"})
        gaps = []
        for a, b, source in r.gaps:
            if b < tl.start_tai_ns or a > tl.end_tai_ns:
                continue
            x0 = _x(max(a, tl.start_tai_ns), tl)
            gaps.append({"x": round(x0, 2), "w": round(max(2.0, _x(min(b, tl.end_tai_ns), tl) - x0), 2),
                         "title": f"gap ({source}): {iso(a)} – {iso(b)} ({(b - a) / NS_PER_S:.6g} s)"})
        rows.append({"y": y, "label": f"{r.stream} / {r.sensor}", "spans": spans, "gaps": gaps})
    height = TOP + len(tl.rows) * ROW_H + AXIS_H
    return {"width": WIDTH, "height": height, "label_w": LABEL_W, "plot_w": PLOT_W, "row_h": ROW_H, "rows": rows,
            "axis_y": TOP + len(tl.rows) * ROW_H + 4, "ticks": _ticks(tl)}
