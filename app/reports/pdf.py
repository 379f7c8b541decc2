"""PDF of a report: headless Chromium prints the self-contained HTML report.

Why Chromium: the HTML report is the single layout (tables, figures, print CSS with A4 pages); printing
it gives a PDF identical in content, with selectable text, and costs no Python dependency. It is found
as ``$ATTITUDE_CHROMIUM`` or ``chromium``/``chromium-browser``/``google-chrome`` on PATH (Debian:
``apt-get install chromium``). Where no Chromium is installed, :func:`fallback_pdf` draws a plainer PDF
with matplotlib (already a dependency): the report's key facts, summary rows and every figure.
"""

from __future__ import annotations

import io
import logging
import os
import shutil
import subprocess
import tempfile
import textwrap
import threading
from collections.abc import Sequence
from pathlib import Path

log = logging.getLogger("attitude.reports")

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--disable-extensions", "--disable-dev-shm-usage", "--mute-audio", "--hide-scrollbars",
                  "--no-pdf-header-footer")
TIMEOUT_S = 120.0
_slots = threading.BoundedSemaphore(2)  # Chromium takes ~200 MB per print; at most two at once


class PdfError(RuntimeError):
    """Chromium failed to print the report (the message carries its output)."""


def find_chromium() -> str | None:
    explicit = os.environ.get("ATTITUDE_CHROMIUM")
    if explicit:
        return explicit if Path(explicit).is_file() else shutil.which(explicit)
    for name in CHROMIUM_NAMES:
        path = shutil.which(name)
        if path:
            return path
    return None


def chromium_pdf(html: str, chromium: str, timeout_s: float = TIMEOUT_S) -> bytes:
    """Print ``html`` (a self-contained page: no network needed) to PDF with headless Chromium."""
    with _slots, tempfile.TemporaryDirectory(prefix="attitude-pdf-") as tmp:
        page = Path(tmp) / "report.html"
        out = Path(tmp) / "report.pdf"
        page.write_text(html, encoding="utf-8")
        cmd = [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={Path(tmp) / 'profile'}", f"--print-to-pdf={out}",
               page.as_uri()]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True,
                                env={**os.environ, "HOME": tmp})
        try:
            output, _ = proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, 9)
            proc.communicate()
            raise PdfError(f"Chromium did not print the report within {timeout_s:.0f} s") from None
        if proc.returncode != 0 or not out.is_file() or out.stat().st_size == 0:
            tail = output.decode(errors="replace")[-2000:]
            raise PdfError(f"Chromium exited with code {proc.returncode} without a PDF: {tail}")
        return out.read_bytes()


def fallback_pdf(title: str, facts: Sequence[tuple[str, str]], figures: Sequence[tuple[str, bytes]]) -> bytes:
    """A plain PDF without Chromium: a title page of facts and one page per figure (PNG bytes)."""
    # matplotlib's PDF backend is imported here, not at start-up: only this fallback needs it.
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.figure import Figure
    from matplotlib.image import imread

    buf = io.BytesIO()
    with PdfPages(buf) as pdf:
        lines: list[str] = []
        for key, value in facts:
            wrapped = textwrap.wrap(f"{key}: {value}", 100) or [""]
            lines += [wrapped[0], *("    " + w for w in wrapped[1:])]
        per_page = 60
        for start in range(0, max(1, len(lines)), per_page):
            fig = Figure(figsize=(8.27, 11.69))
            fig.text(0.06, 0.96, title if start == 0 else f"{title} (continued)", fontsize=13, weight="bold",
                     va="top")
            fig.text(0.06, 0.93, "\n".join(lines[start:start + per_page]), fontsize=7.5, family="monospace",
                     va="top")
            pdf.savefig(fig)
        for caption, png in figures:
            fig = Figure(figsize=(8.27, 11.69))
            ax = fig.add_axes((0.05, 0.1, 0.9, 0.82))
            ax.imshow(imread(io.BytesIO(png), format="png"))
            ax.set_axis_off()
            fig.text(0.5, 0.95, caption, ha="center", fontsize=11)
            pdf.savefig(fig)
    return buf.getvalue()


def html_to_pdf(html: str, title: str, facts: Sequence[tuple[str, str]],
                figures: Sequence[tuple[str, bytes]]) -> tuple[bytes, str]:
    """(PDF bytes, engine): Chromium's print of ``html``; the fallback if Chromium is missing or fails."""
    chromium = find_chromium()
    if chromium is None:
        log.warning("no Chromium found (set ATTITUDE_CHROMIUM or install chromium): plain PDF drawn instead")
        return fallback_pdf(title, facts, figures), "matplotlib"
    try:
        return chromium_pdf(html, chromium), "chromium"
    except (PdfError, OSError) as exc:
        log.error("Chromium could not print the report, plain PDF drawn instead: %s", exc)
        return fallback_pdf(title, facts, figures), "matplotlib"
