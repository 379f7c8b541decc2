"""The gyro offset fit's fast helpers give bit for bit what the general routines they replace give (issue 24)."""

from __future__ import annotations

import numpy as np

from processing.attitude import rotations as rot
from processing.gyro_calibration.bias_fit_model import quat_product


def test_quat_product_is_quat_multiply_bit_for_bit() -> None:
    rng = np.random.default_rng(5)
    p = rng.normal(size=(2000, 4)) * 10.0 ** rng.integers(-8, 3, (2000, 1))
    q = rng.normal(size=(2000, 4))
    for a, b in ((p, q), (p[0], q), (p, q[0]), (p[0], q[1]), (p[:, None, :][:10], q[None, :5, :])):
        got = quat_product(a, b)
        want = rot.quat_multiply(a, b)
        assert got.shape == want.shape and got.flags.c_contiguous
        np.testing.assert_array_equal(got, want)


def test_rotated_rates_are_quat_rotate_bit_for_bit() -> None:
    from processing.gyro_calibration.bias_fit import _rotated_rates

    rng = np.random.default_rng(6)
    w = rng.normal(size=(140_000, 3)) * 1e-3  # several chunks
    for q in (rng.normal(size=4), np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.3, -0.1, 0.9, 0.2])):
        got = _rotated_rates(q, w)
        assert got.flags.f_contiguous
        np.testing.assert_array_equal(got, rot.quat_rotate(q, w))


def test_dcm_rows_are_quat_to_dcm_bit_for_bit() -> None:
    from processing.gyro_calibration.bias_fit import _dcm_rows

    q = np.random.default_rng(7).normal(size=(3000, 4))
    got = _dcm_rows(q)
    assert got.flags.c_contiguous
    np.testing.assert_array_equal(got, rot.quat_to_dcm(q))
