"""Noise level and time-tag consistency of raw GNSS states, and the check of a GNSS fit against them.

Split from processing.orbits.gnss_orbit (which smooths the states): :func:`divided_difference_noise`
(robust white-noise sigma), :func:`time_tag_check` (late time tags from a robust local orbit) and
:func:`check_gnss_fit` (the fit's residuals against the receiver noise, with the likely cause). Used by
processing.star_tracker.orbital_attitude and processing.screening.gnss.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.polynomial import chebyshev as cheb
from numpy.typing import ArrayLike, NDArray

from processing.orbits.gnss_orbit import SIGMA_FLOOR_M, SIGMA_FLOOR_M_S, GnssFit, _as_states, split_arcs
from processing.units import MU_EARTH_M3_S2, NS_PER_S


def divided_difference_noise(t_s: ArrayLike, y: ArrayLike, order: int = 4) -> NDArray:
    """Robust white-noise sigma per column of y (N, d) sampled at t_s (N,) (irregular spacing allowed).

    The ``order``-th divided difference D = sum_j w_j y_j (w_j = 1 / prod_{i != j} (t_j - t_i) over
    order + 1 consecutive samples) of a smooth signal is y^(order)(xi) / order!, negligible for an orbit
    at 1-10 s sampling (4th: n^4 r / 24 ~ 1e-7 m/s^4), while white noise of sigma gives D ~ N(0, sigma^2
    sum w_j^2). So sigma = 1.4826 median |D / sqrt(sum w_j^2)| -- a median, so that a few outliers or
    late time tags (which move whole blocks, leaving only the block edges in the differences) do not
    inflate it. Returns (d,) (NaN with fewer than order + 2 samples).
    """
    t = np.asarray(t_s, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    y2 = yy if yy.ndim == 2 else yy[:, None]
    n = t.size
    if n < order + 2:
        return np.full(y2.shape[1], np.nan)
    k = np.arange(order + 1)
    idx = np.arange(n - order)[:, None] + k[None, :]  # (m, order + 1)
    tt = t[idx] - t[idx[:, :1]]  # relative times (precision)
    diff = tt[:, :, None] - tt[:, None, :]  # (m, j, i)
    diff[:, k, k] = 1.0
    w = 1.0 / np.prod(diff, axis=2)  # (m, order + 1)
    d = np.einsum("mj,mjc->mc", w, y2[idx])
    z = d / np.sqrt(np.sum(w * w, axis=1))[:, None]
    return 1.4826 * np.median(np.abs(z), axis=0)


@dataclass(frozen=True)
class TimeTagCheck:
    """Per-sample time-tag consistency of GNSS states against a robust local orbit (:func:`time_tag_check`).

    offset_s (N,): the time tau by which each state lags its tag (state of t - tau reported at t; > 0:
    tagged late), NaN where not judged; shift_consistent (N,): the position and velocity residuals are
    both explained by that tau (a pure time-tag error, not a position or velocity fault);
    position_residual_m (N,): |r - r_fit| before the shift; applied (N,): judged.
    """

    offset_s: NDArray
    shift_consistent: NDArray
    position_residual_m: NDArray
    applied: NDArray


TIME_TAG_WINDOW_S = 600.0
TIME_TAG_DEGREE = 7
"""Degree of the robust position fit over TIME_TAG_WINDOW_S (1 mm over 10 min of LEO arc)."""


def time_tag_check(time_tai_ns: ArrayLike, r_E: ArrayLike, v_E: ArrayLike, *, position_sigma_m: float,
                   velocity_sigma_m_s: float, k: float = 6.0, window_s: float = TIME_TAG_WINDOW_S,
                   max_gap_s: float = 120.0) -> TimeTagCheck:
    """Time-tag offsets of GNSS states from a robust fit of the positions (dr = -v tau, dv = -a tau).

    time_tai_ns (N,) increasing; r_E, v_E (N, 3) ITRF [m, m/s]; position_sigma_m, velocity_sigma_m_s: the
    receiver's noise (1 sigma per axis). In pieces of at most ``window_s`` (split at gaps > max_gap_s) a
    Chebyshev polynomial of degree TIME_TAG_DEGREE (mm over 10 min of LEO arc) is fitted to the positions
    with iterative rejection of residuals beyond k x max(robust scale, sigma) -- a minority of states
    tagged late by seconds sit kilometres off it. A state whose tag is late by tau reports r(t - tau) ~
    r(t) - v tau and v(t - tau) ~ v(t) - a tau: tau = -(dr . v) / |v|^2 and the state is
    ``shift_consistent`` when |dr + v tau| <= k sqrt(2) sigma_r and |dv + a tau| <= k (sigma_v + sigma_r
    |a| / |v|) (the along-track noise passes into tau). Pieces with fewer than 3 x (degree + 1) samples
    are not judged.
    """
    t = np.asarray(time_tai_ns, dtype=np.int64)
    r = np.asarray(r_E, dtype=np.float64)
    v = np.asarray(v_E, dtype=np.float64)
    n = t.size
    tau = np.full(n, np.nan)
    consistent = np.zeros(n, dtype=bool)
    resid = np.full(n, np.nan)
    applied = np.zeros(n, dtype=bool)
    if n < 3 * (TIME_TAG_DEGREE + 1):
        return TimeTagCheck(tau, consistent, resid, applied)
    sig_r = max(position_sigma_m, SIGMA_FLOOR_M)
    step_ns = int(window_s / 3.0 * NS_PER_S)
    for arc in split_arcs(t, np.inf, max_gap_s):
        ta = t[arc]
        for c0 in range(int(ta[0]), int(ta[-1]) + 1, step_ns):  # judge [c0, c0 + step) from a window around it
            lo = int(np.searchsorted(ta, c0 - step_ns, side="left"))
            hi = int(np.searchsorted(ta, c0 + 2 * step_ns, side="left"))
            j0 = int(np.searchsorted(ta, c0, side="left"))
            j1 = int(np.searchsorted(ta, c0 + step_ns, side="left"))
            if j1 <= j0 or hi - lo < 3 * (TIME_TAG_DEGREE + 1):
                continue
            sl = slice(arc.start + lo, arc.start + hi)
            out = _time_tag_piece(t[sl], r[sl], v[sl], sig_r, velocity_sigma_m_s, k)
            judged = slice(j0 - lo, j1 - lo)
            dst = slice(arc.start + j0, arc.start + j1)
            tau[dst], consistent[dst], resid[dst] = out[0][judged], out[1][judged], out[2][judged]
            applied[dst] = True
    return TimeTagCheck(tau, consistent, resid, applied)


def _time_tag_piece(t: NDArray, r: NDArray, v: NDArray, sig_r: float, sig_v: float, k: float
                    ) -> tuple[NDArray, NDArray, NDArray]:
    """(tau, shift_consistent, |dr|) of one window (:func:`time_tag_check`)."""
    m = t.size
    s = (t - t[0]).astype(np.float64) / NS_PER_S
    half = max(0.5 * (s[-1] - s[0]), 1e-9)
    x = (s - 0.5 * (s[0] + s[-1])) / half
    design = cheb.chebvander(x, TIME_TAG_DEGREE)
    # Late tags move whole blocks of states consistently (positions still the integral of the velocities):
    # split at the increments that fail that kinematic test, seed the fit with the longest run, then
    # accept every run that agrees with it.
    dt = np.diff(s)
    inc = np.linalg.norm(r[1:] - r[:-1] - 0.5 * (v[1:] + v[:-1]) * dt[:, None], axis=1)
    jerk = 2.0 * MU_EARTH_M3_S2 * np.linalg.norm(v, axis=1) / np.linalg.norm(r, axis=1) ** 3 + 0.02
    tol = k * np.sqrt(2.0 * sig_r ** 2 + 0.5 * (dt * sig_v) ** 2) + dt ** 3 / 12.0 * np.maximum(jerk[1:], jerk[:-1])
    run = np.concatenate([[0], np.cumsum(inc > tol)])
    counts = np.bincount(run)
    order = np.argsort(-counts, kind="stable")
    accepted = np.zeros(counts.size, dtype=bool)
    accepted[order[0]] = True
    thr = k * 1.6 * sig_r
    if counts[order[0]] >= 2 * (TIME_TAG_DEGREE + 1):
        for j in order[1:]:  # grow: a run joins when the fit with it still fits every accepted run
            trial = accepted.copy()
            trial[j] = True
            sel = trial[run]
            c, *_ = np.linalg.lstsq(design[sel], r[sel], rcond=None)
            e = np.linalg.norm(r - design @ c, axis=1)
            med = np.array([np.median(e[run == i]) if trial[i] else 0.0 for i in range(counts.size)])
            if np.all(med <= thr):
                accepted = trial
        use = accepted[run]
    else:
        use = np.ones(m, dtype=bool)
    coef = np.zeros((TIME_TAG_DEGREE + 1, 3))
    for _ in range(8):  # ... then rejection beyond k x the noise
        coef, *_ = np.linalg.lstsq(design[use], r[use], rcond=None)
        e = np.linalg.norm(r - design @ coef, axis=1)
        scale = float(np.median(e[use])) / 1.5382  # median of chi_3 -> sigma per axis
        new = e <= k * max(scale, sig_r) * 1.6
        if new.sum() < 2 * (TIME_TAG_DEGREE + 1) or np.array_equal(new, use):
            break
        use = new
    r_fit = design @ coef
    # chebder(c, m) applies the one-step derivative m times (scl = 1): chaining the steps gives the same
    # coefficients bit for bit with 3 steps instead of 1 + 2 + 3
    d1 = cheb.chebder(coef)
    d2 = cheb.chebder(d1)
    d3 = cheb.chebder(d2)
    v_fit = cheb.chebval(x, d1 / half).T
    a_fit = cheb.chebval(x, d2 / half ** 2).T
    j_fit = cheb.chebval(x, d3 / half ** 3).T
    dr = r - r_fit
    speed2 = np.sum(v_fit * v_fit, axis=1)
    tau = -np.sum(dr * v_fit, axis=1) / speed2
    for _ in range(3):  # r(t - tau) = r - v tau + a tau^2 / 2 - j tau^3 / 6 (tau of seconds: 50 m at 3.4 s)
        t2 = tau[:, None] ** 2
        tau = -np.sum((dr - a_fit * t2 / 2.0 + j_fit * t2 * tau[:, None] / 6.0) * v_fit, axis=1) / speed2
    tc = tau[:, None]
    e_r = np.linalg.norm(dr + v_fit * tc - a_fit * tc ** 2 / 2.0 + j_fit * tc ** 3 / 6.0, axis=1)
    e_v = np.linalg.norm(v - v_fit + a_fit * tc - j_fit * tc ** 2 / 2.0, axis=1)
    acc = np.linalg.norm(a_fit, axis=1)
    ok = (e_r <= k * np.sqrt(2.0) * sig_r) & (e_v <= k * (sig_v + sig_r * acc / np.sqrt(speed2)))
    return tau, ok, np.linalg.norm(dr, axis=1)


GNSS_RMS_RATIO_MAX = 2.0
"""The fit's residual rms may exceed the receiver noise by this factor before the fit is called inconsistent."""
GNSS_RESIDUAL_FLOOR_M = 1.0
GNSS_RESIDUAL_FLOOR_M_S = 1e-3
"""Residual rms below these is never inconsistent: it turns a LEO orbital frame by < 0.03 arcsec (a precise
orbit, e.g. GRACE-FO GNV1B with sub-mm noise, leaves sub-mm model residuals above its noise)."""


