"""Several star-tracker heads on one body: per-head, per-axis accuracy from their relative attitude.

Method (no motion model). Heads A and B measure q_IA = q_IB q_BA exp(n_A) and q_IB' = q_IB q_BB exp(n_B)
(noise n about the sensor axes, as the simulators and 003 model it). Their relative attitude

    q_AB(t) = q_IA^-1 q_IB' = exp(-n_A) q_BA^-1 q_BB exp(n_B)

does not depend on the spacecraft's motion. About the configured relative mounting q_AB0 = q_BSA^-1 q_BSB,
the rotation vector d = rotvec(q_AB q_AB0^-1), in head A's axes, is to first order

    d(t) = m(t) - n_A + C n_B,      C = dcm(q_AB) (head-B vectors into head A),

with m(t) the mounting error of the pair and its slow (thermal, orbital) variation. Steps:

1. Pairs: every sample of A with a sample of B within ``coincidence_s``; otherwise, when
   ``max_interpolation_s`` > 0, B's attitude interpolated (slerp in the inertial frame) between its
   neighbours at fraction u, which scales B's noise variance by f = (1 - u)^2 + u^2 (and assumes the
   body's angular acceleration times the gap squared is small against the noise).
2. m(t) removed per segment (split at gaps, at most ``segment_max_s``) by the sine series plus trend of
   003 §1.3 with the harmonic count chosen by GCV (processing.signal.sine_series); residuals e_k scaled
   by sqrt(n / (n - M - 2)) so that their outer products are unbiased for white noise.
3. The noise of each head is taken diagonal in its own axes, Sigma_h = diag(s_h1^2, s_h2^2, s_h3^2), and
   independent between heads. Then E[e e^T] = Sigma_A + f C Sigma_B C^T, linear in the 3 H variances:
   6 equations (the distinct elements) per pair of samples. Two heads whose axes are not parallel
   determine all six variances; with three heads the system is over-determined. Solved by generalised
   least squares with the Gaussian covariance of the sample outer products, Var(vech e e^T) =
   2 D^+ (S (x) S) D^+^T, iterated on the estimate; the information matrix gives the covariance of the
   variances and, by its (normalised) eigenvalues, which are determinable (e.g. heads with parallel
   boresights separate only sums: those variances are reported as undeterminable).
4. The model is checked on the data: Ljung-Box statistic of the residuals (whiteness; correlated noise
   makes the white-noise covariance too small: it is inflated by 1 + 2 sum rho_l^2, the variance
   factor of a sample variance of a correlated sequence, and ``correlated`` is set), and the reduced
   chi-square of the outer products against their model.
5. Inter-boresight angle (between the sensor +z axes) per pair: samples, the smoothed variation and
   their statistics, and the angle of the configured mountings.

Inputs: int64 TAI ns times (sorted), scalar-first q_IS (N, 4), configured q_BS (4,). SI (rad) inside.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.attitude import rotations
from processing.estimation.chi2 import chi2_sf
from processing.estimation.consistency import ljung_box, whiteness
from processing.signal.sine_series import SineSeriesSolver
from processing.star_tracker.smoothing import seconds_since, split_segments
from processing.tasks import ResultWarning
from processing.units import NS_PER_S

__all__ = ["HeadPair", "HeadSeries", "MultiHeadAccuracy", "MultiHeadError", "MultiHeadSettings",
           "analyze_heads", "multi_head_warnings"]

_IU = np.triu_indices(3)  # the 6 distinct elements of a symmetric 3x3: (0,0) (0,1) (0,2) (1,1) (1,2) (2,2)
LJUNG_BOX_LAGS = 20
MIN_BLOCKS = 30  # fewer time blocks: the white-noise covariance times the autocorrelation factor instead


class MultiHeadError(ValueError):
    """Inputs that cannot give a multi-head estimate (fewer than two heads, too few common samples)."""


@dataclass(frozen=True)
class HeadSeries:
    """One head: name, times (N,) int64 TAI ns sorted, q_IS (N, 4) scalar first, configured q_BS (4,)."""

    name: str
    time_tai_ns: NDArray[np.int64]
    q_IS: NDArray[np.float64]
    q_BS: NDArray[np.float64]


@dataclass(frozen=True)
class MultiHeadSettings:
    """coincidence_s: samples of two heads this close count as simultaneous; max_interpolation_s: the
    largest gap of a head's samples across which it is interpolated to the other's times (0: only
    simultaneous samples); segment_max_s / max_gap_s: segments of the slow-variation fit;
    min_variation_period_s: the shortest period of the relative attitude's real variation (thermal, orbital)
    that fit follows (caps its harmonics, so that correlated noise is not followed); block_s: time blocks of
    the empirical (sandwich) covariance, which also holds when samples are correlated within a block;
    observability_rtol: a normalised information eigenvalue below this times the largest is a direction
    the data do not determine; min_pairs: fewest sample pairs per head pair;
    identical_heads: every head has the same per-axis noise (3 unknowns instead of 3 per head: what makes
    two heads determine it; the chi-square of the fit tests the assumption)."""

    coincidence_s: float = 0.005
    max_interpolation_s: float = 0.0
    segment_max_s: float = 1200.0
    max_gap_s: float = 30.0
    min_variation_period_s: float = 300.0
    block_s: float = 120.0
    observability_rtol: float = 1e-6
    min_pairs: int = 60
    identical_heads: bool = False

    def __post_init__(self) -> None:
        if not (self.coincidence_s >= 0 and self.max_interpolation_s >= 0 and self.segment_max_s > 0
                and self.max_gap_s > 0 and self.min_variation_period_s > 0 and self.block_s > 0
                and 0 < self.observability_rtol < 1 and self.min_pairs >= 10):
            raise MultiHeadError(f"invalid multi-head settings: {self}")


@dataclass(frozen=True)
class HeadPair:
    """One pair of heads (a, b): sample pairs used (and how many interpolated), the residuals e (M, 3) rad in
    head a's axes at times t (M,) int64, the mounting error of b relative to a (mean rotation vector, rad,
    in a's axes) and the inter-boresight angle: samples (M,), smoothed (M,), configured, rad; Ljung-Box p."""

    a: str
    b: str
    n_pairs: int
    n_interpolated: int
    time_tai_ns: NDArray[np.int64]
    residual_rad: NDArray[np.float64]
    relative_mounting_error_rad: NDArray[np.float64]
    boresight_angle_rad: NDArray[np.float64]
    boresight_angle_smooth_rad: NDArray[np.float64]
    boresight_angle_configured_rad: float
    ljung_box_p: float

    def boresight_stats(self) -> dict[str, float]:
        """Mean, std of the samples, peak-to-peak of the smoothed variation, rad."""
        s = self.boresight_angle_smooth_rad
        theta = self.boresight_angle_rad
        return {"mean_rad": float(np.mean(theta)), "std_rad": float(np.std(theta)),
                "variation_peak_to_peak_rad": float(np.ptp(s)) if s.size else 0.0}


