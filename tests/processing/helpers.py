"""Small checks shared by the simulator tests."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.stats import chi2


def chi2_bounds(n: int, level: float = 0.999) -> tuple[float, float]:
    """Two-sided bounds of s^2 / sigma^2 for s^2 = sum(x^2) / n of n zero-mean normal samples."""
    return chi2.ppf((1 - level) / 2, n) / n, chi2.ppf(1 - (1 - level) / 2, n) / n


def assert_same_streams(a: dict[str, dict[str, Any]], b: dict[str, dict[str, Any]]) -> None:
    """Two simulations' telemetry (stream -> column -> values) are identical, column by column."""
    assert a.keys() == b.keys()
    for stream, cols in a.items():
        assert cols.keys() == b[stream].keys(), stream
        for name, values in cols.items():
            np.testing.assert_array_equal(values, b[stream][name], err_msg=f"{stream}.{name}")
