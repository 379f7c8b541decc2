"""The settings and the steps of :func:`processing.gyro_calibration.calibration.calibrate_gyro` (paper 000).

Holds :class:`CalibrationSettings`, :class:`CalibrationError`, the motion classes
(:func:`correction_flags`), the drift convergence time, and the steps 2-5 of the calibration described in
:mod:`processing.gyro_calibration.calibration`: the alignment windows and their star-tracker rates, the
passes (eq. 7 integration, drift observer, drift trend, alignment), the reported drift with its sigma
(the end-of-trend functional and the calibration errors' share by finite differences of the observer) and
the slew report. Each step returns a frozen record.

Times are float64 seconds from any epoch; quaternions scalar first.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.gyro_calibration.alignment import AlignmentEstimate, RateNoise, estimate_alignment
from processing.gyro_calibration.drift_observer import (
    MODE_CORRECTED,
    DriftObserverResult,
    DriftTrend,
    fit_drift_trend,
    ramp_lag_s,
    run_drift_observer,
    stationary_noise,
)
from processing.gyro_calibration.observability import RANK_TOLERANCE
from processing.gyro_calibration.slews import SlewReport, slew_report
from processing.gyro_calibration.window_rates import (
    AlignmentError,
    WindowRates,
    alignment_windows,
    star_tracker_window_rates,
)
from processing.signal.gyro_integration import (
    IntervalRotations,
    SubstepPlan,
    interval_rate_maxima,
    interval_rotations,
    plan_substeps,
)
from processing.signal.two_pass_filter import QuasiCoordinateSpline
from processing.units import RAD_PER_ARCSEC, RAD_PER_DEG

__all__ = [
    "CalibrationError",
    "CalibrationSettings",
    "align_windows",
    "build_context",
    "correction_flags",
    "drift_convergence_time",
    "drift_summary",
    "iterate_passes",
    "pass_slew_report",
]

FloatArray = NDArray[np.float64]


class CalibrationError(ValueError):
    """The data do not allow the calibration (too short, no calibration intervals, shapes)."""


@dataclass(frozen=True)
class CalibrationSettings:
    """Parameters of :func:`calibrate_gyro` (defaults from 000 where it gives them).

    t_r_s: observer settling time T_r [s] (nu = 3 / (xi T_r)); 200 s by default: with the growing-memory
    start-up the drift converges to 0.01 "/s in ~30 s whatever T_r, while the stationary noise falls with
    T_r (seed-000 hour: 0.0012 "/s rms at 200 s, 0.003 "/s at 60 s); the price is lag behind a changing
    drift (the estimate is the drift ~120 s earlier at 200 s, ~36 s at 60 s; for drift changes of
    0.2 "/s per hour T_r = 100 s halves the end-of-window error); xi: damping (0.95);
    rate_threshold_rad_s: class MT_alpha bound (1 deg/s); window_min, window_max: alignment window
    lengths in star-tracker samples (12..18); output_period_s: T_p of the rate comparison (0.125 s);
    trend_window_s, trend_degree: drift trend for the prediction through slews and for the reported
    drift (2nd order); max_iterations, change_tolerance: stop when every change < tolerance x sigma;
    acquisition: growing-memory observer gains at start-up; estimate_drift_offset: joint constant
    drift in the alignment; min_spread, max_misalignment_sigma_rad: observability thresholds;
    convergence_tolerance_rad_s: tube for the drift convergence time; window_outlier_factor: windows
    whose polynomial residual exceeds this factor x the median are not used; lag_compensation: advance
    the drift trends by the observer's ramp lag (processing.gyro_calibration.drift_observer.ramp_lag_s);
    per_axis_scale_factor: the alignment's linear step also estimates the scale factor per gyro axis;
    rank_tolerance: relative eigenvalue threshold of the information matrix
    (processing.gyro_calibration.observability).
    """

    t_r_s: float = 200.0
    xi: float = 0.95
    rate_threshold_rad_s: float = 1.0 * RAD_PER_DEG
    window_min: int = 12
    window_max: int = 18
    output_period_s: float = 0.125
    trend_window_s: float = 600.0
    trend_degree: int = 2
    max_iterations: int = 6
    change_tolerance: float = 0.2
    acquisition: bool = True
    estimate_drift_offset: bool = True
    min_spread: float = 0.02
    max_misalignment_sigma_rad: float = 10.0 * RAD_PER_ARCSEC
    convergence_tolerance_rad_s: float = 0.01 * RAD_PER_ARCSEC
    window_outlier_factor: float = 1.5
    lag_compensation: bool = True
    per_axis_scale_factor: bool = False
    rank_tolerance: float = RANK_TOLERANCE


def correction_flags(max_rate_rad_s: ArrayLike, valid: ArrayLike, threshold_rad_s: float) -> NDArray[np.bool_]:
    """Class MT_alpha per star-tracker sample (K,) from the interval maxima (K - 1,): the intervals on
    both sides of the sample are valid and have |w| <= threshold (the first/last sample: its one side)."""
    slow = (np.asarray(max_rate_rad_s) <= threshold_rad_s) & np.asarray(valid, dtype=bool)
    left = np.concatenate([slow[:1], slow])
    right = np.concatenate([slow, slow[-1:]])
    return left & right


def drift_convergence_time(t_s: ArrayLike, drift: ArrayLike, usable: ArrayLike, reference: ArrayLike,
                           tolerance: float) -> float:
    """Seconds from t_s[0] to the first usable sample after which every usable |drift - reference| <= tol
    on all axes (the usable samples before it included). NaN when the last usable sample is outside."""
    t = np.asarray(t_s, dtype=np.float64)
    ok = np.asarray(usable, dtype=bool)
    bad = ok & np.any(np.abs(np.asarray(drift) - np.asarray(reference)) > tolerance, axis=-1)
    idx_ok = np.flatnonzero(ok)
    if idx_ok.size == 0:
        return float("nan")
    if not np.any(bad):
        return float(t[idx_ok[0]] - t[0])
    last_bad = int(np.flatnonzero(bad)[-1])
    after = idx_ok[idx_ok > last_bad]
    return float(t[after[0]] - t[0]) if after.size else float("nan")


# ---------------------------------------------------------------------------------------------------
# The steps of :func:`calibrate_gyro` (module docstring of processing.gyro_calibration.calibration),
# each returning a frozen record.


@dataclass(frozen=True)
class _Windows:
    """Step 2: the star-tracker window rates, the windows used (fit residual test), and at their samples
    the times, star-tracker rates w_A, window index, inverse rate variances and spline rates w_G; the
    star-tracker noise per axis from the window fits."""

    rates: WindowRates
    used: NDArray[np.bool_]
    t_s: FloatArray
    w_A: FloatArray
    window: NDArray[np.intp]
    inv_var: FloatArray
    w_G: FloatArray
    st_noise_rad: FloatArray
    gain: FloatArray


@dataclass(frozen=True)
class _Context:
    """What every pass uses: the star-tracker samples inside the gyro data, the nominal mounting, the
    substep plan of the spline, the alignment windows, T_o, the drift-trend lag and the settings."""

    t_st: FloatArray
    q_st: FloatArray
    q_nom: FloatArray
    plan: SubstepPlan
    windows: _Windows
    t_o: float
    lag: float
    cfg: CalibrationSettings


def build_context(
    spline: QuasiCoordinateSpline, t_st: FloatArray, q_st: FloatArray, q_GS_nominal: ArrayLike,
    cfg: CalibrationSettings,
) -> _Context:
    """Step 2: motion classes from the filtered rate, alignment windows and their star-tracker rates."""
    inside = (t_st >= spline.t_s[0]) & (t_st <= spline.t_s[-1])
    t_st, q_st = t_st[inside], q_st[inside]
    if t_st.size < 3 * cfg.window_max:
        raise CalibrationError(
            f"need at least {3 * cfg.window_max} star-tracker samples inside the gyro data, got {t_st.size}"
        )
    q_nom = rotations.quat_canonical(rotations.quat_normalize(np.asarray(q_GS_nominal, dtype=np.float64)))
    t_o = float(np.median(np.diff(t_st)))
    lag = ramp_lag_s(t_o, cfg.t_r_s, cfg.xi) if cfg.lag_compensation else 0.0
    plan = plan_substeps(spline, t_st)
    on = correction_flags(*interval_rate_maxima(plan), cfg.rate_threshold_rad_s)
    starts, stops = alignment_windows(t_st, on, n_min=cfg.window_min, n_max=cfg.window_max)
    if starts.size < 3:
        raise CalibrationError(
            f"only {starts.size} alignment windows of {cfg.window_min}..{cfg.window_max} samples with "
            f"|w| <= {cfg.rate_threshold_rad_s / RAD_PER_DEG:g} deg/s; at least 3 are needed"
        )
    windows = star_tracker_window_rates(t_st, q_st, starts, stops, t_p_s=cfg.output_period_s)
    rms = np.linalg.norm(windows.residual_rms_rad, axis=1)
    used = rms <= cfg.window_outlier_factor * np.median(rms)
    sel = used[windows.window]
    t_win = windows.t_s[sel]
    win = _Windows(
        rates=windows, used=used, t_s=t_win, w_A=windows.w_A_rad_s[sel], window=windows.window[sel],
        inv_var=1.0 / windows.rate_variance_s2[sel], w_G=spline.rate(t_win),
        st_noise_rad=np.sqrt(np.median(windows.residual_rms_rad[used] ** 2, axis=0)),
        gain=np.asarray(windows.rate_noise_gain)[sel],
    )
    return _Context(t_st, q_st, q_nom, plan, win, t_o, lag, cfg)


def align_windows(
    ctx: _Context, drift_model: DriftTrend | None, q_prior: FloatArray, m_prior: float, degree: int
) -> AlignmentEstimate:
    """Steps 3-4: QUEST alignment and scale factor on the window samples, the drift model subtracted."""
    win, cfg = ctx.windows, ctx.cfg
    w_g = win.w_G if drift_model is None else win.w_G - drift_model(win.t_s)
    try:
        return estimate_alignment(
            win.t_s, w_g, win.w_A, win.window, win.inv_var, q_GS_prior=q_prior, scale_factor_prior=m_prior,
            q_GS_nominal=ctx.q_nom, drift_degree=degree, min_spread=cfg.min_spread,
            max_sigma_rad=cfg.max_misalignment_sigma_rad, noise=RateNoise(win.gain, win.st_noise_rad),
            per_axis_scale_factor=cfg.per_axis_scale_factor, rank_tolerance=cfg.rank_tolerance,
        )
    except AlignmentError as exc:
        raise CalibrationError(str(exc)) from exc


@dataclass(frozen=True)
class _Pass:
    """Step 4, one pass: the new estimate, the observer run and its interval rotations, rate map and
    reference drift, the drift model, the usable samples (corrected, stationary gains), the change in
    sigmas and the history record."""

    est: AlignmentEstimate
    obs: DriftObserverResult
    rot: IntervalRotations
    rate_map: FloatArray
    b_ref: FloatArray
    model: DriftTrend
    usable: NDArray[np.bool_]
    change: float
    record: dict[str, object]
    q_GS_in: FloatArray
    m_in: float


def _pass(
    it: int, ctx: _Context, est: AlignmentEstimate, model: DriftTrend | None, report: Callable[[float, str], None]
) -> _Pass:
    """Step 4: eq. 7 integration with the current calibration, drift observer, drift trend, alignment."""
    cfg, t_st = ctx.cfg, ctx.t_st
    q_GS, m = est.q_GS, est.scale_factor_error
    t_mid = 0.5 * (t_st[0] + t_st[-1])
    b_ref = est.drift_offset(t_mid) + (model(t_mid) if model is not None else 0.0)
    frac = 0.1 + 0.8 * it / (cfg.max_iterations + 1)
    report(frac, f"pass {it}: integrating the calibrated gyro (eq. 7)")
    report(frac + 0.3 / cfg.max_iterations, f"pass {it}: drift observer")
    rot, rate_map, obs = _observer_run(ctx, q_GS, m, b_ref)
    usable = (obs.mode == MODE_CORRECTED) & obs.stationary
    if np.count_nonzero(usable) < 2:
        raise CalibrationError("the drift observer never reached its stationary gains in a calibration interval")
    new_model = fit_drift_trend(t_st[usable], obs.drift_rad_s[usable], cfg.trend_degree).shifted(ctx.lag)
    report(frac + 0.6 / cfg.max_iterations, f"pass {it}: alignment and scale factor (QUEST)")
    new = align_windows(ctx, new_model, q_GS, m, 0)
    d_theta = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(q_GS), new.q_GS))
    # the change of the determined parameters only (the others are held at the prior or not reported)
    sig_th = np.sqrt(np.diag(new.misalignment_cov_rad2))
    changes = [0.0, *(np.abs(d_theta) / np.maximum(sig_th, 1e-300))[new.observable_axes].tolist()]
    if np.all(new.scale_factor_observable):
        changes.append(abs(new.scale_factor_error - m) / max(new.scale_factor_sigma, 1e-300))
    change = float(max(changes))
    record: dict[str, object] = {
        "iteration": it, "misalignment_rad": new.misalignment_rad.tolist(),
        "scale_factor_error": new.scale_factor_error,
        "drift_offset_rad_s": new.drift_offset(t_st[-1]).tolist(), "change_sigma": change,
    }
    return _Pass(new, obs, rot, rate_map, b_ref, new_model, usable, change, record, q_GS, m)


def _observer_run(ctx: _Context, q_GS: FloatArray, m: float, b_ref: FloatArray,
                  near: tuple[IntervalRotations, FloatArray, float] | None = None
                  ) -> tuple[IntervalRotations, FloatArray, DriftObserverResult]:
    """Eq. 7 integration with a calibration (q_GS, m, reference drift) and the drift observer on it.

    near = (rotations, q_GS0, m0) of a run with the same reference drift and a nearby calibration: the
    interval rotations are mapped instead of integrated again (the integrand R_SG (w - b) / (1 + m) of the
    new calibration is the old one turned by the constant R(q_GS0^-1 o q_GS)^T and scaled by
    (1 + m0) / (1 + m): exact for the turn, to second order in the interval's rotation for the scale)."""
    cfg = ctx.cfg
    if near is None:
        rot = interval_rotations(ctx.plan, q_GX=q_GS, scale_factor_error=m, drift=b_ref)
    else:
        rot0, q0, m0 = near
        turn = rotations.quat_to_dcm(rotations.quat_multiply(rotations.quat_conjugate(q0), q_GS)).T
        rv = (1.0 + m0) / (1.0 + m) * rot0.rotvec_rad @ turn.T
        rot = dataclasses.replace(rot0, q=rotations.rotvec_to_quat(rv), rotvec_rad=rv)
    on = correction_flags(rot.max_rate_rad_s, rot.valid, cfg.rate_threshold_rad_s)
    rate_map = rotations.quat_to_dcm(rotations.quat_conjugate(q_GS)) / (1.0 + m)
    obs = run_drift_observer(
        ctx.t_st, ctx.q_st, rot.q, rot.rotvec_rad, rot.valid, on, rate_map=rate_map, drift_ref_rad_s=b_ref,
        t_r_s=cfg.t_r_s, xi=cfg.xi, acquisition=cfg.acquisition, trend_window_s=cfg.trend_window_s,
        trend_degree=cfg.trend_degree,
    )
    return rot, rate_map, obs


def _end_drift(ctx: _Context, obs: DriftObserverResult) -> tuple[FloatArray, DriftTrend, NDArray[np.bool_]]:
    """The drift at the end of the data (trend of the usable estimates of the last trend window), that
    trend and the samples it was fitted to."""
    cfg, t_st = ctx.cfg, ctx.t_st
    usable = (obs.mode == MODE_CORRECTED) & obs.stationary
    last = usable & (t_st >= t_st[-1] - cfg.trend_window_s)
    if not np.any(last):
        last = usable
    trend = fit_drift_trend(t_st[last], obs.drift_rad_s[last], cfg.trend_degree).shifted(ctx.lag)
    return trend(t_st[-1]), trend, last


@dataclass(frozen=True)
class _Passes:
    """Step 5: the last pass, the history of every pass (pass 0 first) and whether the changes fell
    below the tolerance."""

    last: _Pass
    history: tuple[dict[str, object], ...]
    converged: bool


def iterate_passes(ctx: _Context, est: AlignmentEstimate, report: Callable[[float, str], None]) -> _Passes:
    """Steps 4-5: passes until every change is below ``change_tolerance`` sigmas (at most max_iterations)."""
    history: list[dict[str, object]] = [{
        "iteration": 0, "misalignment_rad": est.misalignment_rad.tolist(),
        "scale_factor_error": est.scale_factor_error, "change_sigma": float("inf"),
    }]
    model: DriftTrend | None = None
    last: _Pass | None = None
    for it in range(1, ctx.cfg.max_iterations + 1):
        last = _pass(it, ctx, est, model, report)
        history.append(last.record)
        est, model = last.est, last.model
        if last.change < ctx.cfg.change_tolerance:
            return _Passes(last, tuple(history), True)
    assert last is not None
    return _Passes(last, tuple(history), False)


@dataclass(frozen=True)
class _DriftSummary:
    """The drift at the end of the data [rad/s] (trend of the last window), the noise of the corrected
    estimates about the whole-span model, the convergence time [s] (NaN if never), the sigma of the end
    drift [rad/s] and the correlation time of the estimates [s] (per axis)."""

    end_rad_s: FloatArray
    noise_rad_s: FloatArray
    convergence_s: float
    sigma_rad_s: FloatArray
    correlation_time_s: FloatArray


def drift_summary(ctx: _Context, passes: _Passes) -> _DriftSummary:
    """The reported drift, its noise, sigma and convergence time from the last observer run."""
    cfg, t_st, p = ctx.cfg, ctx.t_st, passes.last
    obs, usable, model = p.obs, p.usable, p.model
    last = usable & (t_st >= t_st[-1] - cfg.trend_window_s)
    end_trend = (fit_drift_trend(t_st[last], obs.drift_rad_s[last], cfg.trend_degree).shifted(ctx.lag)
                 if np.any(last) else model)
    dev = obs.drift_rad_s[usable] - model(t_st[usable])
    noise = np.std(dev, axis=0) if dev.shape[0] > 1 else np.full(3, np.nan)
    corrected = obs.mode == MODE_CORRECTED
    conv = drift_convergence_time(t_st, obs.drift_rad_s, corrected, model(t_st), cfg.convergence_tolerance_rad_s)
    sigma, tau, shift = _end_drift_sigma(ctx, p, last, end_trend)
    return _DriftSummary(end_trend(t_st[-1]) + shift, noise, conv, sigma, tau)


def _end_drift_sigma(ctx: _Context, p: _Pass, last: NDArray[np.bool_], trend: DriftTrend
                     ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Sigma (3,) of the end-of-data drift trend, the correlation time (3,) of the estimates and the
    change (3,) of the end drift from the observer's calibration to the final one (G of term ii).

    The trend's end value is a linear functional L of the estimates b_k of the last window (LSQ polynomial
    of the trend's degree). Two error terms: (i) the estimates' noise about the trend, correlated with
    rho(dt) = exp(-|dt| / tau), tau from their lag-1 autocorrelation (the observer is a low-pass filter
    of time constant ~T_r); (ii) the apparent drift of the calibration errors, (1 + m) R(q_GS)
    (dm w_k - w_k x dtheta) at the samples' rates, through the same L, with the alignment's covariance.
    NaN when the drift is not determined."""
    est = p.est
    t = ctx.t_st[last]
    if t.size < 3 or not np.all(est.drift_observable):
        return np.full(3, np.nan), np.full(3, np.nan), np.zeros(3)
    x = (t - trend.t_ref_s) / trend.scale_s
    x_end = (ctx.t_st[-1] + ctx.lag - trend.t_ref_s) / trend.scale_s
    powers = np.arange(trend.degree + 1)
    func = (x_end**powers) @ np.linalg.pinv(x[:, None] ** powers)  # (n,): end value = func @ b
    dev = p.obs.drift_rad_s[last] - trend(t - ctx.lag)
    s2 = np.mean(dev**2, axis=0)
    rho1 = np.sum(dev[1:] * dev[:-1], axis=0) / np.maximum(np.sum(dev**2, axis=0), 1e-300)
    t_o = ctx.t_o
    tau = np.where(rho1 > 0, -t_o / np.log(np.clip(rho1, 1e-12, 1.0 - 1e-12)), 0.0)
    dt = np.abs(t[:, None] - t[None, :])
    var_noise = np.array([s2[a] * (func @ np.exp(-dt / max(tau[a], 1e-9 * t_o)) @ func) for a in range(3)])
    sens, cov = _calibration_sensitivity(ctx, p)
    var_cal = np.diag(sens @ cov @ sens.T)
    # (iii) never below the sigma of the constant drift that the window rate comparisons determine on their
    # own (the alignment's joint drift offset): the observer's estimate also carries errors of the chain
    # that (i)-(ii) do not model (e.g. slew transients of the integration); on the one-axis arcs of
    # bench/alignment_observability.py (i)-(ii) alone covered 90-93 % of the drift components within 3 sigma
    floor = np.nan_to_num(est.drift_offset_sigma_rad_s)
    # the observer ran with the last-but-one calibration: move the end drift to the final one (linear)
    d_theta = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(p.q_GS_in), est.q_GS))
    shift = sens @ np.concatenate([[est.scale_factor_error - p.m_in], d_theta])
    return np.maximum(np.sqrt(var_noise + var_cal), floor), tau, shift


SENSITIVITY_STEP_SCALE = 1e-4
"""Step of the finite differences of :func:`_calibration_sensitivity` in the scale factor; the misalignment
step is the same number in rad (20"): linear regime of the observer, far above round-off."""


def _calibration_sensitivity(ctx: _Context, p: _Pass) -> tuple[FloatArray, FloatArray]:
    """Variance (3,) of the end drift due to the calibration errors: the observer absorbs the apparent
    drift (1 + m) R(q_GS) (dm w - w x dtheta) while it corrects, and keeps what it absorbed during a scan
    through the following holds, so its response is that of the whole chain: G = d(end drift) / d(m,
    theta) by finite differences of the last observer run (4 more observer runs on mapped interval
    rotations, :func:`_observer_run`; theta as q_GS o exp(theta)).
    Returns G (3, 4) and the covariance (4, 4) of (m, theta) on the determinable subspace."""
    est = p.est
    n_m = est.covariance.shape[0] - 3 - 3 * (est.drift_offset.degree + 1)
    if n_m != 1:  # per-axis factors: the chain applies the scalar one; its variance is scale_factor_sigma^2
        cov = np.zeros((4, 4))
        cov[0, 0] = est.scale_factor_sigma**2
        cov[1:, 1:] = est.covariance[n_m : n_m + 3, n_m : n_m + 3]
    else:
        cov = est.covariance[:4, :4]
    base, _, _ = _end_drift(ctx, p.obs)
    h = SENSITIVITY_STEP_SCALE
    sens = np.zeros((3, 4))
    for k in range(4):  # 4 observer runs, each vectorised over the samples
        q, m = p.q_GS_in, p.m_in
        if k == 0:
            m = m + h
        else:
            q = rotations.quat_multiply(q, rotations.rotvec_to_quat(h * np.eye(3)[k - 1]))
        _, _, obs = _observer_run(ctx, q, m, p.b_ref, near=(p.rot, p.q_GS_in, p.m_in))
        sens[:, k] = (_end_drift(ctx, obs)[0] - base) / h
    return sens, np.nan_to_num(cov)


def pass_slew_report(ctx: _Context, passes: _Passes, drift_noise_rad_s: FloatArray) -> SlewReport:
    """Slews of the last observer run with their error bounds from the 3-sigma calibration errors."""
    cfg, est = ctx.cfg, passes.last.est
    st_noise = ctx.windows.st_noise_rad
    att_sd, _ = stationary_noise(ctx.t_o, cfg.t_r_s, float(np.sqrt(np.mean(st_noise**2))), cfg.xi)
    sig_th = np.nan_to_num(est.misalignment_sigma_rad, nan=cfg.max_misalignment_sigma_rad)
    bound_terms = {
        "initial_error_rad": 3.0 * float(np.sqrt(3.0)) * att_sd,
        "drift_error_rad_s": 3.0 * float(np.linalg.norm(drift_noise_rad_s)),
        "scale_factor_error": 3.0 * est.scale_factor_sigma,
        "misalignment_error_rad": 3.0 * float(np.linalg.norm(sig_th)),
    }
    return slew_report(passes.last.obs, passes.last.rot, bound_terms)

