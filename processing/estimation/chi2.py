"""Chi-square distribution functions for consistency tests and confidence intervals.

The same values as ``scipy.stats.chi2`` (ppf, isf, sf, cdf) from the incomplete-gamma functions of
``scipy.special`` (chi²(k) is 2 Gamma(k/2, 1): gammainc, gammaincc and their inverses): importing
scipy.stats costs about 2 s of CPU in every process that does it (the service, the job forkserver), for
four functions of one distribution. Vectorised over both arguments; ``dof`` may be any positive real
(e.g. an effective number of degrees of freedom).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import gammainc, gammaincc, gammainccinv, gammaincinv

__all__ = ["chi2_cdf", "chi2_isf", "chi2_ppf", "chi2_sf"]


def _out(x: Any) -> Any:
    return float(x) if np.ndim(x) == 0 else np.asarray(x, dtype=np.float64)


def chi2_cdf(x: ArrayLike, dof: ArrayLike) -> Any:
    """P(X <= x) for X ~ chi²(dof)."""
    return _out(gammainc(np.asarray(dof, dtype=np.float64) / 2.0, np.asarray(x, dtype=np.float64) / 2.0))


def chi2_sf(x: ArrayLike, dof: ArrayLike) -> Any:
    """P(X > x) for X ~ chi²(dof) (accurate in the far tail, unlike 1 - cdf)."""
    return _out(gammaincc(np.asarray(dof, dtype=np.float64) / 2.0, np.asarray(x, dtype=np.float64) / 2.0))


def chi2_ppf(q: ArrayLike, dof: ArrayLike) -> Any:
    """The q-quantile x of chi²(dof): P(X <= x) = q."""
    return _out(2.0 * gammaincinv(np.asarray(dof, dtype=np.float64) / 2.0, q))


def chi2_isf(p: ArrayLike, dof: ArrayLike) -> Any:
    """The upper p-quantile x of chi²(dof): P(X > x) = p (accurate for small p)."""
    return _out(2.0 * gammainccinv(np.asarray(dof, dtype=np.float64) / 2.0, p))