@dataclass(frozen=True)
class MultiHeadAccuracy:
    """Per head (in ``heads`` order): sigma_rad (H, 3) about its x, y, z axes (NaN where undeterminable),
    sigma_sigma_rad (H, 3), observable (H, 3), for undeterminable ones the range sigma_bounds_rad (H, 3, 2)
    that keeps every variance >= 0 (else NaN); the covariance of the variances (3H, 3H) rad^4; the pairs;
    whiteness (``correlated``: some pair's residuals are not white, covariance inflated by
    ``inflation``); reduced chi-square of the outer products and its degrees of freedom."""

    heads: tuple[str, ...]
    sigma_rad: NDArray[np.float64]
    sigma_sigma_rad: NDArray[np.float64]
    observable: NDArray[np.bool_]
    sigma_bounds_rad: NDArray[np.float64]
    variance_covariance: NDArray[np.float64]
    pairs: tuple[HeadPair, ...]
    correlated: bool
    inflation: float
    reduced_chi2: float
    dof: int
    identical_heads: bool


def _slerp_at(t: NDArray, tb: NDArray, qb: NDArray, idx: NDArray) -> tuple[NDArray, NDArray]:
    """q (M, 4) of b interpolated at t between samples idx-1 and idx, and the fraction u (M,)."""
    t0, t1 = tb[idx - 1], tb[idx]
    u = (t - t0).astype(np.float64) / (t1 - t0).astype(np.float64)
    q0 = qb[idx - 1]
    step = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(q0), qb[idx]))
    return rotations.quat_multiply(q0, rotations.rotvec_to_quat(step * u[:, None])), u


