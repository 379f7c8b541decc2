"""Text geometry of matplotlib figures: overlapping or overprinting text, found from the drawn bounding boxes.

A figure is drawn once with the Agg renderer (as the job runner saves it); every text that is actually
drawn (titles, axis labels, tick labels, legend entries, annotations) is recorded with its window
extent. Problems reported:

- two texts overlap (tick labels crowding, a title over the tick labels of the axes above, ...);
- a text of one axes runs into the plotting area of another axes (a long y label into its neighbour,
  a legend under an inset).

Texts outside the figure need no check: figures are saved with ``bbox_inches="tight"``, which grows
the canvas to hold every text.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

TOLERANCE_PX = 1.0  # overlaps smaller than this (in both directions) are rounding


@dataclass(frozen=True)
class DrawnText:
    text: str
    x0: float
    y0: float
    x1: float
    y1: float
    axes: Any  # the axes the text belongs to, or None for figure texts

    def overlap(self, other: DrawnText) -> float:
        """The smaller of the horizontal and vertical overlap (px): > 0 when the boxes intersect."""
        w = min(self.x1, other.x1) - max(self.x0, other.x0)
        h = min(self.y1, other.y1) - max(self.y0, other.y0)
        return min(w, h)


@contextmanager
def _recording(out: list[DrawnText]) -> Iterator[None]:
    from matplotlib.text import Text

    original = Text.draw

    def draw(self: Text, renderer: Any) -> None:
        original(self, renderer)
        if self.get_visible() and self.get_text().strip() and self.get_alpha() != 0:
            box = self.get_window_extent(renderer)
            if box.width > 0 and box.height > 0:
                out.append(DrawnText(self.get_text(), box.x0, box.y0, box.x1, box.y1, self.axes))

    Text.draw = draw  # type: ignore[method-assign]
    try:
        yield
    finally:
        Text.draw = original  # type: ignore[method-assign]


def drawn_texts(fig: Any) -> list[DrawnText]:
    """Every text the figure draws, with its bounding box in display pixels."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    out: list[DrawnText] = []
    with _recording(out):
        fig.canvas.draw()
    unique: dict[tuple[str, float, float], DrawnText] = {}
    for t in out:  # a text drawn twice (e.g. by a layout pass) counts once
        unique[(t.text, round(t.x0, 1), round(t.y0, 1))] = t
    return list(unique.values())


def _same_place(a: Any, b: Any) -> bool:
    pa, pb = a.get_position(), b.get_position()
    return bool(np.allclose([pa.x0, pa.y0, pa.x1, pa.y1], [pb.x0, pb.y0, pb.x1, pb.y1], atol=1e-3))


def _inside(a: Any, b: Any) -> bool:
    """Axes ``a`` lies within axes ``b`` (an inset)."""
    pa, pb = a.get_position(), b.get_position()
    return pa.x0 >= pb.x0 - 1e-3 and pa.x1 <= pb.x1 + 1e-3 and pa.y0 >= pb.y0 - 1e-3 and pa.y1 <= pb.y1 + 1e-3


def _short(s: str) -> str:
    s = " ".join(s.split())
    return s if len(s) <= 40 else s[:37] + "..."


def problems(fig: Any, tolerance_px: float = TOLERANCE_PX) -> list[str]:
    """What is wrong with the text of ``fig`` (empty when nothing overlaps or runs off)."""
    texts = drawn_texts(fig)
    found: list[str] = []
    for i, a in enumerate(texts):
        for b in texts[i + 1:]:
            if a.overlap(b) > tolerance_px:
                found.append(f"text {_short(a.text)!r} overlaps {_short(b.text)!r}")
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        if not ax.get_visible() or not ax.axison:
            continue
        box = ax.get_window_extent(renderer)
        area = DrawnText("", box.x0, box.y0, box.x1, box.y1, ax)
        for t in texts:
            if t.axes is None or t.axes is ax or _same_place(t.axes, ax) or _inside(t.axes, ax):
                continue
            if t.overlap(area) > tolerance_px:
                found.append(f"text {_short(t.text)!r} runs into another plot")
    return found
