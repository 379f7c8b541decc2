"""Whether the gyro covers a star-tracker segment well enough for steps 5 and 7 of
processing.star_tracker.accuracy, and if not, which criterion failed with its value and threshold.

The gyro rates of a segment are smoothed by the sine series with the cutoff M/(2T) of the star-tracker
fit (processing.star_tracker.accuracy_gyro). The gyro is used in a segment when it covers the segment
at the star tracker's rate; two criteria, in this order:

1. ``rate``: gyro samples per second in the segment's span at least GYRO_MIN_RATE_RATIO (1/2) of the
   star tracker's. The automatic M is capped at (N - 2)/4, a cutoff at half the star tracker's Nyquist
   frequency, so a gyro at half its rate still has the cutoff within its own Nyquist frequency;
   slower, its lines above the cutoff alias onto what the star tracker sees. A gyro gap longer than half
   the segment fails it too (the reason names the longest gap, the segment's ends included).
2. ``samples``: at least GYRO_SAMPLES_PER_PARAMETER (2) gyro samples per parameter of the gyro series
   (M_g + 2, M_g the star-tracker M scaled to the gyro span), i.e. the cutoff below the gyro's mean
   Nyquist frequency. (The criterion before issue 23 asked for 4 per parameter, the star tracker's own
   cap: a 1 Hz gyro beside a 1 Hz star tracker at the automatic M's cap always failed it.)

Shorter gyro gaps are no reason to leave the gyro out: the lines it finds are fitted per segment as
sinusoids, which span a gap. Measured (bench/realistic_gyro_turn.py, item 2: 11 segments with gyro gaps of
121-136 s in 10 h of realistic data): sigma / truth 0.95-1.07 with the gyro across the gap, 1.20-1.47 on
x1 with the star tracker alone. The longest gap is reported either way.

Times int64 TAI ns; spans and gaps in s.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.units import NS_PER_S

__all__ = [
    "GYRO_MIN_RATE_RATIO",
    "GYRO_SAMPLES_PER_PARAMETER",
    "GyroCoverage",
    "coverage_notes",
    "enough_gyro_samples",
    "segment_gyro_coverage",
]

GYRO_MIN_RATE_RATIO = 0.5
"""Criterion ``rate``: the gyro's sample rate in a segment at least this fraction of the star tracker's."""
GYRO_SAMPLES_PER_PARAMETER = 2
"""Criterion ``samples``: gyro samples per parameter (M_g + 2) of the gyro sine series."""
NOTE_SEGMENTS = 3
"""A note names at most this many segments without gyro (the job summary counts them all)."""


def enough_gyro_samples(n_gyro: int, gyro_harmonics: int) -> bool:
    """Criterion ``samples``: n_gyro >= GYRO_SAMPLES_PER_PARAMETER (gyro_harmonics + 2)."""
    return n_gyro >= GYRO_SAMPLES_PER_PARAMETER * (gyro_harmonics + 2)


@dataclass(frozen=True)
class GyroCoverage:
    """The gyro in one star-tracker segment (rows ``start``:``stop``, span_s [s]): its samples idx (K,) in
    the span, the rates [Hz] of both sensors in it, the longest gyro gap [s] (ends included) and where it
    starts [s since the segment's first sample], the gyro series' harmonic count; ``criterion`` the first
    failed criterion ("rate", "samples"; None: used) with its measured ``value`` and ``threshold``."""

    start: int
    stop: int
    span_s: float
    idx: NDArray
    star_tracker_rate_hz: float
    gyro_rate_hz: float
    longest_gap_s: float
    longest_gap_at_s: float
    gyro_harmonics: int
    criterion: str | None
    value: float | None
    threshold: float | None

    @property
    def used(self) -> bool:
        return self.criterion is None

    @property
    def reason(self) -> str | None:
        """Why the gyro is not used in the segment (None when it is), in words with the numbers."""
        where = f"star-tracker rows {self.start}-{self.stop - 1} ({self.span_s:.0f} s)"
        gap = f"; longest gyro gap {self.longest_gap_s:.1f} s at +{self.longest_gap_at_s:.0f} s"
        if self.criterion == "rate":
            return (f"{where}: gyro at {self.gyro_rate_hz:.3g} Hz, the star tracker at {self.star_tracker_rate_hz:.3g} "
                    f"Hz (ratio {self.value:.3g} < {self.threshold:g}){gap}")
        if self.criterion == "samples":
            return (f"{where}: {self.idx.size} gyro samples for a series of {self.gyro_harmonics + 2} parameters "
                    f"(< {self.threshold:g} = {GYRO_SAMPLES_PER_PARAMETER} per parameter){gap}")
        return None


def _longest_gap(t_first_ns: int, t_last_ns: int, g_ns: NDArray) -> tuple[float, float]:
    """(longest gap [s], its start [s since t_first]) of the gyro times g_ns within [t_first, t_last],
    the ends of the span counting as gyro gaps."""
    edges = np.concatenate([[t_first_ns], g_ns, [t_last_ns]]).astype(np.int64)
    d = np.diff(edges)
    k = int(np.argmax(d))
    return float(d[k]) / NS_PER_S, float(edges[k] - t_first_ns) / NS_PER_S


def segment_gyro_coverage(start: int, stop: int, t_ns: NDArray, g_ns: NDArray, harmonics: int) -> GyroCoverage:
    """The criteria of the module docstring for the star-tracker rows start:stop of t_ns (their fit has
    ``harmonics``) against the gyro times g_ns (K,) sorted."""
    t_first, t_last = int(t_ns[start]), int(t_ns[stop - 1])
    span_s = (t_last - t_first) / NS_PER_S
    lo = int(np.searchsorted(g_ns, t_first, side="left"))
    hi = int(np.searchsorted(g_ns, t_last, side="right"))
    idx = np.arange(lo, hi)
    st_rate = (stop - start) / span_s if span_s > 0 else float("nan")
    g_rate = idx.size / span_s if span_s > 0 else float("nan")
    gap_s, gap_at_s = _longest_gap(t_first, t_last, g_ns[lo:hi])
    m_g = int(round(harmonics * (g_ns[hi - 1] - g_ns[lo]) / (t_last - t_first))) if idx.size > 1 and span_s > 0 else 0
    need = float(GYRO_SAMPLES_PER_PARAMETER * (m_g + 2))
    ratio = g_rate / st_rate if span_s > 0 else 0.0
    criterion: str | None = None
    value = threshold = None
    if not ratio >= GYRO_MIN_RATE_RATIO:
        criterion, value, threshold = "rate", float(ratio), GYRO_MIN_RATE_RATIO
    elif not enough_gyro_samples(idx.size, m_g):
        criterion, value, threshold = "samples", float(idx.size), need
    return GyroCoverage(start, stop, span_s, idx, float(st_rate), float(g_rate), gap_s, gap_at_s, m_g, criterion,
                        value, threshold)


def coverage_notes(coverage: Sequence[GyroCoverage]) -> list[str]:
    """Notes on the segments without gyro: none when the gyro is used in every segment; else the count,
    the failed criteria and the first NOTE_SEGMENTS reasons."""
    unused = [c for c in coverage if not c.used]
    if not unused:
        return []
    counts = {k: sum(c.criterion == k for c in unused) for k in ("rate", "samples")}
    by = ", ".join(f"{k} {n}" for k, n in counts.items() if n)
    reasons = "; ".join(str(c.reason) for c in unused[:NOTE_SEGMENTS])
    more = f"; and {len(unused) - NOTE_SEGMENTS} more" if len(unused) > NOTE_SEGMENTS else ""
    if len(unused) == len(coverage):
        head = (f"gyro not used: it covers none of the {len(coverage)} star-tracker segments at the star tracker's "
                f"rate (failed criteria: {by})")
    else:
        head = (f"gyro not used in {len(unused)} of {len(coverage)} star-tracker segments (the star tracker alone "
                f"there; failed criteria: {by})")
    return [f"{head}: {reasons}{more}"]