def _match(a: HeadSeries, b: HeadSeries, cfg: MultiHeadSettings) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Rows of a that have a partner in b: indices (M,), b's q_IS there (M, 4), B's noise-variance factor f
    (M,) and whether the partner is a real sample (M,) bool."""
    ta, tb = a.time_tai_ns, b.time_tai_ns
    j = np.clip(np.searchsorted(tb, ta), 1, tb.size - 1)
    near = np.where(np.abs(tb[j - 1] - ta) <= np.abs(tb[j] - ta), j - 1, j)
    coincident = np.abs(tb[near] - ta) <= cfg.coincidence_s * NS_PER_S
    inside = (ta > tb[0]) & (ta < tb[-1]) & ((tb[j] - tb[j - 1]) <= cfg.max_interpolation_s * NS_PER_S)
    interp = ~coincident & inside & (cfg.max_interpolation_s > 0)
    rows = np.flatnonzero(coincident | interp)
    q = b.q_IS[near[rows]].copy()
    f = np.ones(rows.size)
    k = np.flatnonzero(interp[rows])
    if k.size:
        q[k], u = _slerp_at(ta[rows[k]], tb, b.q_IS, j[rows[k]])
        f[k] = (1 - u) ** 2 + u**2
    return rows, q, f, coincident[rows]


def _smooth(t_ns: NDArray, d: NDArray, cfg: MultiHeadSettings) -> tuple[NDArray, NDArray]:
    """Residuals of d (M, 3) about its per-segment sine-series fit, scaled to unbiased outer products, and
    the fit itself (M, 3)."""
    e = np.empty_like(d)
    fit = np.empty_like(d)
    for sl in split_segments(t_ns, cfg.segment_max_s, cfg.max_gap_s):
        n = sl.stop - sl.start
        if n < 8:
            e[sl], fit[sl] = np.nan, d[sl]
            continue
        t_s = seconds_since(t_ns[sl], int(t_ns[sl.start]))
        top = min((n - 2) // 4, int(2 * t_s[-1] / cfg.min_variation_period_s))
        solver = SineSeriesSolver(t_s, top)
        m = solver.path(d[sl]).select("gcv")
        f = solver.fit(d[sl], m)
        fit[sl] = f.fitted
        e[sl] = (d[sl] - f.fitted) * np.sqrt(n / (n - m - 2))
    return e, fit


def _ljung_box_p(e: NDArray, coincident: NDArray) -> float:
    """Smallest Ljung-Box p-value over the components of the residuals at real (coincident) samples."""
    x = e[coincident & np.all(np.isfinite(e), axis=1)]
    if x.shape[0] <= 4 * LJUNG_BOX_LAGS:
        return float("nan")
    return float(np.nanmin(ljung_box(x, LJUNG_BOX_LAGS).p))


def _rho_inflation(e: NDArray) -> float:
    """1 + 2 sum_l rho_l^2 (largest over components): the variance factor of a sample variance of a correlated
    sequence, lags up to LJUNG_BOX_LAGS."""
    rho = whiteness(e[np.all(np.isfinite(e), axis=1)], LJUNG_BOX_LAGS).rho
    return float(np.nanmax(1 + 2 * np.sum(rho**2, axis=1)))


@dataclass(frozen=True)
class _PairData:
    """What the variance fit needs of one pair: head indices, residuals e (M, 3) (NaN rows unused), noise-
    variance factors f (M,) of head b, C (3, 3) head b into head a, segment labels (M,)."""

    ia: int
    ib: int
    t: NDArray
    e: NDArray
    f: NDArray
    C: NDArray


def _pair(a: HeadSeries, b: HeadSeries, ia: int, ib: int, cfg: MultiHeadSettings) -> tuple[HeadPair, _PairData]:
    rows, q_b, f, coincident = _match(a, b, cfg)
    if rows.size < cfg.min_pairs:
        raise MultiHeadError(f"heads {a.name} and {b.name} have {rows.size} samples in common (within "
                             f"{cfg.coincidence_s} s, or interpolated across at most {cfg.max_interpolation_s} s); "
                             f"at least {cfg.min_pairs} are needed")
    t = a.time_tai_ns[rows]
    q_ab = rotations.quat_multiply(rotations.quat_conjugate(a.q_IS[rows]), q_b)
    q_ab0 = rotations.quat_multiply(rotations.quat_conjugate(a.q_BS), b.q_BS)
    d = rotations.quat_to_rotvec(rotations.quat_multiply(q_ab, rotations.quat_conjugate(q_ab0)))
    e, _ = _smooth(t, d, cfg)
    C_all = rotations.quat_to_dcm(q_ab)
    theta = np.arctan2(np.hypot(C_all[:, 0, 2], C_all[:, 1, 2]), C_all[:, 2, 2])
    _, theta_fit = _smooth(t, theta[:, None], cfg)
    C0 = rotations.quat_to_dcm(q_ab0)
    pair = HeadPair(a=a.name, b=b.name, n_pairs=int(np.sum(np.all(np.isfinite(e), axis=1))),
                    n_interpolated=int(np.sum(~coincident)), time_tai_ns=t, residual_rad=e,
                    relative_mounting_error_rad=np.mean(d, axis=0), boresight_angle_rad=theta,
                    boresight_angle_smooth_rad=theta_fit[:, 0],
                    boresight_angle_configured_rad=float(np.arctan2(np.hypot(C0[0, 2], C0[1, 2]), C0[2, 2])),
                    ljung_box_p=_ljung_box_p(e, coincident))
    mean_q = rotations.quat_normalize(np.sum(q_ab * np.sign(q_ab @ q_ab[0])[:, None], axis=0))
    ok = np.all(np.isfinite(e), axis=1)
    return pair, _PairData(ia, ib, t[ok], e[ok], f[ok], rotations.quat_to_dcm(mean_q))


_I, _J = _IU
_G_DIAG = (_I[:, None] == np.arange(3)) & (_J[:, None] == np.arange(3))  # (6, 3): element (i, i) <- variance i


def _g_b(C: NDArray) -> NDArray:
    """(6, 3): element (i, j) of C diag(v) C^T per unit variance v_m."""
    return C[_I, :] * C[_J, :]


def _outer_cov(S: NDArray) -> NDArray:
    """Var(vech(e e^T)) (..., 6, 6) for Gaussian e with covariance S (..., 3, 3)."""
    i, j = _I[:, None], _J[:, None]
    k, l_ = _I[None, :], _J[None, :]
    return S[..., i, k] * S[..., j, l_] + S[..., i, l_] * S[..., j, k]


def _normal_equations(data: Sequence[_PairData], x: NDArray | None, n_par: int) -> tuple[NDArray, NDArray, list]:
    """Information A (P, P) and right side b (P,) of the GLS fit of the variances x (None: unit weights),
    with per pair the weights W (M, 6, 6) and the outer products s (M, 6) for the residual check."""
    A = np.zeros((n_par, n_par))
    b = np.zeros(n_par)
    parts = []
    for p in data:
        Ga, Gb = _G_DIAG.astype(float), _g_b(p.C)
        s = p.e[:, _I] * p.e[:, _J]
        if x is None:
            W = np.broadcast_to(np.eye(6), (p.f.size, 6, 6))
        else:
            floor = 1e-6 * max(float(np.max(x)), 1e-30)
            Sa = np.diag(np.maximum(x[3 * p.ia:3 * p.ia + 3], floor))
            Sb = p.C @ np.diag(np.maximum(x[3 * p.ib:3 * p.ib + 3], floor)) @ p.C.T
            W = np.linalg.inv(_outer_cov(Sa + p.f[:, None, None] * Sb))
        sa, sb = slice(3 * p.ia, 3 * p.ia + 3), slice(3 * p.ib, 3 * p.ib + 3)
        w0, w1, w2 = W.sum(axis=0), np.einsum("k,kij->ij", p.f, W), np.einsum("k,kij->ij", p.f**2, W)
        A[sa, sa] += Ga.T @ w0 @ Ga
        A[sa, sb] += Ga.T @ w1 @ Gb
        A[sb, sa] += Gb.T @ w1.T @ Ga
        A[sb, sb] += Gb.T @ w2 @ Gb
        Ws = np.einsum("kij,kj->ki", W, s)
        b[sa] += Ga.T @ Ws.sum(axis=0)
        b[sb] += Gb.T @ (p.f @ Ws)
        parts.append((Ga, Gb, W, s))
    return A, b, parts


def _determinable(A: NDArray, rtol: float) -> tuple[NDArray, NDArray, NDArray]:
    """(pseudo-inverse of A on its determinable subspace, determinable mask per parameter, the null-space
    directions (P, k)). A parameter is determinable when it has no component along a null direction."""
    d = np.sqrt(np.maximum(np.diag(A), 1e-300))
    lam, V = np.linalg.eigh(A / np.outer(d, d))
    keep = lam > rtol * lam[-1]
    inv = (V[:, keep] / lam[keep]) @ V[:, keep].T / np.outer(d, d)
    null = V[:, ~keep] / d[:, None]
    null = null / np.linalg.norm(null, axis=0)
    return inv, np.sum(null**2, axis=1) < 1e-6, null


def _positivity_bounds(x: NDArray, null: NDArray) -> NDArray:
    """(P, 2) range of each variance over x + c n (one null direction n) with every variance >= 0: what the
    data still say of variances they do not determine (two heads: a shared isotropic part moves freely
    from one head to the other). NaN without exactly one null direction or when no c keeps all >= 0."""
    out = np.full((x.size, 2), np.nan)
    if null.shape[1] != 1:
        return out
    n = null[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        c = -x / n
    lo = np.max(np.where(n > 0, c, -np.inf))
    hi = np.min(np.where(n < 0, c, np.inf))
    if np.isfinite(lo) and np.isfinite(hi) and lo <= hi:
        ends = x[:, None] + n[:, None] * np.array([lo, hi])[None, :]
        out = np.sort(np.maximum(ends, 0.0), axis=1)
    return out


def _residual_check(data: Sequence[_PairData], parts: list, x: NDArray, block_s: float) -> tuple[float, NDArray]:
    """chi-square of the outer products against their model, and the score sums M^T W r per time block of
    block_s (B, P) for the sandwich covariance."""
    chi2 = 0.0
    t0 = min(int(p.t[0]) for p in data)
    blocks: dict[int, NDArray] = {}
    step = max(int(block_s * NS_PER_S), 1)
    for p, (Ga, Gb, W, s) in zip(data, parts, strict=True):
        r = s - (Ga @ x[3 * p.ia:3 * p.ia + 3])[None, :] - p.f[:, None] * (Gb @ x[3 * p.ib:3 * p.ib + 3])[None, :]
        Wr = np.einsum("kij,kj->ki", W, r)
        chi2 += float(np.sum(r * Wr))
        g = np.zeros((r.shape[0], x.size))
        g[:, 3 * p.ia:3 * p.ia + 3] += Wr @ Ga
        g[:, 3 * p.ib:3 * p.ib + 3] += p.f[:, None] * (Wr @ Gb)
        label = (p.t - t0) // step
        uniq, inv = np.unique(label, return_inverse=True)
        sums = np.zeros((uniq.size, x.size))
        np.add.at(sums, inv, g)
        for u, row in zip(uniq.tolist(), sums, strict=True):
            blocks[u] = blocks.get(u, 0.0) + row
    return chi2, np.array(list(blocks.values())).reshape(-1, x.size)


def analyze_heads(heads: Sequence[HeadSeries], settings: MultiHeadSettings | None = None) -> MultiHeadAccuracy:
    """Per-head, per-axis accuracy of two or more star-tracker heads from their relative attitude (module
    docstring). Every pair of heads is used; raises :class:`MultiHeadError`."""
    cfg = settings or MultiHeadSettings()
    if len(heads) < 2:
        raise MultiHeadError(f"the multi-head method needs at least two heads, got {len(heads)}")
    hs = [HeadSeries(h.name, np.asarray(h.time_tai_ns, dtype=np.int64),
                     rotations.quat_canonical(rotations.quat_normalize(np.asarray(h.q_IS, dtype=float))),
                     rotations.quat_normalize(np.asarray(h.q_BS, dtype=float))) for h in heads]
    for h in hs:
        if h.time_tai_ns.size < cfg.min_pairs or np.any(np.diff(h.time_tai_ns) <= 0):
            raise MultiHeadError(f"head {h.name}: times must be strictly increasing, at least {cfg.min_pairs} samples")
    blk = [0 if cfg.identical_heads else i for i in range(len(hs))]
    pairs, data = zip(*[_pair(hs[i], hs[j], blk[i], blk[j], cfg) for i in range(len(hs))
                        for j in range(i + 1, len(hs))], strict=True)
    n_par = 3 * (max(blk) + 1)
    A, b, _ = _normal_equations(data, None, n_par)
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    for _ in range(3):
        A, b, parts = _normal_equations(data, x, n_par)
        inv, det, null = _determinable(A, cfg.observability_rtol)
        x = inv @ b
    chi2, instants = _residual_check(data, parts, x, max(1.0, 2 * cfg.max_interpolation_s))
    _, scores = _residual_check(data, parts, x, cfg.block_s)
    dof = int(sum(6 * p.f.size for p in data) - np.sum(det))
    reduced = chi2 / max(dof, 1)
    inflation = max(_rho_inflation(p.e) for p in data)
    p_min = min((pr.ljung_box_p for pr in pairs if np.isfinite(pr.ljung_box_p)), default=float("nan"))
    correlated = bool(np.isfinite(p_min) and p_min < 0.01 / (3 * len(pairs)))
    # the pairs of three or more heads share each head's noise (a sandwich over instants holds for that),
    # correlated noise is not white (a sandwich over longer blocks, or the autocorrelation factor when
    # there are too few blocks); never less than the white-noise figure
    cov_model = inv * max(1.0, reduced)
    cov = inv @ (instants.T @ instants) @ inv
    cov_corr = inv @ (scores.T @ scores) @ inv if scores.shape[0] >= MIN_BLOCKS else cov * inflation
    top = np.maximum(np.maximum(np.diag(cov_model), np.diag(cov)), np.diag(cov_corr))
    scale = np.sqrt(top / np.maximum(np.diag(cov), 1e-300))
    cov = cov * np.outer(scale, scale)
    rows = np.array(blk)
    var = x.reshape(-1, 3)[rows]
    sd = np.sqrt(np.maximum(np.diag(cov), 0)).reshape(-1, 3)[rows]
    ok = det.reshape(-1, 3)[rows]
    with np.errstate(divide="ignore", invalid="ignore"):
        sig_sig = np.where(var > 2 * sd, sd / (2 * np.sqrt(var)), np.sqrt(sd))
    bounds = np.sqrt(_positivity_bounds(x, null)).reshape(-1, 3, 2)[rows]
    sigma = np.where(ok, np.sqrt(np.maximum(var, 0)), np.nan)
    return MultiHeadAccuracy(heads=tuple(h.name for h in hs), sigma_rad=sigma,
                             sigma_sigma_rad=np.where(ok, sig_sig, np.nan), observable=ok,
                             sigma_bounds_rad=np.where(ok[..., None], np.nan, bounds),
                             variance_covariance=cov, pairs=tuple(pairs), correlated=correlated,
                             inflation=inflation, reduced_chi2=reduced, dof=dof,
                             identical_heads=cfg.identical_heads)


MOUNTING_PLAUSIBLE_RAD = 0.5 * np.pi / 180
"""A relative mounting further than this from the configured one is reported as implausible input."""
MODEL_P_MIN = 1e-3
"""The outer products' chi-square below this p-value rejects the noise model (diagonal, independent heads)."""