@dataclass(frozen=True)
class GnssFitCheck:
    """The GNSS fit's residuals judged against the receiver's noise (:func:`check_gnss_fit`).

    position_sigma_m / velocity_sigma_m_s: the noise used (given, or estimated from the samples' divided
    differences, ``noise_source``); rms_ratio (2,): fit residual rms / noise for position and velocity;
    chi2, dof, p_value: of the squared residuals over noise^2 (both kinds); consistent: both ratios below
    GNSS_RMS_RATIO_MAX. Cause analysis (when not consistent): late_tags (N,) states whose residuals are a time
    shift, late_offset_s (median shift of those, > 0: tagged late), inertial_velocity (velocities look
    inertial: v - dr/dt ~ w_E x r), cause: short text. position_error_m, velocity_error_m_s: the fit's
    error per axis to pass on to what is derived from it (the orbital frame).
    """

    position_sigma_m: float
    velocity_sigma_m_s: float
    noise_source: str
    rms_ratio: tuple[float, float]
    chi2: float
    dof: int
    p_value: float
    consistent: bool
    late_tags: NDArray
    late_offset_s: float | None
    inertial_velocity: bool
    cause: str | None
    position_error_m: float
    velocity_error_m_s: float


def check_gnss_fit(fit: GnssFit, time_tai_ns: ArrayLike, r_E: ArrayLike, v_E: ArrayLike, *,
                   position_sigma_m: float | None = None, velocity_sigma_m_s: float | None = None) -> GnssFitCheck:
    """Judge a fit against the receiver noise and name the likely cause when it does not fit.

    The noise is the given one or, per kind, the robust divided-difference estimate of the samples
    (:func:`divided_difference_noise`: insensitive to a minority of late tags, which move whole blocks).
    The fit is inconsistent when its residual rms exceeds GNSS_RMS_RATIO_MAX x that noise and the floors
    GNSS_RESIDUAL_FLOOR_M / _M_S (a chi-square test would call any mis-stated noise inconsistent with 10^4
    samples; the ratio says how far). Causes tried:
    time tags (:func:`time_tag_check`: residuals that are one time shift, in position and velocity) and
    the velocity frame (Earth-relative velocities expected; inertial ones differ by w_E x r, ~0.5 km/s).
    position_error_m / velocity_error_m_s: the fit's error at the samples to pass on to derived frames:
    sigma sqrt(p / n) per axis when consistent, the residual rms itself when not (the fit follows the
    inconsistent data by an unknown share).
    """
    from processing.estimation.chi2 import chi2_sf
    from processing.units import OMEGA_EARTH_RAD_S

    t, r, v = _as_states(time_tai_ns, r_E, v_E)
    t_s = (t - t[0]).astype(np.float64) / NS_PER_S
    est_r = float(np.sqrt(np.mean(divided_difference_noise(t_s, r) ** 2)))
    est_v = float(np.sqrt(np.mean(divided_difference_noise(t_s, v) ** 2)))
    sig_r = max(position_sigma_m if position_sigma_m is not None else est_r, SIGMA_FLOOR_M)
    sig_v = max(velocity_sigma_m_s if velocity_sigma_m_s is not None else est_v, SIGMA_FLOOR_M_S)
    source = ("given" if position_sigma_m is not None and velocity_sigma_m_s is not None else
              "estimated from the divided differences of the samples" if position_sigma_m is None
              and velocity_sigma_m_s is None else "given (position or velocity) and estimated (the other)")
    rms_r = float(np.sqrt(np.mean(fit.position_rms_m ** 2)))
    rms_v = float(np.sqrt(np.mean(fit.velocity_rms_m_s ** 2)))
    n = fit.n_samples
    p = sum((a.degree + 1) if a.method == "chebyshev" else sum(a.harmonics) + 2 for a in fit.arcs)
    chi2 = 3.0 * n * ((rms_r / sig_r) ** 2 + (rms_v / sig_v) ** 2)
    dof = max(6 * n - 3 * p, 1)
    ratio = (rms_r / sig_r, rms_v / sig_v)
    consistent = (rms_r <= max(GNSS_RMS_RATIO_MAX * sig_r, GNSS_RESIDUAL_FLOOR_M)
                  and rms_v <= max(GNSS_RMS_RATIO_MAX * sig_v, GNSS_RESIDUAL_FLOOR_M_S))
    late = np.zeros(t.size, dtype=bool)
    offset = None
    inertial = False
    cause = None
    if not consistent:
        chk = time_tag_check(t, r, v, position_sigma_m=sig_r, velocity_sigma_m_s=sig_v)
        speed = np.linalg.norm(v, axis=1)
        late = chk.applied & chk.shift_consistent & (np.abs(chk.offset_s) > 6.0 * sig_r / np.maximum(speed, 1.0))
        if np.any(late):
            offset = float(np.median(chk.offset_s[late]))
            cause = (f"time tags: {int(late.sum())} states are time-tagged {abs(offset):.3g} s "
                     f"{'late' if offset > 0 else 'early'} (positions and velocities are those of one time shift)")
        v_pos = _position_rate(t, r)  # the positions' own rate of change (the joint fit compromises)
        w_x_r = np.cross([0.0, 0.0, OMEGA_EARTH_RAD_S], r)
        ok = np.isfinite(v_pos).all(axis=1)
        if np.any(ok):
            dv = v[ok] - v_pos[ok]
            inertial = bool(np.median(np.linalg.norm(dv - w_x_r[ok], axis=1))
                            < 0.1 * np.median(np.linalg.norm(w_x_r[ok], axis=1))
                            and np.median(np.linalg.norm(dv, axis=1)) > 0.5 * np.median(np.linalg.norm(w_x_r[ok],
                                                                                                        axis=1)))
        if inertial:
            cause = ((cause + "; ") if cause else "") + ("frame: the velocities differ from the positions' rate of "
                                                         "change by w_E x r, i.e. they are inertial, not Earth-fixed")
        if cause is None:
            cause = ("unknown: neither a time-tag offset nor an inertial velocity frame explains the residuals; check "
                     "the frame (ITRF expected), the units and the time scale of the GNSS states")
    if consistent:
        pos_err = sig_r * float(np.sqrt(min(1.0, p / max(n, 1))))
        vel_err = sig_v * float(np.sqrt(min(1.0, p / max(n, 1))))
    else:
        pos_err, vel_err = rms_r, rms_v
    return GnssFitCheck(position_sigma_m=sig_r, velocity_sigma_m_s=sig_v, noise_source=source,
                        rms_ratio=(float(ratio[0]), float(ratio[1])), chi2=float(chi2), dof=int(dof),
                        p_value=float(chi2_sf(chi2, dof)), consistent=bool(consistent), late_tags=late,
                        late_offset_s=offset, inertial_velocity=inertial, cause=cause, position_error_m=pos_err,
                        velocity_error_m_s=vel_err)


def _position_rate(t: NDArray, r: NDArray) -> NDArray:
    """dr/dt (N, 3) of a Chebyshev fit of degree TIME_TAG_DEGREE to the positions alone, per piece of at most
    TIME_TAG_WINDOW_S (NaN in pieces too short)."""
    out = np.full(r.shape, np.nan)
    for sl in split_arcs(t, TIME_TAG_WINDOW_S, 120.0):
        if sl.stop - sl.start < 2 * (TIME_TAG_DEGREE + 1):
            continue
        s = (t[sl] - t[sl.start]).astype(np.float64) / NS_PER_S
        half = max(0.5 * (s[-1] - s[0]), 1e-9)
        x = (s - 0.5 * (s[0] + s[-1])) / half
        coef, *_ = np.linalg.lstsq(cheb.chebvander(x, TIME_TAG_DEGREE), r[sl], rcond=None)
        out[sl] = cheb.chebval(x, cheb.chebder(coef) / half).T
    return out
