"""The gyro offset fit's fast helpers give bit for bit what the general routines they replace give (issue 24)."""

from __future__ import annotations

import numpy as np

from processing.attitude import rotations as rot


def test_rotated_rates_are_quat_rotate_bit_for_bit() -> None:
    from processing.gyro_calibration.bias_fit import _rotated_rates

    rng = np.random.default_rng(6)
    w = rng.normal(size=(140_000, 3)) * 1e-3  # several chunks
    for q in (rng.normal(size=4), np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.3, -0.1, 0.9, 0.2])):
        got = _rotated_rates(q, w)
        assert got.flags.f_contiguous
        np.testing.assert_array_equal(got, rot.quat_rotate(q, w))
