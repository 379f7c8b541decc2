"""Off-line alignment and scale-factor calibration of the gyro against the star tracker (000, eq. 9).

Paper 000 (Somov & Butyrin 2016), section "Юстировка и калибровка масштабного коэффициента": the
misalignment S^Delta (gyro frame G relative to the star-tracker frame A) and the scale-factor error m
are found off-line by comparing the angular rate restored independently from the gyro and from the
star tracker, at the same times, in windows of n_j in [12..18] T_o inside calibration intervals
(class MT_alpha, |w| <= 1 deg/s):

(i) w^g from the gyro spline (processing.signal.two_pass_filter) in G, every T_p;
(ii) the star-tracker MRPs sigma^a_k of the window fitted by a 5th-order least-squares polynomial;
(iii) w^a from the inverse MRP kinematics (processing.attitude.mrp_kinematics.rate_from_mrp) of that
    polynomial, every T_p.

Then QUEST (000, eq. 9) on the unit vectors g_i = w^g_i / |w^g_i|, a_i = w^a_i / |w^a_i| gives S^Delta,
and the scale factor follows from the ratios of the magnitudes. Details of this implementation:

- frames: with our convention (DESIGN.md) S^Delta = dcm_GS = R(q_GS), v_G = q_GS o v_S o q_GS^-1.
  QUEST is processing.attitude.wahba.quest with b = g (frame G), r = a (frame S), so it returns q_GS directly
  (its eq. 9 eigenvector in Shuster's convention is the conjugate; the module documents it). The
  result is checked against Davenport's q-method and the SVD method (``solver_disagreement_rad``).
- weights: the error of a unit vector is |dw_perp| / |w|, and the star-tracker rate error does not
  depend on the rate but on the position in the window (the derivative of the fitted polynomial is
  ~6x more uncertain at the ends than at the centre), so alpha_i = |w^a_i|^2 / var_i with var_i the
  polynomial's rate variance at that sample are the inverse variances (000 leaves alpha_i free, with
  sum 1; the normalisation does not change the solution). The same weights serve the scale factor and
  the linear step.
- scale factor: under eq. (1), |w^g| / |w^a| = 1 + m, so m^ is the weighted mean of |w^g|/|w^a| - 1
  with the same weights, m^ = sum |a| |g| / sum |a|^2 - 1. (000 writes m_i = 1 - w^g/w^a, which is -m
  under its own eq. 1; the sign here is the one consistent with eq. 1.)
- drift: the gyro rates must be free of drift before they are compared (b ~ 1"/s against rates of
  ~2000"/s would bias m by 5e-4). The caller subtracts its drift model (the observer's trend); a
  residual drift db(t), a polynomial in time of degree ``drift_degree`` (0: constant), is estimated
  jointly with the corrections dm, dtheta by linear least squares on all window samples,
  r = w^g_S - w^a = dm w^a - [w^a x] dtheta + db(t) (the linearisation of eq. 1 about the current
  calibration, in star-tracker axes), and removed before QUEST. Without it the drift observer, which
  reads dm w + dtheta x w as drift during a scan at constant rate, would keep the iteration from
  converging (the first pass, with no drift model yet, uses the full 2nd-order polynomial).
- solver input: processing.attitude.wahba's solvers sum over the vectors of an epoch row by row (they are built
  for many epochs of few vectors). The attitude profile matrix B = sum alpha_i g_i a_i^T is a
  sufficient statistic of Wahba's problem (K of eq. 9 depends on B only), so the n pairs are replaced by
  the three pairs of its singular value decomposition, B = sum s_k u_k v_k^T, which have the same B,
  the same K and the same solution.
- uncertainty: samples of one window are strongly correlated (one polynomial), so the covariance of
  (dm, dtheta, db) is the delete-one-window jackknife of that linear least squares (which, with equal
  weights on the rate residuals, is the linearisation of the weighted QUEST + scale estimate).
- observability: the misalignment about an axis is seen only through rates perpendicular to it. The
  spread matrix F = sum alpha_i (I - a_i a_i^T) / sum alpha_i (trace 2; eigenvalues 0, 1, 1 for rates
  about one axis only) is reported with its eigen-decomposition; a direction with an eigenvalue below
  ``min_spread`` or a jackknife sigma above ``max_sigma_rad`` is unobservable: its component is held at
  the prior value (the nominal mounting), and every axis with a component above 0.1 along it is
  reported as unknown.

Times s, rates rad/s, angles rad, quaternions (..., 4) scalar first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations, wahba
from processing.attitude.mrp_kinematics import rate_from_mrp
from processing.gyro_calibration.drift_observer import DriftTrend

__all__ = [
    "AlignmentError",
    "AlignmentEstimate",
    "WindowRates",
    "alignment_windows",
    "estimate_alignment",
    "star_tracker_window_rates",
]

FloatArray = NDArray[np.float64]

POLY_DEGREE = 5
"""Degree of the star-tracker MRP polynomial in a window (000: 5)."""
REGULARISATION = 1e-9
"""Weight (relative to the total) of three pseudo vector pairs that pin unobservable rotations to the prior."""


class AlignmentError(ValueError):
    """Not enough or inconsistent data for the alignment (no windows, shapes)."""


def alignment_windows(
    t_s: ArrayLike, eligible: ArrayLike, *, n_min: int = 12, n_max: int = 18, max_spacing_s: float | None = None
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Tile runs of eligible star-tracker samples into windows of n_min..n_max samples (000: 12..18).

    t_s (K,) sample times [s]; eligible (K,) bool (class MT_alpha and gyro data on both sides). A run
    is a maximal sequence of eligible samples with spacing <= max_spacing_s (default 1.5 x the median
    spacing). A run of L samples gives floor(L / n_max) windows of n_max samples, plus one of the
    remaining L mod n_max if that is >= n_min (the longest windows carry the most information: the
    rate error of a window falls like n^-3/2). Returns the start and stop (exclusive) sample indices
    (W,) of the windows, in time order.
    """
    t = np.asarray(t_s, dtype=np.float64)
    ok = np.asarray(eligible, dtype=bool)
    if t.ndim != 1 or ok.shape != t.shape:
        raise AlignmentError(f"expected t_s (K,) and eligible (K,), got {t.shape} and {ok.shape}")
    if not 2 <= n_min <= n_max:
        raise AlignmentError(f"need 2 <= n_min <= n_max, got {n_min}, {n_max}")
    if t.size < 2:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    spacing = max_spacing_s if max_spacing_s is not None else 1.5 * float(np.median(np.diff(t)))
    brk = np.ones(t.size, dtype=bool)
    brk[1:] = (np.diff(t) > spacing) | ~ok[1:] | ~ok[:-1]
    run_start = np.flatnonzero(brk & ok)
    run_id = np.cumsum(brk) - 1
    lengths = np.bincount(run_id[ok], minlength=run_id[-1] + 1)[run_id[run_start]]
    starts: list[int] = []
    stops: list[int] = []
    for a, n in zip(run_start.tolist(), lengths.tolist(), strict=True):  # one iteration per run (tens)
        if n < n_min:
            continue
        sizes = [n_max] * (n // n_max)
        if n % n_max >= n_min:
            sizes.append(n % n_max)
        edges = a + np.concatenate([[0], np.cumsum(sizes)])
        starts.extend(edges[:-1].tolist())
        stops.extend(edges[1:].tolist())
    return np.asarray(starts, dtype=np.intp), np.asarray(stops, dtype=np.intp)


@dataclass(frozen=True)
class WindowRates:
    """Star-tracker-derived rates in the alignment windows (000, steps ii-iii).

    t_s (n,): the T_p grid of every window (from its first to its last sample); window (n,) index;
    w_A_rad_s (n, 3): rate of the star-tracker frame in its own axes; rate_variance_s2 (n,): variance
    of each rate component per unit variance of the star-tracker angle noise [1/s^2] (the polynomial
    derivative's error grows from the centre to the ends of a window by a factor ~6 in std); starts,
    stops (W,): sample ranges; residual_rms_rad (W, 3): rms of the polynomial fit residuals as angles
    (4 sigma) per axis, with the degrees of freedom n_j - 6 (an estimate of the star-tracker noise).
    """

    t_s: FloatArray
    window: NDArray[np.intp]
    w_A_rad_s: FloatArray
    rate_variance_s2: FloatArray
    starts: NDArray[np.intp]
    stops: NDArray[np.intp]
    residual_rms_rad: FloatArray


def star_tracker_window_rates(
    t_s: ArrayLike, q_IS: ArrayLike, starts: ArrayLike, stops: ArrayLike, *, t_p_s: float = 0.125,
    degree: int = POLY_DEGREE,
) -> WindowRates:
    """Fit each window's star-tracker MRPs by a degree-5 LSQ polynomial and differentiate (000, ii-iii).

    t_s (K,) [s], q_IS (K, 4); starts, stops (W,) sample ranges (alignment_windows). The MRPs are those
    of the attitude relative to the window's middle sample, sigma_k = sigma(q_mid^-1 o q_k) (small, no
    shadow switching; the rate of S relative to I is the same); local time x = (t - t_c) / h in [-1, 1].
    Rates w^a = F^w(sigma(x), d sigma / dt) on t_first + j t_p_s <= t_last. Vectorised over windows
    (padded to the longest). Returns :class:`WindowRates`.
    """
    t = np.asarray(t_s, dtype=np.float64)
    q = rotations.quat_normalize(np.asarray(q_IS, dtype=np.float64))
    a = np.asarray(starts, dtype=np.intp)
    b = np.asarray(stops, dtype=np.intp)
    if a.size == 0:
        raise AlignmentError("no alignment windows: no calibration interval of at least n_min samples")
    n_w = b - a
    if np.any(n_w < degree + 2):
        raise AlignmentError(f"windows need at least degree + 2 = {degree + 2} samples, got {int(n_w.min())}")
    w_count, width = a.size, int(n_w.max())
    pos = np.arange(width)
    mask = pos[None, :] < n_w[:, None]
    idx = np.where(mask, a[:, None] + pos, a[:, None])
    mid = a + n_w // 2
    t_c = 0.5 * (t[a] + t[b - 1])
    half = 0.5 * (t[b - 1] - t[a])
    x = (t[idx] - t_c[:, None]) / half[:, None]
    q_rel = rotations.quat_multiply(rotations.quat_conjugate(q[mid])[:, None, :], q[idx])
    sigma = rotations.quat_to_mrp(q_rel)  # (W, width, 3)
    v = np.where(mask[..., None], x[..., None] ** np.arange(degree + 1), 0.0)
    vt = np.swapaxes(v, 1, 2)
    coef = np.linalg.solve(vt @ v, vt @ np.where(mask[..., None], sigma, 0.0))  # (W, degree + 1, 3)
    resid = np.where(mask[..., None], sigma - v @ coef, 0.0)
    rms = 4.0 * np.sqrt(np.sum(resid**2, axis=1) / (n_w - degree - 1)[:, None])
    counts = np.floor((t[b - 1] - t[a]) / t_p_s + 1e-9).astype(np.intp) + 1
    window = np.repeat(np.arange(w_count), counts)
    offset = np.arange(window.size) - np.repeat(np.cumsum(counts) - counts, counts)
    tp = t[a][window] + offset * t_p_s
    xp = (tp - t_c[window]) / half[window]
    powers = xp[:, None] ** np.arange(degree + 1)
    dpowers = np.zeros_like(powers)
    dpowers[:, 1:] = np.arange(1, degree + 1) * powers[:, :-1]
    c = coef[window]
    s_fit = np.einsum("np,npk->nk", powers, c)
    s_dot = np.einsum("np,npk->nk", dpowers, c) / half[window][:, None]
    # Var(sigma') = var_sigma d^T (V^T V)^-1 d / half^2; angle noise = 4 sigma noise and w ~ 4 sigma'.
    gram_inv = np.linalg.inv(vt @ v)[window]
    var = np.einsum("np,npq,nq->n", dpowers, gram_inv, dpowers) / half[window] ** 2
    return WindowRates(t_s=tp, window=window, w_A_rad_s=rate_from_mrp(s_fit, s_dot), rate_variance_s2=var,
                       starts=a, stops=b, residual_rms_rad=rms)


@dataclass(frozen=True)
class AlignmentEstimate:
    """Result of one alignment and scale-factor estimate (000, eq. 9 and the m_i mean).

    q_GS (4,): estimated S^Delta = R(q_GS) (canonical); misalignment_rad (3,): rotation vector of
    q_GS_nominal^-1 o q_GS in star-tracker axes (= rotvec(q_GS) when the nominal is the identity);
    scale_factor_error: m^; misalignment_cov_rad2 (3, 3), scale_factor_sigma: jackknife over windows;
    drift_offset: the residual drift polynomial removed (gyro frame, a DriftTrend);
    drift_offset_sigma_rad_s (3,): jackknife sigma of its constant term;
    spread_eigenvalues (3,) ascending and spread_axes (3, 3) columns: the rate-direction spread matrix;
    observable_axes (3,) bool per star-tracker axis; solver_disagreement_rad: largest angle between
    QUEST, q-method and SVD; n_windows, n_samples; residual_rad_s (n, 3): w^g_S - w^a after the
    estimate (star-tracker axes); linearised (p,): (dm, dtheta, drift coefficients in S) of the linear
    step.
    """

    q_GS: FloatArray
    misalignment_rad: FloatArray
    scale_factor_error: float
    misalignment_cov_rad2: FloatArray
    scale_factor_sigma: float
    drift_offset: DriftTrend
    drift_offset_sigma_rad_s: FloatArray
    spread_eigenvalues: FloatArray
    spread_axes: FloatArray
    observable_axes: NDArray[np.bool_]
    solver_disagreement_rad: float
    n_windows: int
    n_samples: int
    residual_rad_s: FloatArray
    linearised: FloatArray

    @property
    def misalignment_sigma_rad(self) -> FloatArray:
        """Per-axis 1-sigma of the misalignment (rad), NaN on unobservable axes."""
        s = np.sqrt(np.diag(self.misalignment_cov_rad2))
        return np.where(self.observable_axes, s, np.nan)


def _normal_blocks(w_a: FloatArray, r: FloatArray, x: FloatArray, sw: FloatArray, window: NDArray[np.intp],
                   drift_degree: int | None) -> tuple[FloatArray, FloatArray]:
    """Per-window normal matrices N_w (W, p, p) and right sides v_w (W, p) of the weighted (sw) LSQ of
    r = dm a - [a x] dtheta + sum_k c_k x^k (the drift polynomial only if drift_degree is not None)."""
    n = w_a.shape[0]
    n_drift = 0 if drift_degree is None else drift_degree + 1
    p = 4 + 3 * n_drift
    jac = np.zeros((n, 3, p))
    jac[:, :, 0] = w_a
    jac[:, :, 1:4] = -rotations.skew(w_a)
    for k in range(n_drift):
        jac[:, :, 4 + 3 * k : 7 + 3 * k] = np.eye(3) * (x**k)[:, None, None]
    nn = np.einsum("n,nki,nkj->nij", sw, jac, jac)
    vv = np.einsum("n,nki,nk->ni", sw, jac, r)
    order = np.argsort(window, kind="stable")
    first = np.flatnonzero(np.diff(window[order], prepend=-1))  # window ids are 0..W-1, all present
    return np.add.reduceat(nn[order], first, axis=0), np.add.reduceat(vv[order], first, axis=0)


def _solve_wahba(b: FloatArray, r: FloatArray, w: FloatArray) -> tuple[FloatArray, float]:
    """QUEST (000 eq. 9) via processing.attitude.wahba on the three SVD pairs of B (module docstring); returns
    q_BR and the largest angle [rad] between QUEST, Davenport's q-method and the SVD method."""
    big_b = wahba.attitude_profile_matrix(b, r, w)
    u, s, vt = np.linalg.svd(big_b)
    pairs = (u.T, vt, s)
    q = rotations.quat_canonical(wahba.quest(*pairs, covariance=False).q)
    others = (wahba.q_method(*pairs, covariance=False).q, wahba.svd_method(*pairs, covariance=False).q)
    return q, float(max(rotations.angle_between(q, o) for o in others))


def estimate_alignment(
    t_s: ArrayLike,
    w_G_rad_s: ArrayLike,
    w_A_rad_s: ArrayLike,
    window: ArrayLike,
    sample_weight: ArrayLike | None = None,
    *,
    q_GS_prior: ArrayLike,
    scale_factor_prior: float = 0.0,
    q_GS_nominal: ArrayLike = (1.0, 0.0, 0.0, 0.0),
    drift_degree: int | None = 0,
    min_spread: float = 0.02,
    max_sigma_rad: float = 10.0 * np.pi / 648000.0,
) -> AlignmentEstimate:
    """Misalignment (QUEST, 000 eq. 9) and scale-factor error from gyro vs star-tracker rates.

    t_s (n,) [s] sample times; w_G_rad_s (n, 3): gyro rates in G with the drift model already
    subtracted; w_A_rad_s (n, 3): the star-tracker rates at the same times (frame A = S); window (n,)
    window index of each sample; sample_weight (n,): inverse variance of the star-tracker rate error of
    each sample (WindowRates.rate_variance_s2 ** -1; default equal). drift_degree: degree of the jointly
    estimated residual drift polynomial (None: none).
    q_GS_prior, scale_factor_prior: current calibration (linearisation point of the drift-offset step,
    and the value kept along unobservable directions); q_GS_nominal: the configured mounting.
    min_spread, max_sigma_rad: observability thresholds (module docstring). Returns
    :class:`AlignmentEstimate`.
    """
    smp = _alignment_samples(t_s, w_G_rad_s, w_A_rad_s, window, sample_weight)
    q_prior = rotations.quat_canonical(rotations.quat_normalize(np.asarray(q_GS_prior, dtype=np.float64)))
    q_nom = rotations.quat_canonical(rotations.quat_normalize(np.asarray(q_GS_nominal, dtype=np.float64)))
    lin = _linear_step(smp, q_prior, float(scale_factor_prior), drift_degree)
    rot = _quest_rotation(smp, lin.g_corr, q_prior)
    obs = _observability(smp, rot, lin.cov[1:4, 1:4], q_prior, q_nom, min_spread, max_sigma_rad)
    # Scale factor: weighted mean of |w^g| / |w^a| - 1 with weights sw |w^a|^2 (000: mean of the m_i).
    g_norm = np.linalg.norm(lin.g_corr, axis=1)
    m_est = float(np.sum(smp.sw * np.sqrt(rot.a_norm2) * g_norm) / rot.total) - 1.0
    residual = rotations.quat_rotate(rotations.quat_conjugate(obs.q_GS), lin.g_corr) / (1.0 + m_est) - smp.a_vec
    return AlignmentEstimate(
        q_GS=obs.q_GS, misalignment_rad=obs.theta, scale_factor_error=m_est, misalignment_cov_rad2=lin.cov[1:4, 1:4],
        scale_factor_sigma=float(np.sqrt(lin.cov[0, 0])), drift_offset=lin.offset,
        drift_offset_sigma_rad_s=lin.offset_sigma, spread_eigenvalues=obs.spread_eigenvalues,
        spread_axes=obs.spread_axes, observable_axes=obs.observable_axes, solver_disagreement_rad=rot.disagreement,
        n_windows=smp.n_windows, n_samples=int(smp.g.shape[0]), residual_rad_s=residual, linearised=lin.x,
    )


@dataclass(frozen=True)
class _Samples:
    """The finite samples: times t (n,), gyro rates g and star-tracker rates a_vec (n, 3), window ids
    renumbered 0..W-1, weights sw (n,) scaled to a largest of 1, and the number of windows W."""

    t: FloatArray
    g: FloatArray
    a_vec: FloatArray
    wid: NDArray[np.intp]
    sw: FloatArray
    n_windows: int


def _alignment_samples(
    t_s: ArrayLike, w_G_rad_s: ArrayLike, w_A_rad_s: ArrayLike, window: ArrayLike, sample_weight: ArrayLike | None
) -> _Samples:
    t = np.asarray(t_s, dtype=np.float64)
    g = np.asarray(w_G_rad_s, dtype=np.float64)
    a_vec = np.asarray(w_A_rad_s, dtype=np.float64)
    wid = np.asarray(window, dtype=np.intp)
    if g.ndim != 2 or g.shape[1] != 3 or a_vec.shape != g.shape or wid.shape != g.shape[:1] or t.shape != wid.shape:
        raise AlignmentError(
            f"expected t_s (n,), rates (n, 3), (n, 3), window (n,), got {t.shape}, {g.shape}, {a_vec.shape}, "
            f"{wid.shape}"
        )
    sw = np.ones(t.shape) if sample_weight is None else np.asarray(sample_weight, dtype=np.float64)
    if sw.shape != t.shape or np.any(sw < 0):
        raise AlignmentError(f"sample_weight must be (n,) = {t.shape} and >= 0, got {sw.shape}")
    good = np.all(np.isfinite(g), axis=1) & np.all(np.isfinite(a_vec), axis=1) & np.isfinite(t) & np.isfinite(sw)
    t, g, a_vec, wid, sw = t[good], g[good], a_vec[good], wid[good], sw[good] / np.max(sw[good])
    _, wid = np.unique(wid, return_inverse=True)
    n_win = int(wid.max()) + 1 if wid.size else 0
    if n_win < 3:
        raise AlignmentError(f"need at least 3 alignment windows with valid rates, got {n_win}")
    return _Samples(t, g, a_vec, wid, sw, n_win)


@dataclass(frozen=True)
class _Linear:
    """The linear step: x = (dm, dtheta, drift coefficients in S), its jackknife covariance, the residual
    drift polynomial in G and the sigma of its constant term, and the gyro rates with it removed."""

    x: FloatArray
    cov: FloatArray
    offset: DriftTrend
    offset_sigma: FloatArray
    g_corr: FloatArray


def _linear_step(smp: _Samples, q_prior: FloatArray, m0: float, drift_degree: int | None) -> _Linear:
    """Residual drift polynomial (and the linearised dm, dtheta), delete-one-window jackknife covariance."""
    t, g, a_vec, n_win = smp.t, smp.g, smp.a_vec, smp.n_windows
    q_SG = rotations.quat_conjugate(q_prior)
    t_ref = 0.5 * float(t.min() + t.max())
    scale = max(0.5 * float(t.max() - t.min()), 1.0)
    x_t = (t - t_ref) / scale
    r = rotations.quat_rotate(q_SG, g) / (1.0 + m0) - a_vec
    big_n, big_v = _normal_blocks(a_vec, r, x_t, smp.sw, smp.wid, drift_degree)
    n_tot, v_tot = big_n.sum(axis=0), big_v.sum(axis=0)
    # pseudo-inverses: a rotation about the only rate direction leaves the normal matrix singular
    x = np.linalg.pinv(n_tot, rcond=1e-12, hermitian=True) @ v_tot
    loo = (np.linalg.pinv(n_tot[None] - big_n, rcond=1e-12, hermitian=True) @ (v_tot[None] - big_v)[..., None])[..., 0]
    dev = loo - loo.mean(axis=0)
    cov = (n_win - 1) / n_win * dev.T @ dev
    n_drift = 0 if drift_degree is None else drift_degree + 1
    coef_S = x[4:].reshape(n_drift, 3) if n_drift else np.zeros((1, 3))
    coef_G = (1.0 + m0) * rotations.quat_rotate(q_prior, coef_S)
    offset = DriftTrend(coefficients=coef_G, t_ref_s=t_ref, scale_s=scale, span_s=(float(t.min()), float(t.max())))
    offset_sigma = np.sqrt(np.diag(cov)[4:7]) * (1.0 + m0) if n_drift else np.zeros(3)
    return _Linear(x, cov, offset, offset_sigma, g - offset(t))


@dataclass(frozen=True)
class _Rotation:
    """QUEST on the unit rate vectors: q_GS, the largest disagreement of the three solvers, the weights
    sw |w^a|^2 (n,), their total and |w^a|^2 (n,)."""

    q_GS: FloatArray
    disagreement: float
    weight: FloatArray
    total: float
    a_norm2: FloatArray


def _quest_rotation(smp: _Samples, g_corr: FloatArray, q_prior: FloatArray) -> _Rotation:
    """QUEST (000 eq. 9) on the unit vectors, weights sw |w^a|^2, with weak pseudo-pairs pinning
    unobservable rotations to the prior."""
    a_norm2 = np.sum(smp.a_vec * smp.a_vec, axis=1)
    weight = smp.sw * a_norm2
    total = float(weight.sum())
    eye = np.eye(3)
    q_est, disagreement = _solve_wahba(
        np.concatenate([g_corr, rotations.quat_rotate(q_prior, eye)]), np.concatenate([smp.a_vec, eye]),
        np.concatenate([weight, np.full(3, REGULARISATION * total)]),
    )
    return _Rotation(q_est, disagreement, weight, total, a_norm2)


@dataclass(frozen=True)
class _Observability:
    """The estimate with unobservable directions held at the prior: q_GS, misalignment theta (3,), the
    spread matrix eigenvalues (ascending) and axes (columns), and the observable star-tracker axes."""

    q_GS: FloatArray
    theta: FloatArray
    spread_eigenvalues: FloatArray
    spread_axes: FloatArray
    observable_axes: NDArray[np.bool_]


def _observability(
    smp: _Samples, rot: _Rotation, cov_th: FloatArray, q_prior: FloatArray, q_nom: FloatArray, min_spread: float,
    max_sigma_rad: float,
) -> _Observability:
    """Observability of the rotation from the spread of rate directions (module docstring)."""
    a_unit = smp.a_vec / np.linalg.norm(smp.a_vec, axis=1, keepdims=True)
    spread = (rot.total * np.eye(3) - np.einsum("n,ni,nj->ij", rot.weight, a_unit, a_unit)) / rot.total
    lam, axes = np.linalg.eigh(spread)
    sig_dir = np.sqrt(np.maximum(np.einsum("ij,ik,kj->j", axes, cov_th, axes), 0.0))
    unobservable = (lam < min_spread) | (sig_dir > max_sigma_rad)
    q_est = rot.q_GS
    theta = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(q_nom), q_est))
    if np.any(unobservable):
        theta_prior = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(q_nom), q_prior))
        u = axes[:, unobservable]
        theta = theta - u @ (u.T @ theta) + u @ (u.T @ theta_prior)
        q_est = rotations.quat_canonical(rotations.quat_multiply(q_nom, rotations.rotvec_to_quat(theta)))
    observable_axes = ~np.any(np.abs(axes[:, unobservable]) > 0.1, axis=1)
    return _Observability(q_est, theta, lam, axes, observable_axes)