def multi_head_warnings(res: MultiHeadAccuracy) -> list[ResultWarning]:
    """What the data say about the multi-head estimate's assumptions (ResultWarning codes)."""
    out: list[ResultWarning] = []
    if res.correlated:
        worst = min((p for p in res.pairs if np.isfinite(p.ljung_box_p)), key=lambda p: p.ljung_box_p)
        out.append(ResultWarning(
            "correlated_residuals",
            f"the relative attitude of {worst.a} and {worst.b} has correlated residuals (Ljung-Box p = "
            f"{worst.ljung_box_p:.2g} over {LJUNG_BOX_LAGS} lags): the per-head sigmas are lower bounds (the "
            "slow-variation fit absorbs part of correlated noise) and their uncertainty is inflated x"
            f"{np.sqrt(res.inflation):.2f}", {"ljung_box_p": worst.ljung_box_p, "lags": LJUNG_BOX_LAGS,
                                              "variance_inflation": res.inflation}))
    p_model = float(chi2_sf(res.reduced_chi2 * res.dof, res.dof)) if res.dof > 0 else float("nan")
    if np.isfinite(p_model) and p_model < MODEL_P_MIN:
        what = "identical heads" if res.identical_heads else "independent heads"
        out.append(ResultWarning(
            "implausible_input",
            f"the inter-head residuals do not fit the noise model ({what}, noise diagonal in each head's axes): "
            f"reduced chi-square {res.reduced_chi2:.3f} over {res.dof} degrees of freedom (p = {p_model:.2g})"
            + (": the heads differ; use three heads or per-head noise" if res.identical_heads else ""),
            {"reduced_chi2": res.reduced_chi2, "dof": res.dof, "p": p_model}))
    for p in res.pairs:
        err = float(np.linalg.norm(p.relative_mounting_error_rad))
        if err > MOUNTING_PLAUSIBLE_RAD:
            out.append(ResultWarning(
                "implausible_input",
                f"{p.b} is {np.degrees(err):.2f} deg from its configured mounting relative to {p.a}: a mounting "
                "(q_BS) or quaternion-convention error in the data or the configuration",
                {"pair": [p.a, p.b], "relative_mounting_error_deg": float(np.degrees(err))}))
    if not np.all(res.observable):
        bad = [f"{h} {'xyz'[i]}" for h, row in zip(res.heads, res.observable, strict=True)
               for i, ok in enumerate(row) if not ok]
        hint = ("two heads separate only what is not common to both (a shared isotropic part moves freely "
                "between them): add a third head, or assume identical heads (identical_heads)"
                if len(res.heads) == 2 and not res.identical_heads else
                "the heads' axes are (nearly) parallel: only sums of their variances are determined")
        out.append(ResultWarning("not_observable", f"not determined: {', '.join(bad)}; {hint}; the summary gives "
                                 "the range that keeps every variance >= 0 where there is one",
                                 {"undetermined": bad}))
    return out
