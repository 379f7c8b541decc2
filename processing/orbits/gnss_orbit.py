"""GNSS orbit states: smoothing and interpolation of ITRF position/velocity, ascending nodes (003 §1.6).

003 §1.6 approximates the GNSS coordinates and velocity components (Greenwich frame, 0.1 s) over
the whole interval of interest (under 20 min) by discrete Fourier series and reports rms errors of
the approximation below 1 m and 1 mm/s; the fit then gives the orbital frame at any time.

Two smoothers are offered, per arc (a run of samples without gaps, cut into pieces of at most
``arc_max_s``):

``"chebyshev"`` (default) -- a joint weighted least-squares fit of position AND velocity by one
    Chebyshev polynomial series per axis, r(t) = sum_k c_k T_k(x), v(t) = dr/dt = sum_k c_k T_k'(x)
    / h (x = (t - t_mid)/h in [-1, 1]), rows weighted by 1/sigma_r and 1/sigma_v (the noise levels
    estimated from the residuals, two passes). Why not the sine series here: an orbit arc of 20 min
    turns the position vector by ~70 deg; after the linear trend of 003 §1.3 is removed, the odd
    periodic extension of the remainder has a kink at both ends, so its sine coefficients decay only
    as m^-3 and ~200 harmonics are needed to follow a 7000 km curve to 1 m -- the fit then passes on
    half the noise (measured on the seed-003 simulator: 0.47 m, 0.49 mm/s with 1 m, 1 mm/s noise)
    and its derivative is useless near the ends (0.25 m/s). An orbit arc is an entire function of
    time: its Chebyshev coefficients decay geometrically, degree ~10 represents 20 min of LEO arc to
    ~1 cm, and the few parameters average the noise down (measured: 1-4 cm and 0.05-0.1 mm/s), with
    r and v consistent by construction (v_E is the time derivative of r_E in the rotating frame).
    The degree is chosen by generalised cross-validation (Craven & Wahba 1979) over 3..DEGREE_MAX.
``"sine"`` -- the 003 §1.3 series (processing.signal.sine_series) fitted to position and to velocity
    separately, harmonic count by GCV, as the paper does; kept for comparison with 003.

Both report residual rms per axis (the 003 figures "< 1 m, < 1 mm/s") and the velocity/position
consistency. States are ITRF (m, m/s, velocity relative to the rotating Earth); times int64 tai_ns.
Ascending nodes are found in the inertial frame (GCRS) where z changes sign upwards; the time since
the preceding node (the "virtual orbit" of 003 §1.6, fig. 12) comes from those nodes or, before the
first one in the data, from the osculating two-body elements (error ~1e-3 of the time since node,
from J2).

The noise level and time-tag consistency of the raw states and the check of a fit against the receiver
noise (divided_difference_noise, time_tag_check, check_gnss_fit) are in processing.orbits.gnss_checks.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.polynomial import chebyshev as cheb
from numpy.typing import ArrayLike, NDArray

from processing.frames.earth_orientation import EarthOrientation, itrs_to_gcrs_state
from processing.signal.sine_series import SineSeriesFit, fit_sine_series, select_harmonics
from processing.units import MU_EARTH_M3_S2, NS_PER_S

DEGREE_MIN = 3
DEGREE_MAX = 30
"""Largest Chebyshev degree tried (20 min of LEO arc needs ~10; a 95 min orbit ~25)."""
ARC_MAX_S = 1200.0
"""Default longest arc fitted by one series (003 §1.6: intervals of at most 20 min)."""
SINE_MAX_HARMONICS = 400
SIGMA_FLOOR_M = 1e-4
SIGMA_FLOOR_M_S = 1e-7

Method = Literal["chebyshev", "sine"]
EopSource = EarthOrientation | Callable[[NDArray[np.int64]], EarthOrientation] | None


class GnssFitError(ValueError):
    """GNSS samples that cannot be smoothed: shapes, too few samples, non-finite values."""


def _as_states(time_tai_ns: ArrayLike, r_E: ArrayLike, v_E: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
    t = np.asarray(time_tai_ns, dtype=np.int64)
    r = np.asarray(r_E, dtype=np.float64)
    v = np.asarray(v_E, dtype=np.float64)
    if t.ndim != 1 or r.shape != (t.size, 3) or v.shape != (t.size, 3):
        raise GnssFitError(f"expected times (N,), positions (N, 3) and velocities (N, 3), got {t.shape}, "
                           f"{r.shape}, {v.shape}")
    if t.size < DEGREE_MIN + 3:
        raise GnssFitError(f"need at least {DEGREE_MIN + 3} GNSS samples, got {t.size}")
    if np.any(np.diff(t) <= 0):
        raise GnssFitError("GNSS times must be strictly increasing (duplicates removed)")
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(v))):
        raise GnssFitError("GNSS positions and velocities must be finite")
    return t, r, v


def split_arcs(time_tai_ns: NDArray, arc_max_s: float, max_gap_s: float) -> list[slice]:
    """Index slices of arcs: split at gaps longer than max_gap_s, runs cut into equal pieces of at
    most arc_max_s (each piece keeps at least DEGREE_MIN + 3 samples when it can)."""
    t = np.asarray(time_tai_ns, dtype=np.int64)
    cuts = np.flatnonzero(np.diff(t) > max_gap_s * NS_PER_S) + 1
    bounds = np.concatenate([[0], cuts, [t.size]])
    out: list[slice] = []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        span_s = (t[b - 1] - t[a]) / NS_PER_S
        pieces = max(1, int(np.ceil(span_s / arc_max_s - 1e-9)))
        pieces = max(1, min(pieces, (b - a) // (DEGREE_MIN + 3)))
        edges = t[a] + np.round(np.arange(1, pieces) * (t[b - 1] - t[a]) / pieces).astype(np.int64)
        idx = np.concatenate([[a], a + np.searchsorted(t[a:b], edges, side="left"), [b]])
        out += [slice(int(i), int(j)) for i, j in zip(idx[:-1], idx[1:], strict=True) if j > i]
    return out


@dataclass(frozen=True)
class GnssArc:
    """One fitted arc. Times: first/last sample [tai_ns]; ``t_ref_ns`` origin of the fit's time.

    position_rms_m, velocity_rms_m_s (3,): rms residuals per ITRF axis; consistency_rms_m_s (3,): rms
    of (d r_fit/dt - v_fit) at the samples (0 for "chebyshev" by construction); degree (chebyshev) or
    harmonics (sine; position, velocity); position_sigma_m / velocity_sigma_m_s: the weights used.
    """

    first_tai_ns: int
    last_tai_ns: int
    t_ref_ns: int
    n_samples: int
    method: str
    degree: int
    harmonics: tuple[int, int]
    position_rms_m: NDArray
    velocity_rms_m_s: NDArray
    consistency_rms_m_s: NDArray
    position_sigma_m: float
    velocity_sigma_m_s: float
    margin_ns: int
    _coef: NDArray | None = field(default=None, repr=False)
    _half_s: float = 1.0
    _mid_s: float = 0.0
    _fit_r: SineSeriesFit | None = field(default=None, repr=False)
    _fit_v: SineSeriesFit | None = field(default=None, repr=False)

    def evaluate(self, tai_ns: ArrayLike) -> tuple[NDArray, NDArray]:
        """r_E, v_E (..., 3) [m, m/s] of the fit at tai_ns (...) (no coverage check)."""
        t = np.asarray(tai_ns, dtype=np.int64)
        s = (t - self.t_ref_ns).astype(np.float64) / NS_PER_S
        if self.method == "chebyshev":
            assert self._coef is not None
            x = (s - self._mid_s) / self._half_s
            r = np.moveaxis(np.asarray(cheb.chebval(x, self._coef)), 0, -1)
            v = np.moveaxis(np.asarray(cheb.chebval(x, cheb.chebder(self._coef) / self._half_s)), 0, -1)
            return r, v
        assert self._fit_r is not None and self._fit_v is not None
        return self._fit_r.evaluate(s), self._fit_v.evaluate(s)


def _cheb_design(x: NDArray, degree: int, half_s: float) -> tuple[NDArray, NDArray]:
    v = cheb.chebvander(x, degree)
    d = cheb.chebvander(x, max(degree - 1, 0)) @ cheb.chebder(np.eye(degree + 1), axis=0) / half_s
    return v, d


def _joint_fit(x: NDArray, r: NDArray, v: NDArray, degree: int, half_s: float, s_r: float, s_v: float
               ) -> tuple[NDArray, NDArray, NDArray]:
    vr, dv = _cheb_design(x, degree, half_s)
    a = np.vstack([vr / s_r, dv / s_v])
    y = np.vstack([r / s_r, v / s_v])
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    return coef, r - vr @ coef, v - dv @ coef


def _gcv_degree(x: NDArray, r: NDArray, v: NDArray, top: int, half_s: float, s_r: float, s_v: float) -> int:
    """Degree in DEGREE_MIN..top minimising GCV = m RSS / (m - p)^2 of the joint weighted fit.

    The Chebyshev designs are nested, so one QR of the widest design gives every RSS: RSS(d) =
    |(I - QQ^T) y|^2 + sum of the squared components of Q^T y beyond column d (m = 2N rows per axis).
    """
    vr, dv = _cheb_design(x, top, half_s)
    a = np.vstack([vr / s_r, dv / s_v])
    y = np.vstack([r / s_r, v / s_v])
    q, _ = np.linalg.qr(a)
    proj = q.T @ y
    base = float(np.sum((y - q @ proj) ** 2))
    tail = np.concatenate([np.cumsum(np.sum(proj ** 2, axis=1)[::-1])[::-1], [0.0]])
    degrees = np.arange(DEGREE_MIN, top + 1)
    rss = base + tail[degrees + 1]
    m = a.shape[0]
    p = degrees + 1
    score = np.where(m > p, m * rss / np.maximum(m - p, 1) ** 2, np.inf)
    return int(degrees[int(np.argmin(score))])


def _fit_chebyshev(t_s: NDArray, r: NDArray, v: NDArray, degree: int | None) -> dict:
    mid = 0.5 * (t_s[0] + t_s[-1])
    half = max(0.5 * (t_s[-1] - t_s[0]), 1e-9)
    x = (t_s - mid) / half
    n = t_s.size
    top = min(DEGREE_MAX, n - 2)
    # Noise levels for the weights: separate fits of a generous degree, then the joint fit's residuals.
    d0 = min(12, top)
    s_r = max(float(np.sqrt(np.mean((r - cheb.chebvander(x, d0) @ np.linalg.lstsq(
        cheb.chebvander(x, d0), r, rcond=None)[0]) ** 2))), SIGMA_FLOOR_M)
    dv0 = _cheb_design(x, d0, half)[1][:, 1:]
    s_v = max(float(np.sqrt(np.mean((v - dv0 @ np.linalg.lstsq(dv0, v, rcond=None)[0]) ** 2))), SIGMA_FLOOR_M_S)
    best = degree
    for _ in range(2):
        if degree is None:
            best = _gcv_degree(x, r, v, top, half, s_r, s_v)
        assert best is not None
        coef, er, ev = _joint_fit(x, r, v, best, half, s_r, s_v)
        dof = max(n - (best + 1) / 2.0, 1.0)
        s_r = max(float(np.sqrt(np.sum(er ** 2) / (3 * dof))), SIGMA_FLOOR_M)
        s_v = max(float(np.sqrt(np.sum(ev ** 2) / (3 * dof))), SIGMA_FLOOR_M_S)
    assert best is not None
    coef, er, ev = _joint_fit(x, r, v, best, half, s_r, s_v)
    return {"coef": coef, "half": half, "mid": mid, "degree": best, "er": er, "ev": ev,
            "s_r": s_r, "s_v": s_v, "consistency": np.zeros(3)}


def _fit_sine(t_s: NDArray, r: NDArray, v: NDArray, harmonics: int | None) -> dict:
    cap = min(SINE_MAX_HARMONICS, t_s.size - 4)
    m_r = harmonics if harmonics is not None else select_harmonics(t_s, r, cap, criterion="gcv")[0]
    m_v = harmonics if harmonics is not None else select_harmonics(t_s, v, cap, criterion="gcv")[0]
    fr = fit_sine_series(t_s, r, int(m_r))
    fv = fit_sine_series(t_s, v, int(m_v))
    er, ev = r - fr.fitted, v - fv.fitted
    consistency = np.sqrt(np.mean((fr.derivative(t_s) - fv.evaluate(t_s)) ** 2, axis=0))
    return {"fit_r": fr, "fit_v": fv, "harmonics": (int(m_r), int(m_v)), "er": er, "ev": ev,
            "s_r": float(np.sqrt(np.mean(er ** 2))), "s_v": float(np.sqrt(np.mean(ev ** 2))),
            "consistency": consistency}


@dataclass(frozen=True)
class GnssFit:
    """Smoothed GNSS orbit: arcs (in time order) and pooled statistics.

    evaluate(tai_ns) -> (r_E, v_E, covered): NaN rows where no arc covers a time (between arcs,
    more than an arc's ``margin_ns`` beyond its end samples).
    """

    arcs: tuple[GnssArc, ...]
    method: str

    @property
    def n_samples(self) -> int:
        return int(sum(a.n_samples for a in self.arcs))

    def _pooled(self, name: str) -> NDArray:
        w = np.array([a.n_samples for a in self.arcs], dtype=float)
        vals = np.stack([getattr(a, name) for a in self.arcs])
        return np.sqrt(np.sum(w[:, None] * vals ** 2, axis=0) / np.sum(w))

    @property
    def position_rms_m(self) -> NDArray:
        return self._pooled("position_rms_m")

    @property
    def velocity_rms_m_s(self) -> NDArray:
        return self._pooled("velocity_rms_m_s")

    @property
    def consistency_rms_m_s(self) -> NDArray:
        return self._pooled("consistency_rms_m_s")

    def covered(self, tai_ns: ArrayLike) -> NDArray:
        t = np.asarray(tai_ns, dtype=np.int64)
        out = np.zeros(t.shape, dtype=bool)
        for a in self.arcs:
            out |= (t >= a.first_tai_ns - a.margin_ns) & (t <= a.last_tai_ns + a.margin_ns)
        return out

    def evaluate(self, tai_ns: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
        t = np.asarray(tai_ns, dtype=np.int64).reshape(-1)
        r = np.full((t.size, 3), np.nan)
        v = np.full((t.size, 3), np.nan)
        done = np.zeros(t.size, dtype=bool)
        for a in self.arcs:
            m = ~done & (t >= a.first_tai_ns - a.margin_ns) & (t <= a.last_tai_ns + a.margin_ns)
            if np.any(m):
                r[m], v[m] = a.evaluate(t[m])
                done |= m
        shape = np.shape(tai_ns)
        return r.reshape(shape + (3,)), v.reshape(shape + (3,)), done.reshape(shape)


def fit_gnss(
    time_tai_ns: ArrayLike,
    r_E: ArrayLike,
    v_E: ArrayLike,
    *,
    method: Method = "chebyshev",
    arc_max_s: float = ARC_MAX_S,
    max_gap_s: float | None = None,
    degree: int | None = None,
) -> GnssFit:
    """Smooth ITRF GNSS states arc by arc (module docstring; 003 §1.6).

    time_tai_ns (N,) int64 strictly increasing; r_E (N, 3) [m]; v_E (N, 3) [m/s]. method:
    "chebyshev" (joint r/v fit, degree by GCV unless ``degree``) or "sine" (003 sine series,
    harmonics by GCV unless ``degree`` gives them). max_gap_s: a longer interval starts a new arc
    (default 10 x the median step). Arcs with fewer than DEGREE_MIN + 3 samples are skipped.
    """
    t, r, v = _as_states(time_tai_ns, r_E, v_E)
    step_s = float(np.median(np.diff(t))) / NS_PER_S
    gap_s = 10.0 * step_s if max_gap_s is None else max_gap_s
    arcs: list[GnssArc] = []
    for sl in split_arcs(t, arc_max_s, gap_s):
        tt = t[sl]
        if tt.size < DEGREE_MIN + 3:
            continue
        t_ref = int(tt[0])
        s = (tt - t_ref).astype(np.float64) / NS_PER_S
        if method == "chebyshev":
            f = _fit_chebyshev(s, r[sl], v[sl], degree)
        elif method == "sine":
            f = _fit_sine(s, r[sl], v[sl], degree)
        else:
            raise GnssFitError(f"method must be 'chebyshev' or 'sine', got {method!r}")
        arc_step = float(np.median(np.diff(tt))) if tt.size > 1 else step_s * NS_PER_S
        arcs.append(GnssArc(
            first_tai_ns=int(tt[0]), last_tai_ns=int(tt[-1]), t_ref_ns=t_ref, n_samples=int(tt.size),
            method=method, degree=int(f.get("degree", 0)), harmonics=f.get("harmonics", (0, 0)),
            position_rms_m=np.sqrt(np.mean(f["er"] ** 2, axis=0)),
            velocity_rms_m_s=np.sqrt(np.mean(f["ev"] ** 2, axis=0)),
            consistency_rms_m_s=np.asarray(f["consistency"], dtype=float),
            position_sigma_m=float(f["s_r"]), velocity_sigma_m_s=float(f["s_v"]),
            margin_ns=int(round(1.5 * arc_step)),
            _coef=f.get("coef"), _half_s=float(f.get("half", 1.0)), _mid_s=float(f.get("mid", 0.0)),
            _fit_r=f.get("fit_r"), _fit_v=f.get("fit_v"),
        ))
    if not arcs:
        raise GnssFitError(f"no arc has {DEGREE_MIN + 3} or more GNSS samples (gaps longer than {gap_s:g} s "
                           "split the data)")
    return GnssFit(arcs=tuple(arcs), method=method)


def _eop_at(eop: EopSource, tai_ns: NDArray) -> EarthOrientation:
    if eop is None:
        return EarthOrientation()
    if callable(eop):
        return eop(tai_ns)
    return eop


def gnss_to_gcrs(fit: GnssFit, tai_ns: ArrayLike, eop: EopSource = None
                 ) -> tuple[NDArray, NDArray, NDArray]:
    """Fitted GCRS state r_I, v_I (..., 3) at tai_ns and the covered mask (NaN where not covered).

    ``eop``: EarthOrientation (scalars or arrays shaped like tai_ns) or a callable tai_ns ->
    EarthOrientation (e.g. interpolation of an uploaded finals2000A table), or None for zero EOP.
    """
    t = np.asarray(tai_ns, dtype=np.int64)
    r_E, v_E, ok = fit.evaluate(t)
    r_I = np.full(r_E.shape, np.nan)
    v_I = np.full(v_E.shape, np.nan)
    if np.any(ok):
        e = _eop_at(eop, t[ok])
        r_I[ok], v_I[ok] = itrs_to_gcrs_state(r_E[ok], v_E[ok], t[ok], e)
    return r_I, v_I, ok


def ascending_nodes(fit: GnssFit, eop: EopSource = None, step_s: float = 10.0) -> NDArray[np.int64]:
    """Times [tai_ns] (K,) where the fitted orbit crosses the GCRS equator northwards (z_I: - -> +).

    Sampled every ``step_s`` within each arc, bracketed crossings refined by bisection on the fit to
    1 µs. eop as in :func:`gnss_to_gcrs`.
    """
    found: list[NDArray] = []
    for arc in fit.arcs:
        n = max(2, int(np.ceil((arc.last_tai_ns - arc.first_tai_ns) / (step_s * NS_PER_S))) + 1)
        grid = np.linspace(arc.first_tai_ns, arc.last_tai_ns, n).round().astype(np.int64)
        z = _z_inertial(arc, grid, eop)
        k = np.flatnonzero((z[:-1] < 0) & (z[1:] >= 0))
        if k.size == 0:
            continue
        lo, hi = grid[k].copy(), grid[k + 1].copy()
        while np.any(hi - lo > 1000):
            mid = lo + (hi - lo) // 2
            zm = _z_inertial(arc, mid, eop)
            below = zm < 0
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        found.append(hi)
    if not found:
        return np.zeros(0, dtype=np.int64)
    return np.unique(np.concatenate(found))


def _z_inertial(arc: GnssArc, t: NDArray, eop: EopSource) -> NDArray:
    r_E, v_E = arc.evaluate(t)
    r_I, _ = itrs_to_gcrs_state(r_E, v_E, t, _eop_at(eop, t))
    return r_I[..., 2]


def _mean_anomaly(nu: NDArray, e: NDArray) -> NDArray:
    big_e = 2.0 * np.arctan2(np.sqrt(1.0 - e) * np.sin(nu / 2.0), np.sqrt(1.0 + e) * np.cos(nu / 2.0))
    return big_e - e * np.sin(big_e)


def time_since_node_kepler_s(r_I: ArrayLike, v_I: ArrayLike, mu_m3_s2: float = MU_EARTH_M3_S2) -> NDArray:
    """Time since the preceding ascending node [s] from the osculating two-body elements of (r_I, v_I).

    r_I, v_I (..., 3) inertial [m, m/s]. dt = (M(u - omega) - M(-omega)) / n mod the period, with
    M the mean anomaly of the true anomaly, u the argument of latitude, omega the argument of perigee
    and n the mean motion (elliptic orbits; NaN otherwise). J2 makes this err by ~1e-3 of dt.
    """
    r = np.asarray(r_I, dtype=float)
    v = np.asarray(v_I, dtype=float)
    rn = np.linalg.norm(r, axis=-1)
    h = np.cross(r, v)
    hn = np.linalg.norm(h, axis=-1)
    node = np.cross(np.array([0.0, 0.0, 1.0]), h)
    nn = np.linalg.norm(node, axis=-1)
    node_u = node / np.where(nn > 0, nn, 1.0)[..., None]
    node_u = np.where((nn > 0)[..., None], node_u, np.array([1.0, 0.0, 0.0]))
    h_u = h / hn[..., None]
    u = np.arctan2(np.sum(np.cross(node_u, r) * h_u, axis=-1), np.sum(node_u * r, axis=-1))
    e_vec = np.cross(v, h) / mu_m3_s2 - r / rn[..., None]
    e = np.linalg.norm(e_vec, axis=-1)
    omega = np.arctan2(np.sum(np.cross(node_u, e_vec) * h_u, axis=-1), np.sum(node_u * e_vec, axis=-1))
    energy = 0.5 * np.sum(v * v, axis=-1) - mu_m3_s2 / rn
    with np.errstate(invalid="ignore", divide="ignore"):
        a = -mu_m3_s2 / (2.0 * energy)
        n = np.sqrt(mu_m3_s2 / a ** 3)
        dm = np.mod(_mean_anomaly(u - omega, e) - _mean_anomaly(-omega, e), 2.0 * np.pi)
        out = dm / n
    return np.where((energy < 0) & (e < 1), out, np.nan)


def time_since_ascending_node_s(tai_ns: ArrayLike, r_I: ArrayLike, v_I: ArrayLike,
                                nodes_tai_ns: ArrayLike) -> NDArray:
    """Time since the preceding ascending node [s] (003 §1.6 "virtual orbit") at tai_ns (N,).

    Uses the latest node of ``nodes_tai_ns`` at or before each time when it is less than one
    osculating period earlier; otherwise the osculating two-body estimate
    (:func:`time_since_node_kepler_s`) from r_I, v_I (N, 3).
    """
    t = np.asarray(tai_ns, dtype=np.int64)
    kepler = time_since_node_kepler_s(r_I, v_I)
    nodes = np.sort(np.asarray(nodes_tai_ns, dtype=np.int64))
    if nodes.size == 0:
        return kepler
    k = np.searchsorted(nodes, t, side="right") - 1
    has = k >= 0
    dt = np.where(has, (t - nodes[np.maximum(k, 0)]).astype(np.float64) / NS_PER_S, np.nan)
    r = np.asarray(r_I, dtype=float)
    v = np.asarray(v_I, dtype=float)
    energy = 0.5 * np.sum(v * v, axis=-1) - MU_EARTH_M3_S2 / np.linalg.norm(r, axis=-1)
    with np.errstate(invalid="ignore"):
        period = 2.0 * np.pi * np.sqrt((-MU_EARTH_M3_S2 / (2.0 * energy)) ** 3 / MU_EARTH_M3_S2)
    use = has & (dt < period)
    return np.where(use, dt, kepler)
