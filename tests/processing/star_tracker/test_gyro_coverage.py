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


def _cov(g_ns, harmonics=100):
    return segment_gyro_coverage(0, T_ST.size, T_ST, np.asarray(g_ns, dtype=np.int64), harmonics)


def test_a_gyro_at_the_star_trackers_rate_is_used_up_to_two_samples_per_parameter():
    g = T_ST[::1] + NS // 3
    c = _cov(g, harmonics=(T_ST.size - 2) // 4)  # the automatic M's cap: 4 samples per parameter fail
    assert c.used and c.reason is None and c.idx.size == 999 and abs(c.gyro_rate_hz - c.star_tracker_rate_hz) < 2e-3
    m_max = c.idx.size // GYRO_SAMPLES_PER_PARAMETER - 2
    assert _cov(g, harmonics=m_max).used
    over = _cov(g, harmonics=m_max + 2)
    assert over.criterion == "samples" and over.value == 999 and over.threshold == 2 * (over.gyro_harmonics + 2)
    assert "999 gyro samples for a series of" in over.reason


def test_slow_gyros_and_gaps_over_half_the_segment_are_named_with_value_threshold_and_longest_gap():
    g = T_ST + NS // 2
    gap = _cov(g[(g < 300 * NS) | (g > 431 * NS)])
    assert gap.used and gap.longest_gap_s == 132.0 and abs(gap.longest_gap_at_s - 299.5) < 1e-9  # used across it
    half = _cov(g[(g < 200 * NS) | (g > 720 * NS)])
    assert half.criterion == "rate" and abs(half.value - 479 / 1000) < 1e-9 and half.threshold == 0.5
    assert "(ratio 0.479 < 0.5); longest gyro gap 521.0 s at +200 s" in half.reason
    late = _cov(g[g > 600 * NS])  # the gyro starts 600.5 s after the star tracker
    assert late.criterion == "rate" and late.longest_gap_s == 600.5 and late.longest_gap_at_s == 0.0
    slow = _cov(g[::3])
    assert slow.criterion == "rate" and abs(slow.value - 1 / 3) < 0.01 and slow.threshold == 0.5
    assert "Hz, the star tracker at 1 Hz (ratio 0.333 < 0.5)" in slow.reason
    assert _cov(g[::2]).used  # half the star tracker's rate is enough
    nothing = _cov(np.zeros(0))
    assert nothing.criterion == "rate" and nothing.value == 0.0 and nothing.longest_gap_s == 999.0


def test_notes_count_the_criteria_and_name_a_few_segments():
    g = T_ST + NS // 2
    ok, slow = _cov(g), _cov(g[::3])
    assert coverage_notes([ok, ok]) == []
    (note,) = coverage_notes([ok, slow])
    assert note.startswith("gyro not used in 1 of 2 star-tracker segments") and "rate 1" in note
    (note,) = coverage_notes([slow] * (NOTE_SEGMENTS + 2))
    assert note.startswith(f"gyro not used: it covers none of the {NOTE_SEGMENTS + 2}") and note.endswith("and 2 more")
    assert note.count("ratio 0.333") == NOTE_SEGMENTS
