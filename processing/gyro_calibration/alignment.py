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
- observability (issue 17): the normal (information) matrix of the linear step over the full parameter set
  (scale factor: scalar or per gyro axis; misalignment 3; drift 3 and its higher terms) decides what the
  rate history determines (processing.gyro_calibration.observability: unit-diagonal eigenvalues below
  ``rank_tolerance`` are null directions; a parameter with a component above 0.1 in them is
  undeterminable). The linear step is solved on the determinable subspace; the rotation directions in
  the null space, or with a rate-direction spread below ``min_spread`` (the spread matrix F = sum
  alpha_i (I - a_i a_i^T) / sum alpha_i, trace 2, eigenvalues 0, 1, 1 for rates about one axis), are
  held at the prior (the nominal mounting at first); an axis is observable when the information matrix
  determines it, no held direction has a component above 0.1 along it and its sigma is at most
  ``max_sigma_rad``. A constant rate vector (nadir pointing) determines none of them.
- uncertainty: samples of one window are one polynomial, so they are strongly correlated; the
  covariance is that of the linear step on the determinable subspace, N+ M N+ with M from the white
  star-tracker noise through the window polynomials (:class:`RateNoise`, WindowRates.rate_noise_gain),
  scaled by the residual variance factor (observed / expected weighted squared rate residuals, which
  also carry the gyro spline's error) when above 1, and by the delete-one-window jackknife's variance
  ratio when that is significantly above 1 (chi-square, W - 1 degrees of freedom, 0.1 %); without a
  noise model the jackknife itself. The jackknife is zero along undetermined directions, so it is never
  the sigma of an undetermined parameter (they have none).

Layout: the windows and the star-tracker rates of steps (ii)-(iii) (alignment_windows, WindowRates,
star_tracker_window_rates, AlignmentError) are in processing.gyro_calibration.window_rates; this module
holds the estimate.

Times s, rates rad/s, angles rad, quaternions (..., 4) scalar first.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations, wahba
from processing.estimation.chi2 import chi2_isf
from processing.gyro_calibration.drift_observer import DriftTrend
from processing.gyro_calibration.observability import (
    RANK_TOLERANCE,
    Observability,
    analyse_information,
    noise_floor,
    noise_meat,
    parameter_jacobian,
    subspace_covariance,
    truncated_inverse,
)
from processing.gyro_calibration.window_rates import AlignmentError

__all__ = [
    "AlignmentEstimate",
    "RateNoise",
    "estimate_alignment",
]

FloatArray = NDArray[np.float64]

REGULARISATION = 1e-7
"""Weight (relative to the total) of three pseudo vector pairs that pin unobservable rotations to the prior.
It also separates the two largest eigenvalues of Wahba's K when all rates are about one axis (the rotation
about it undetermined): with 1e-9 QUEST's eigenvector lost ~1e-5 rad along the determined directions on such
arcs; its pull on the determined rotation is this weight times the offset from the prior (~1e-11 rad)."""


@dataclass(frozen=True)
class RateNoise:
    """The white star-tracker noise model of the window rates: gain (n, width) of each sample
    (WindowRates.rate_noise_gain at the samples given to :func:`estimate_alignment`) and the angle
    noise sigma_rad (3,) per star-tracker axis (e.g. from the window fit residuals)."""

    gain: FloatArray
    sigma_rad: FloatArray


@dataclass(frozen=True)
class AlignmentEstimate:
    """Result of one alignment and scale-factor estimate (000, eq. 9 and the m_i mean).

    q_GS (4,): estimated S^Delta = R(q_GS) (canonical); misalignment_rad (3,): rotation vector of
    q_GS_nominal^-1 o q_GS in star-tracker axes (= rotvec(q_GS) when the nominal is the identity);
    scale_factor_error: m^; misalignment_cov_rad2 (3, 3), scale_factor_sigma (NaN when undeterminable):
    from the covariance on the determinable subspace (processing.gyro_calibration.observability; zero
    along the null directions, so only the determinable components' entries are sigmas);
    drift_offset: the residual drift polynomial removed (gyro frame, a DriftTrend);
    drift_offset_sigma_rad_s (3,): sigma of its constant term (gyro axes);
    spread_eigenvalues (3,) ascending and spread_axes (3, 3) columns: the rate-direction spread matrix;
    observable_axes (3,) bool per star-tracker axis (misalignment determinable and its sigma below the
    limit); scale_factor_observable, drift_observable (3,): determinable by the information matrix;
    observability: the analysis itself; solver_disagreement_rad: largest angle between QUEST, q-method
    and SVD; n_windows, n_samples; residual_rad_s (n, 3): w^g_S - w^a after the estimate (star-tracker
    axes); linearised (p,): the parameters of the linear step (observability.names; the minimum-norm
    subspace solution); covariance (p, p) of the linear step on the determinable subspace; jackknife_cov
    (p, p): the delete-one-window jackknife of the same (a cross-check that inflates the covariance when
    significantly larger; zero along undetermined directions, so never the sigma by itself);
    residual_variance_factor: observed over expected weighted squared rate residuals (the covariance is
    scaled by it when above 1); scale_factor_per_axis (3,) and its sigma: m per gyro axis from the
    linear step when estimated (per_axis_scale_factor), else NaN; rate_offset_sigma_rad_s (3,): the
    sigma of a constant rate offset estimated alone from these windows (their noise; NaN without a noise
    model): the misalignment sigma that a rms rate w perpendicular to an axis would give is about
    rate_offset_sigma / w, the scale-factor sigma for a spread (std) s of |w| about rate_offset_sigma / s.
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
    observability: Observability
    scale_factor_observable: NDArray[np.bool_]
    drift_observable: NDArray[np.bool_]
    covariance: FloatArray
    jackknife_cov: FloatArray
    residual_variance_factor: float
    scale_factor_per_axis: FloatArray
    scale_factor_per_axis_sigma: FloatArray
    rate_offset_sigma_rad_s: FloatArray = field(default_factory=lambda: np.full(3, np.nan))

    @property
    def misalignment_sigma_rad(self) -> FloatArray:
        """Per-axis 1-sigma of the misalignment (rad), NaN on unobservable axes."""
        s = np.sqrt(np.diag(self.misalignment_cov_rad2))
        return np.where(self.observable_axes, s, np.nan)

    @property
    def complete(self) -> bool:
        """Every misalignment axis, the scale factor and every drift component determined."""
        return bool(np.all(self.observable_axes) and np.all(self.scale_factor_observable)
                    and np.all(self.drift_observable))


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
    noise: RateNoise | None = None,
    per_axis_scale_factor: bool = False,
    rank_tolerance: float = RANK_TOLERANCE,
) -> AlignmentEstimate:
    """Misalignment (QUEST, 000 eq. 9) and scale-factor error from gyro vs star-tracker rates.

    t_s (n,) [s] sample times; w_G_rad_s (n, 3): gyro rates in G with the drift model already
    subtracted; w_A_rad_s (n, 3): the star-tracker rates at the same times (frame A = S); window (n,)
    window index of each sample; sample_weight (n,): inverse variance of the star-tracker rate error of
    each sample (WindowRates.rate_variance_s2 ** -1; default equal). drift_degree: degree of the jointly
    estimated residual drift polynomial (None: none).
    q_GS_prior, scale_factor_prior: current calibration (linearisation point of the drift-offset step,
    and the value kept along unobservable directions); q_GS_nominal: the configured mounting.
    min_spread, max_sigma_rad: a misalignment axis is also unobservable when the rate directions' spread
    about it is below min_spread or its sigma above max_sigma_rad. noise: the star-tracker noise model of
    the rates (:class:`RateNoise`), which gives the covariance; without it the samples are taken as
    independent with variances proportional to 1 / sample_weight, scaled by the residual variance.
    per_axis_scale_factor: the linear step estimates m per gyro axis (reported beside the scalar m of
    the magnitude ratios). rank_tolerance: processing.gyro_calibration.observability. Returns
    :class:`AlignmentEstimate`.
    """
    smp = _alignment_samples(t_s, w_G_rad_s, w_A_rad_s, window, sample_weight, noise)
    q_prior = rotations.quat_canonical(rotations.quat_normalize(np.asarray(q_GS_prior, dtype=np.float64)))
    q_nom = rotations.quat_canonical(rotations.quat_normalize(np.asarray(q_GS_nominal, dtype=np.float64)))
    m0 = float(scale_factor_prior)
    lin = _linear_step(smp, q_prior, m0, drift_degree, per_axis_scale_factor, rank_tolerance)
    rot = _quest_rotation(smp, lin.g_corr, q_prior)
    n_m = 3 if per_axis_scale_factor else 1
    obs = _observability(smp, rot, lin, n_m, q_prior, q_nom, min_spread, max_sigma_rad)
    # Scale factor: weighted mean of |w^g| / |w^a| - 1 with weights sw |w^a|^2 (000: mean of the m_i).
    g_norm = np.linalg.norm(lin.g_corr, axis=1)
    m_est = float(np.sum(smp.sw * np.sqrt(rot.a_norm2) * g_norm) / rot.total) - 1.0
    residual = rotations.quat_rotate(rotations.quat_conjugate(obs.q_GS), lin.g_corr) / (1.0 + m_est) - smp.a_vec
    sf_det = lin.observability.determinable[:n_m]
    var_m = np.diag(lin.cov)[:n_m]
    if per_axis_scale_factor:
        # the weighted mean of the per-axis factors is what the magnitude ratio estimates
        sf_sigma = float(np.sqrt(_per_axis_mean_variance(lin.cov[:3, :3], smp, q_prior))) if np.all(sf_det) else np.nan
        # the residual divides by the scalar prior: dm_k = (m_k - m0) / (1 + m0)
        per_axis = np.where(sf_det, m0 + (1.0 + m0) * lin.x[:3], np.nan)
        per_axis_sigma = np.where(sf_det, (1.0 + m0) * np.sqrt(var_m), np.nan)
    else:
        sf_sigma = float(np.sqrt(var_m[0])) if sf_det[0] else np.nan
        per_axis = per_axis_sigma = np.full(3, np.nan)
    return AlignmentEstimate(
        q_GS=obs.q_GS, misalignment_rad=obs.theta, scale_factor_error=m_est,
        misalignment_cov_rad2=lin.cov[n_m : n_m + 3, n_m : n_m + 3], scale_factor_sigma=sf_sigma,
        drift_offset=lin.offset, drift_offset_sigma_rad_s=lin.offset_sigma, spread_eigenvalues=obs.spread_eigenvalues,
        spread_axes=obs.spread_axes, observable_axes=obs.observable_axes, solver_disagreement_rad=rot.disagreement,
        n_windows=smp.n_windows, n_samples=int(smp.g.shape[0]), residual_rad_s=residual, linearised=lin.x,
        observability=lin.observability, scale_factor_observable=np.array([bool(np.all(sf_det))]),
        drift_observable=lin.observability.flags("drift_") if drift_degree is not None else np.zeros(3, dtype=bool),
        covariance=lin.cov, jackknife_cov=lin.jackknife_cov, residual_variance_factor=lin.variance_factor,
        scale_factor_per_axis=per_axis, scale_factor_per_axis_sigma=per_axis_sigma,
        rate_offset_sigma_rad_s=_rate_offset_sigma(smp, lin.variance_factor),
    )


def _rate_offset_sigma(smp: _Samples, factor: float) -> FloatArray:
    """Sigma (3,) of a constant rate offset estimated alone (weighted mean) from the windows' noise."""
    if smp.noise is None:
        return np.full(3, np.nan)
    eye = np.broadcast_to(np.eye(3), (smp.t.size, 3, 3))
    meat = noise_meat(eye, smp.sw, smp.noise.gain, smp.wid, smp.noise.sigma_rad)
    scale = max(1.0, factor) if np.isfinite(factor) else 1.0
    return np.sqrt(scale * np.diag(meat)) / float(np.sum(smp.sw))


def _per_axis_mean_variance(cov_m: FloatArray, smp: _Samples, q_prior: FloatArray) -> float:
    """Variance of the weighted mean sum_k c_k m_k that the magnitude ratio estimates, c_k ~ sw (R a)_k^2."""
    a_G = rotations.quat_rotate(q_prior, smp.a_vec)
    c = np.sum(smp.sw[:, None] * a_G**2, axis=0)
    c = c / c.sum()
    return float(c @ cov_m @ c)


@dataclass(frozen=True)
class _Samples:
    """The finite samples: times t (n,), gyro rates g and star-tracker rates a_vec (n, 3), window ids
    renumbered 0..W-1, weights sw (n,) scaled to a largest of 1, the number of windows W and the
    noise model (gain (n, width), sigma (3,)) if given."""

    t: FloatArray
    g: FloatArray
    a_vec: FloatArray
    wid: NDArray[np.intp]
    sw: FloatArray
    n_windows: int
    noise: RateNoise | None


def _alignment_samples(
    t_s: ArrayLike, w_G_rad_s: ArrayLike, w_A_rad_s: ArrayLike, window: ArrayLike, sample_weight: ArrayLike | None,
    noise: RateNoise | None,
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
    if noise is not None and (noise.gain.ndim != 2 or noise.gain.shape[0] != t.size or noise.sigma_rad.shape != (3,)):
        raise AlignmentError(f"noise.gain must be (n, width) with n = {t.size} and sigma_rad (3,), got "
                             f"{noise.gain.shape} and {noise.sigma_rad.shape}")
    good = np.all(np.isfinite(g), axis=1) & np.all(np.isfinite(a_vec), axis=1) & np.isfinite(t) & np.isfinite(sw)
    t, g, a_vec, wid, sw = t[good], g[good], a_vec[good], wid[good], sw[good] / np.max(sw[good])
    if noise is not None:
        noise = RateNoise(np.asarray(noise.gain, dtype=np.float64)[good], np.asarray(noise.sigma_rad, dtype=np.float64))
    _, wid = np.unique(wid, return_inverse=True)
    n_win = int(wid.max()) + 1 if wid.size else 0
    if n_win < 3:
        raise AlignmentError(f"need at least 3 alignment windows with valid rates, got {n_win}")
    return _Samples(t, g, a_vec, wid, sw, n_win, noise)


@dataclass(frozen=True)
class _Linear:
    """The linear step: x = (dm, dtheta, drift coefficients in S; 0 for the undeterminable), the
    information analysis, the covariance of the determinable parameters, the jackknife covariance, the
    residual variance factor, the residual drift polynomial in G and the sigma of its constant term, and
    the gyro rates with it removed."""

    x: FloatArray
    observability: Observability
    cov: FloatArray
    jackknife_cov: FloatArray
    variance_factor: float
    offset: DriftTrend
    offset_sigma: FloatArray
    g_corr: FloatArray


def _linear_step(smp: _Samples, q_prior: FloatArray, m0: float, drift_degree: int | None, per_axis: bool,
                 rank_tolerance: float) -> _Linear:
    """Residual drift polynomial and the linearised dm, dtheta on the determinable parameters (the others
    held at the prior), their covariance (observability module) and the delete-one-window jackknife."""
    t, g, a_vec, n_win = smp.t, smp.g, smp.a_vec, smp.n_windows
    q_SG = rotations.quat_conjugate(q_prior)
    t_ref = 0.5 * float(t.min() + t.max())
    scale = max(0.5 * float(t.max() - t.min()), 1.0)
    x_t = (t - t_ref) / scale
    r = rotations.quat_rotate(q_SG, g) / (1.0 + m0) - a_vec
    jac, names = parameter_jacobian(a_vec, x_t, q_prior, drift_degree=drift_degree, per_axis_scale_factor=per_axis)
    p = jac.shape[2]
    jw = jac * smp.sw[:, None, None]
    n_tot = jw.reshape(-1, p).T @ jac.reshape(-1, p)
    v_tot = jw.reshape(-1, p).T @ r.reshape(-1)
    floor = None
    if smp.noise is not None:  # what the rate noise alone puts on the diagonal (observability, step 0)
        floor = noise_floor(names, smp.sw * np.sum(smp.noise.gain**2, axis=1), smp.noise.sigma_rad, q_prior)
    info = analyse_information(n_tot, names, rank_tolerance=rank_tolerance, noise_floor=floor)
    det = info.determinable
    n_plus = truncated_inverse(n_tot, rank_tolerance)
    x = n_plus @ v_tot
    post = r - np.einsum("nkp,p->nk", jac, x)
    n_det = int(np.sum(det))
    jk = _jackknife(jac, r, smp, n_tot, v_tot, n_win, rank_tolerance)
    if smp.noise is not None:
        meat = noise_meat(jac, smp.sw, smp.noise.gain, smp.wid, smp.noise.sigma_rad)
        expected = float(np.sum(smp.sw[:, None] * np.sum(smp.noise.gain**2, axis=1)[:, None] * smp.noise.sigma_rad**2))
        expected -= float(np.trace(n_plus @ meat))
        observed = float(np.sum(smp.sw[:, None] * post**2))
        factor = observed / expected if expected > 0 else float("nan")
        model = subspace_covariance(n_tot, meat, rank_tolerance)
        # cross-check: the jackknife over W windows (~W - 1 degrees of freedom) far above the model means
        # an error the white-noise model does not have (e.g. correlated star-tracker noise): inflate by it
        ratio = float(np.nanmax(np.diag(jk)[det] / np.diag(model)[det])) if n_det else 1.0
        jk_limit = float(chi2_isf(0.001 / max(n_det, 1), n_win - 1)) / (n_win - 1)
        inflation = max(1.0, factor if np.isfinite(factor) else 1.0, ratio if ratio > jk_limit else 1.0)
        cov = model * inflation
    else:  # no noise model: the jackknife (valid whatever the correlation inside a window)
        factor = float("nan")
        cov = jk
    n_drift = 0 if drift_degree is None else drift_degree + 1
    n_m = 3 if per_axis else 1
    coef_S = x[n_m + 3 :].reshape(n_drift, 3) if n_drift else np.zeros((1, 3))
    coef_G = (1.0 + m0) * rotations.quat_rotate(q_prior, coef_S)
    offset = DriftTrend(coefficients=coef_G, t_ref_s=t_ref, scale_s=scale, span_s=(float(t.min()), float(t.max())))
    if n_drift:
        dcm = rotations.quat_to_dcm(q_prior)
        cov_b = cov[n_m + 3 : n_m + 6, n_m + 3 : n_m + 6]
        offset_sigma = (1.0 + m0) * np.sqrt(np.diag(dcm @ cov_b @ dcm.T))
    else:
        offset_sigma = np.zeros(3)
    return _Linear(x, info, cov, jk, factor, offset, offset_sigma, g - offset(t))


def _jackknife(jac: FloatArray, r: FloatArray, smp: _Samples, n_tot: FloatArray, v_tot: FloatArray, n_win: int,
               rank_tolerance: float) -> FloatArray:
    """Delete-one-window jackknife covariance (p, p) of the subspace estimate (zero along null directions)."""
    jw = jac * smp.sw[:, None, None]
    nn = np.matmul(np.swapaxes(jw, 1, 2), jac)
    vv = np.matmul(np.swapaxes(jw, 1, 2), r[:, :, None])[:, :, 0]
    order = np.argsort(smp.wid, kind="stable")
    first = np.flatnonzero(np.diff(smp.wid[order], prepend=-1))  # window ids are 0..W-1, all present
    big_n, big_v = np.add.reduceat(nn[order], first, axis=0), np.add.reduceat(vv[order], first, axis=0)
    loo = (truncated_inverse(n_tot[None] - big_n, rank_tolerance) @ (v_tot[None] - big_v)[..., None])[..., 0]
    dev = loo - loo.mean(axis=0)
    return (n_win - 1) / n_win * dev.T @ dev


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
    smp: _Samples, rot: _Rotation, lin: _Linear, n_m: int, q_prior: FloatArray, q_nom: FloatArray,
    min_spread: float, max_sigma_rad: float,
) -> _Observability:
    """Misalignment directions held at the prior and the observable axes (module docstring): the
    rotation directions in the null space of the information matrix or with a rate-direction spread
    below min_spread are pinned; an axis is observable when the information matrix determines it, no
    pinned direction has a component above 0.1 along it and its sigma is at most max_sigma_rad."""
    a_unit = smp.a_vec / np.linalg.norm(smp.a_vec, axis=1, keepdims=True)
    spread = (rot.total * np.eye(3) - np.einsum("n,ni,nj->ij", rot.weight, a_unit, a_unit)) / rot.total
    lam, axes = np.linalg.eigh(spread)
    info = lin.observability
    pinned_dirs = np.concatenate([axes[:, lam < min_spread], info.null_directions(slice(n_m, n_m + 3))], axis=1)
    q_est = rot.q_GS
    theta = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(q_nom), q_est))
    pinned = np.zeros((3, 0))
    if pinned_dirs.shape[1]:
        u, s, _ = np.linalg.svd(pinned_dirs, full_matrices=False)
        pinned = u[:, s > 0.3]  # unit vectors: a second direction only if it really differs from the first
        theta_prior = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(q_nom), q_prior))
        theta = theta - pinned @ (pinned.T @ theta) + pinned @ (pinned.T @ theta_prior)
        q_est = rotations.quat_canonical(rotations.quat_multiply(q_nom, rotations.rotvec_to_quat(theta)))
    sigma = np.sqrt(np.diag(lin.cov[n_m : n_m + 3, n_m : n_m + 3]))
    observable_axes = (info.determinable[n_m : n_m + 3] & ~np.any(np.abs(pinned) > 0.1, axis=1)
                       & (np.nan_to_num(sigma, nan=np.inf) <= max_sigma_rad))
    return _Observability(q_est, theta, lam, axes, observable_axes)
