"""Which states the arc determines: the information content of the data (DESIGN.md, honesty contract).

The smoothed covariance of the whole state at the first epoch, P_s, combines the prior P_0 with everything
the data say (every measurement of the arc, carried back by the smoother). In coordinates scaled by the
prior sigmas (P~ = S^-1 P_s S^-1, prior = I) the information the data add is J = P~^-1 - I. Its inverse is
the covariance the data alone would give with every other state unknown: along a direction the data do not
see, an eigenvalue lambda of P~ is 1 and lambda / (1 - lambda) is infinite. State i is *determined* when
the data alone fix it to better than ``threshold`` times its prior sigma:

    r_i = sqrt([V diag(lambda / (1 - lambda)) V^T]_ii) < threshold.

This catches combinations as well as single states: on a constant rate the scale factor and the bias of
that axis are seen only as s w + b, so both get large r_i even though their sum is known, and both are
reported as undetermined (null). The unobservable directions (eigenvalues above 1 - threshold²) are
returned as well, as unit vectors in the scaled coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.definitive.model import FloatArray

MAX_LAMBDA = 1.0 - 1e-12


@dataclass(frozen=True)
class Observability:
    """data_sigma_ratio (n,): sigma from the data alone over the prior sigma (inf: not seen at all);
    determined (n,) bool; posterior_ratio (n,): smoothed sigma over prior sigma; unobservable_directions
    (d, n) unit vectors in prior-scaled coordinates."""

    data_sigma_ratio: FloatArray
    determined: NDArray[np.bool_]
    posterior_ratio: FloatArray
    unobservable_directions: FloatArray


def observability(P_smoothed: FloatArray, prior_sigma: FloatArray, threshold: float) -> Observability:
    s = np.asarray(prior_sigma, dtype=np.float64)
    Pt = P_smoothed / np.outer(s, s)
    Pt = 0.5 * (Pt + Pt.T)
    lam, V = np.linalg.eigh(Pt)
    lam = np.clip(lam, 0.0, MAX_LAMBDA)
    data_var = (V * (lam / (1.0 - lam))) @ V.T
    ratio = np.sqrt(np.clip(np.diag(data_var), 0.0, None))
    ratio = np.where(np.diag(data_var) > 1e10, np.inf, ratio)
    weak = lam > 1.0 - threshold**2
    return Observability(data_sigma_ratio=ratio, determined=ratio < threshold,
                         posterior_ratio=np.sqrt(np.clip(np.diag(Pt), 0.0, None)),
                         unobservable_directions=V[:, weak].T.copy())
