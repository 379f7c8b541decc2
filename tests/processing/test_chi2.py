"""processing.estimation.chi2 against scipy.stats.chi2 (the authority it replaces at import time)."""

import numpy as np
from scipy.stats import chi2

from processing.estimation.chi2 import chi2_cdf, chi2_isf, chi2_ppf, chi2_sf


def test_agrees_with_scipy_stats_over_quantiles_and_dofs():
    dof = np.array([[0.5], [1.0], [3.0], [7.5], [60.0], [1e4]])
    q = np.array([[1e-9, 0.005, 0.025, 0.5, 0.975, 0.995]])
    np.testing.assert_allclose(chi2_ppf(q, dof), chi2.ppf(q, dof), rtol=1e-12)
    np.testing.assert_allclose(chi2_isf(q, dof), chi2.isf(q, dof), rtol=1e-12)
    x = chi2.ppf(q, dof)
    np.testing.assert_allclose(chi2_cdf(x, dof), q + 0 * dof, rtol=1e-10)
    np.testing.assert_allclose(chi2_sf(x, dof), chi2.sf(x, dof), rtol=1e-10)


def test_scalars_come_back_as_floats():
    assert isinstance(chi2_ppf(0.975, 3), float)
    assert abs(chi2_ppf(0.975, 3) - 9.348403604496148) < 1e-12  # tables: chi²_{0.975}(3) = 9.348
    assert abs(chi2_isf(0.05, 1) - 3.841458820694124) < 1e-12  # 3.841 (the 5 % point of one dof)
