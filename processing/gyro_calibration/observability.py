"""What the gyro-vs-star-tracker rate comparisons of an arc determine (paper 000 chain; issue 17, item 2).

The alignment step of 000 compares, in the windows of slow motion, the gyro rate w^g (gyro frame G,
the current calibration and drift model removed and mapped into the star-tracker axes S) with the
star-tracker rate w^a. Linearised about the current calibration (processing.gyro_calibration.alignment):

    r_i = w^g_S,i - w^a_i = J_i p + e_i,
    J_i = [ a_i  (scale factor m; or R^T e_k (R a_i)_k per gyro axis k), -[a_i x] (misalignment theta),
            I (constant drift b, S axes) (, x_i^k I: higher drift terms) ],

a_i = w^a_i and R = R(q_GS). The normal (information) matrix of the arc is N = sum_i w_i J_i^T J_i with
the weights of the estimate (w_i: inverse variance of the star-tracker rate at sample i). It depends
only on the rate history: with rates about one fixed axis u the misalignment about u has a zero column
(not determined), and with a constant rate vector a the columns of m (a), theta (-[a x]) and b (I) are
all constant, so only their sum is determined (a nadir-pointing arc at the orbital rate determines
neither the scale factor nor the misalignment nor the drift, only the apparent drift b + m a - a x theta).

Determinability (documented in the README, section of alignment_calibration):

0. the Jacobian is built from the measured rates: a column that the true rates do not excite is still
   filled by the rate noise (theta about the axis of a constant rate), and scaled to unit diagonal it
   would look informative; a column of m or theta whose diagonal is below NOISE_FLOOR_FACTOR (100) times
   what the noise alone gives (:func:`noise_floor`) is set to zero (undeterminable);
1. scale N to unit diagonal, C = D N D with D = diag(N)^-1/2 (unit-free; a parameter with a zero
   column is undeterminable at once);
2. eigen-decompose C; an eigenvalue below ``rank_tolerance`` x the largest is a null direction: a
   combination of parameters that the data determine at least 1/sqrt(rank_tolerance) (1000 by default)
   times worse than its parameters would be if they were uncorrelated. That ratio is far above
   what noise gives on a real arc and far below what a constant rate gives (the rate noise alone,
   ~1e-4 of the rate, leaves eigenvalues ~1e-8);
3. a parameter whose unit vector has a component above ``null_component`` (0.1) in the null directions
   is undeterminable: it cannot be separated from the others (e.g. m and b along the rate axis);
4. the determinable parameters' block of N is checked again (step 2); while it is singular, the one
   with the largest variance inflation (C^-1)_jj is moved to the undeterminable set.

The estimate and its covariance live on the determinable subspace (the eigen-directions kept in step
2): x = N+ J^T W r and Cov = N+ M N+ with N+ the inverse of N on that subspace (:func:`truncated_inverse`;
for a parameter outside the null directions it does not depend on what they hold), M = J^T W Cov(e) W J
built from the white star-tracker noise through the window polynomials (the T_p samples of a window are
one polynomial, so they are strongly correlated: :func:`noise_meat`), scaled by the residual variance
factor (observed weighted squared residuals over their expectation, never below 1) and by the
jackknife's variance ratio when that is significantly above 1 (alignment module).

Arrays (n, 3) in star-tracker axes, rates rad/s, angles rad; pure numerics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.attitude import rotations

__all__ = [
    "Motion",
    "Observability",
    "analyse_information",
    "motion_summary",
    "noise_floor",
    "noise_meat",
    "parameter_jacobian",
    "subspace_covariance",
    "truncated_inverse",
]

FloatArray = NDArray[np.float64]

RANK_TOLERANCE = 1e-6
"""Eigenvalue of the unit-diagonal information matrix, relative to the largest, below which a direction
is not determined (step 2 of the module docstring)."""
NULL_COMPONENT = 0.1
"""Component of a parameter in the null directions above which it is undeterminable (step 3)."""


def parameter_jacobian(w_A_rad_s: FloatArray, x_t: FloatArray, q_GS: FloatArray, *, drift_degree: int | None,
                       per_axis_scale_factor: bool = False) -> tuple[FloatArray, tuple[str, ...]]:
    """J (n, 3, p) of the rate residual w^g_S - w^a with respect to p and the parameter names (p,).

    w_A_rad_s (n, 3) star-tracker rates; x_t (n,) scaled time of the drift polynomial; q_GS (4,) the
    linearisation point. p = (scale factor: m, or m_x, m_y, m_z about the gyro axes, misalignment
    theta_x..z, drift b_x..z (S axes) and, for drift_degree k >= 1, its higher coefficients);
    drift_degree None: no drift.
    """
    a = np.asarray(w_A_rad_s, dtype=np.float64)
    n = a.shape[0]
    n_drift = 0 if drift_degree is None else drift_degree + 1
    n_m = 3 if per_axis_scale_factor else 1
    p = n_m + 3 + 3 * n_drift
    jac = np.zeros((n, 3, p))
    if per_axis_scale_factor:
        dcm = rotations.quat_to_dcm(np.asarray(q_GS, dtype=np.float64))  # v_G = dcm v_S
        a_G = a @ dcm.T
        jac[:, :, :3] = dcm.T[None, :, :] * a_G[:, None, :]  # column k: R^T e_k (R a)_k
        names = ["scale_factor_x", "scale_factor_y", "scale_factor_z"]
    else:
        jac[:, :, 0] = a
        names = ["scale_factor"]
    jac[:, :, n_m : n_m + 3] = -rotations.skew(a)
    names += ["misalignment_x", "misalignment_y", "misalignment_z"]
    for k in range(n_drift):
        jac[:, :, n_m + 3 + 3 * k : n_m + 6 + 3 * k] = np.eye(3) * (x_t**k)[:, None, None]
        names += [f"drift_{c}" if k == 0 else f"drift_{c}_t{k}" for c in "xyz"]
    return jac, tuple(names)


@dataclass(frozen=True)
class Observability:
    """What the information matrix determines (module docstring).

    names (p,); eigenvalues (p,) of the unit-diagonal information matrix relative to the largest,
    ascending, and its eigenvectors (p, p) columns; rank: eigenvalues above the tolerance;
    determinable (p,) bool; variance_inflation (p,): (C^-1)_jj on the determinable block (the factor
    by which correlations with the other determinable parameters inflate each variance; inf for the
    undeterminable); correlation (p, p) of the determinable block (NaN elsewhere); null_component (p,):
    each parameter's component in the null directions; rank_tolerance, null_threshold used;
    parameter_scale (p,): diag(N)^-1/2, so that ``parameter_scale[:, None] * eigenvectors`` are the
    directions in parameter units (0 for a zero column).
    """

    names: tuple[str, ...]
    eigenvalues: FloatArray
    eigenvectors: FloatArray
    rank: int
    determinable: NDArray[np.bool_]
    variance_inflation: FloatArray
    correlation: FloatArray
    null_component: FloatArray
    rank_tolerance: float
    null_threshold: float
    parameter_scale: FloatArray

    def null_directions(self, rows: slice) -> FloatArray:
        """Orthonormal basis (k, m) of the null directions' projection on the parameters ``rows`` (in their
        units), keeping the projections longer than null_threshold (e.g. the misalignment rotations that
        the data do not determine)."""
        # a zero column (scale 0) is a null direction by itself: give it a scale far above the others
        scale = np.where(self.parameter_scale > 0, self.parameter_scale, 1e6 * max(float(self.parameter_scale.max()),
                                                                                    1e-300))
        null = (scale[:, None] * self.eigenvectors)[:, self.eigenvalues < self.rank_tolerance][rows]
        if null.size == 0:
            return np.zeros((null.shape[0], 0))
        norm = np.linalg.norm(null, axis=0)
        null = null / np.where(norm > 0, norm, 1.0)
        part = np.linalg.norm(self.eigenvectors[:, self.eigenvalues < self.rank_tolerance][rows], axis=0)
        u, sv, _ = np.linalg.svd(null[:, part > self.null_threshold], full_matrices=False)
        return u[:, sv > 0.3]  # unit columns: directions that differ, not round-off

    def flags(self, prefix: str) -> NDArray[np.bool_]:
        """Determinable flags of the parameters whose name starts with prefix (e.g. "misalignment_")."""
        return np.array([d for n, d in zip(self.names, self.determinable, strict=True) if n.startswith(prefix)
                         and "_t" not in n[len(prefix):]], dtype=bool)


def _unit_diagonal(normal: FloatArray) -> tuple[FloatArray, FloatArray]:
    d = np.sqrt(np.maximum(np.diag(normal), 0.0))
    inv = np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 0.0)
    return normal * inv[:, None] * inv[None, :], d


def noise_floor(names: tuple[str, ...], weighted_variance: FloatArray, sigma_rad: FloatArray,
                q_GS: FloatArray) -> FloatArray:
    """Diagonal (p,) that the star-tracker rate noise alone puts on N (step 0 of the module docstring).

    The Jacobian is built from the measured rates a = w + e: a column of m or theta holds sum w_i |J_j(e_i)|^2
    even when the true rates do not excite it (theta about the axis of a constant rate). weighted_variance
    (n,): w_i times the rate variance per unit angle variance (sum_k gain_ik^2); sigma_rad (3,) the angle
    noise per axis. Scale factor: sum_a sigma_a^2; theta_k: sum_{a != k} sigma_a^2; per-axis m_k:
    sum_a R_ka^2 sigma_a^2; drift: 0."""
    s2 = np.asarray(sigma_rad, dtype=np.float64) ** 2
    total = float(np.sum(weighted_variance))
    dcm = rotations.quat_to_dcm(np.asarray(q_GS, dtype=np.float64))
    out = np.zeros(len(names))
    for j, name in enumerate(names):
        if name == "scale_factor":
            out[j] = total * float(s2.sum())
        elif name.startswith("scale_factor_"):
            out[j] = total * float(dcm["xyz".index(name[-1])] ** 2 @ s2)
        elif name.startswith("misalignment_"):
            out[j] = total * float(s2.sum() - s2["xyz".index(name[-1])])
    return out


NOISE_FLOOR_FACTOR = 100.0
"""A column of m or theta whose diagonal is below this factor times its noise floor (its excitation by the
true rates less than 10 times the noise in rms) is undeterminable (step 0)."""


def analyse_information(normal: FloatArray, names: tuple[str, ...], *, rank_tolerance: float = RANK_TOLERANCE,
                        null_threshold: float = NULL_COMPONENT, noise_floor: FloatArray | None = None
                        ) -> Observability:
    """Determinable parameters of a normal matrix (p, p) (steps 0-4 of the module docstring); noise_floor
    (p,): :func:`noise_floor` (step 0; None: skipped)."""
    nn = np.asarray(normal, dtype=np.float64)
    p = nn.shape[0]
    if noise_floor is not None:  # step 0: a column that only the rate noise fills carries no information
        weak = np.diag(nn) <= NOISE_FLOOR_FACTOR * np.asarray(noise_floor, dtype=np.float64)
        nn = nn.copy()
        nn[weak, :] = 0.0
        nn[:, weak] = 0.0
    c, d = _unit_diagonal(nn)
    lam, vec = np.linalg.eigh(c)
    top = max(float(lam[-1]), 1e-300)
    rel = lam / top
    null = rel < rank_tolerance
    null_comp = np.sqrt(np.sum(vec[:, null] ** 2, axis=1))
    det = (d > 0) & (null_comp <= null_threshold)
    vif = np.full(p, np.inf)
    while np.any(det):  # step 4: at most p iterations of a p x p eigen-decomposition
        sub = c[np.ix_(det, det)]
        lam_s, vec_s = np.linalg.eigh(sub)
        if lam_s[0] >= rank_tolerance * max(float(lam_s[-1]), 1e-300):
            vif[det] = np.diag(vec_s @ np.diag(1.0 / lam_s) @ vec_s.T)
            break
        comp = np.sum(vec_s[:, lam_s < rank_tolerance * lam_s[-1]] ** 2, axis=1)
        worst = np.flatnonzero(det)[int(np.argmax(comp))]
        det[worst] = False
    corr = np.full((p, p), np.nan)
    if np.any(det):
        cov = np.linalg.inv(c[np.ix_(det, det)])
        s = np.sqrt(np.diag(cov))
        corr[np.ix_(det, det)] = cov / s[:, None] / s[None, :]
    return Observability(names=names, eigenvalues=rel, eigenvectors=vec, rank=int(np.sum(~null)), determinable=det,
                         variance_inflation=vif, correlation=corr, null_component=null_comp,
                         rank_tolerance=rank_tolerance, null_threshold=null_threshold,
                         parameter_scale=np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 0.0))


def noise_meat(jac: FloatArray, weight: FloatArray, gain: FloatArray, window: NDArray[np.intp],
               sigma_rad: FloatArray) -> FloatArray:
    """M = J^T W Cov(e) W J (p, p) for rate errors e_i = sum_k gain_ik n_k of white star-tracker angle noise.

    jac (n, 3, p), weight (n,) the estimate's weights, gain (n, width): the rate error of T_p sample i
    per unit angle noise at the k-th star-tracker sample of its window (window_rates.WindowRates.rate_noise_gain),
    window (n,) window ids 0..W-1 (each window's samples its own: windows do not share star-tracker
    samples), sigma_rad (3,) the star-tracker angle noise per axis. With H_wk = sum_{i in w} w_i gain_ik J_i,
    M = sum_w sum_k H_wk^T diag(sigma^2) H_wk.
    """
    order = np.argsort(window, kind="stable")
    first = np.flatnonzero(np.diff(window[order], prepend=-1))
    contrib = (weight[:, None] * gain)[:, :, None, None] * jac[:, None, :, :]  # (n, width, 3, p)
    h = np.add.reduceat(contrib[order], first, axis=0)  # (W, width, 3, p)
    hs = (h * np.asarray(sigma_rad, dtype=np.float64)[None, None, :, None]).reshape(-1, jac.shape[2])
    return hs.T @ hs


def truncated_inverse(normal: FloatArray, rank_tolerance: float = RANK_TOLERANCE) -> FloatArray:
    """Inverse (..., p, p) of normal matrices (..., p, p) on their determinable subspace.

    With C = D N D (unit diagonal) = V diag(lambda) V^T: D V_k diag(1 / lambda_k) V_k^T D over the
    eigenvalues lambda_k >= rank_tolerance x the largest (module docstring, step 2). For a parameter (or
    combination) outside the null directions this is its covariance per unit noise whatever the null
    directions hold; along the null directions it is zero (they are not determined, not known)."""
    nn = np.asarray(normal, dtype=np.float64)
    diag = np.sqrt(np.maximum(np.einsum("...ii->...i", nn), 0.0))
    d = np.where(diag > 0, 1.0 / np.where(diag > 0, diag, 1.0), 0.0)
    c = nn * d[..., :, None] * d[..., None, :]
    lam, vec = np.linalg.eigh(c)
    keep = lam >= rank_tolerance * np.maximum(lam[..., -1:], 1e-300)
    inv_lam = np.where(keep, 1.0 / np.where(keep, lam, 1.0), 0.0)
    out = np.einsum("...ik,...k,...jk->...ij", vec, inv_lam, vec)
    return out * d[..., :, None] * d[..., None, :]


def subspace_covariance(normal: FloatArray, meat: FloatArray | None, rank_tolerance: float = RANK_TOLERANCE,
                        scale: float = 1.0) -> FloatArray:
    """Covariance (p, p) of the LSQ estimate on the determinable subspace (N+ = :func:`truncated_inverse`):
    scale N+ M N+ (meat given), or scale N+ (the weights are inverse variances of independent samples
    and scale is their residual variance factor)."""
    n_plus = truncated_inverse(normal, rank_tolerance)
    block = n_plus if meat is None else n_plus @ meat @ n_plus
    return scale * 0.5 * (block + block.T)


@dataclass(frozen=True)
class Motion:
    """The rate history of the windows in numbers for the messages: the principal rotation axes (3, 3)
    columns (S axes) of the weighted rate second-moment matrix, the rms rate about each (3,) [rad/s],
    and the weighted mean and std of |w| [rad/s]."""

    axes: FloatArray
    rms_rate_rad_s: FloatArray
    mean_rate_rad_s: float
    std_rate_rad_s: float


def motion_summary(w_A_rad_s: FloatArray, weight: FloatArray) -> Motion:
    """:class:`Motion` of rates (n, 3) with weights (n,)."""
    a = np.asarray(w_A_rad_s, dtype=np.float64)
    w = np.asarray(weight, dtype=np.float64)
    w = w / max(float(w.sum()), 1e-300)
    second = np.einsum("n,ni,nj->ij", w, a, a)
    lam, axes = np.linalg.eigh(second)
    mag = np.linalg.norm(a, axis=1)
    mean = float(np.sum(w * mag))
    return Motion(axes=axes[:, ::-1], rms_rate_rad_s=np.sqrt(np.maximum(lam[::-1], 0.0)), mean_rate_rad_s=mean,
                  std_rate_rad_s=float(np.sqrt(max(float(np.sum(w * (mag - mean) ** 2)), 0.0))))
