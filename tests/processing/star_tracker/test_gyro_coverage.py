"""The gyro-coverage criteria of star_tracker_accuracy (processing.star_tracker.gyro_coverage), on time tags alone."""

import numpy as np

from processing.star_tracker.gyro_coverage import (
    GYRO_SAMPLES_PER_PARAMETER,
    NOTE_SEGMENTS,
    coverage_notes,
    segment_gyro_coverage,
)

NS = 10**9
T_ST = np.arange(1000, dtype=np.int64) * NS  # 1 Hz star tracker, 999 s


def _cov(g_ns, harmonics=100, max_gap_s=120.0):
    return segment_gyro_coverage(0, T_ST.size, T_ST, np.asarray(g_ns, dtype=np.int64), harmonics, max_gap_s)


def test_a_gyro_at_the_star_trackers_rate_is_used_up_to_two_samples_per_parameter():
    g = T_ST[::1] + NS // 3
    c = _cov(g, harmonics=(T_ST.size - 2) // 4)  # the automatic M's cap: 4 samples per parameter fail
    assert c.used and c.reason is None and c.idx.size == 999 and abs(c.gyro_rate_hz - c.star_tracker_rate_hz) < 2e-3
    m_max = c.idx.size // GYRO_SAMPLES_PER_PARAMETER - 2
    assert _cov(g, harmonics=m_max).used
    over = _cov(g, harmonics=m_max + 2)
    assert over.criterion == "samples" and over.value == 999 and over.threshold == 2 * (over.gyro_harmonics + 2)
    assert "999 gyro samples for a series of" in over.reason


def test_long_gaps_the_ends_included_and_slow_gyros_are_named_with_value_and_threshold():
    g = T_ST + NS // 2
    gap = _cov(g[(g < 300 * NS) | (g > 430 * NS)])
    assert gap.criterion == "gap" and gap.value == 131.0 and gap.threshold == 120.0
    assert abs(gap.longest_gap_at_s - 299.5) < 1e-9
    assert "gyro gap of 131.0 s at +300 s > max_gap_s = 120 s" in gap.reason
    assert _cov(g[(g < 300 * NS) | (g > 410 * NS)]).used  # 111 s: within max_gap_s
    late = _cov(g[g > 150 * NS])  # the gyro starts 150.5 s after the star tracker
    assert late.criterion == "gap" and late.value == 150.5 and late.longest_gap_at_s == 0.0
    slow = _cov(g[::3])
    assert slow.criterion == "rate" and abs(slow.value - 1 / 3) < 0.01 and slow.threshold == 0.5
    assert "(ratio 0.333 < 0.5)" in slow.reason
    assert _cov(g[::2]).used  # half the star tracker's rate is enough
    nothing = _cov(np.zeros(0))
    assert nothing.criterion == "gap" and nothing.value == 999.0


def test_notes_count_the_criteria_and_name_a_few_segments():
    g = T_ST + NS // 2
    ok, slow = _cov(g), _cov(g[::3])
    assert coverage_notes([ok, ok]) == []
    (note,) = coverage_notes([ok, slow])
    assert note.startswith("gyro not used in 1 of 2 star-tracker segments") and "rate 1" in note
    (note,) = coverage_notes([slow] * (NOTE_SEGMENTS + 2))
    assert note.startswith(f"gyro not used: it covers none of the {NOTE_SEGMENTS + 2}") and note.endswith("and 2 more")
    assert note.count("ratio 0.333") == NOTE_SEGMENTS
