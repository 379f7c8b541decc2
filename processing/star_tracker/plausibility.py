"""Plausibility of star-tracker quaternions against gyro rates, and the time-tag offset between them.

Beyond 003 (its data model: star-tracker q_IS every few seconds, gyro rates in between, 003 §1.4 compares
the two rates). A star-tracker upload can be read under a wrong convention and still pass every check of
its own (unit norm, increasing times): scalar-last values under q0..q3 headers, q_SI given instead of q_IS,
a mounting q_BS entered as q_SB. The gyro tells: the relative rotation between consecutive star-tracker
samples must be the one the gyro integrates over the same interval.

Model. For consecutive star-tracker samples n, n+1 (no gap) the measured relative rotation is
dQ_n = q_n^-1 o q_{n+1} (sensor axes at t_n). The gyro's is dU_n(tau) = U(t_n + tau)^-1 o U(t_{n+1} + tau),
U the attitude propagated on the gyro grid by 003 §2.3 scheme 2 (exact partial steps between nodes),
turned into the sensor axes by q_SG = q_BS^-1 o q_BG. tau is the time-tag offset: a star-tracker sample
tagged t was taken at t + tau on the gyro's clock (as in processing.definitive: q_IS(t_tag) =
q_IB(t_tag + tau) o q_BS). The residual rotation e_n = rotvec(dU_n,S(tau)^-1 o dQ_n) is, for the right
convention,

    e_n = c dt_n + K theta_n + noise_n,    noise_n = nu_{n+1} - nu_n + g_n,

c = -b_S the gyro offset (w_meas = w + b) in sensor axes (003's Delta), K a small calibration error of the
gyro (scale factors and misalignment; theta_n the gyro's rotation vector over the interval), nu the
star-tracker noise (white, per sensor axis) and g_n the integrated gyro noise (white, N² dt_n per axis for
an angle random walk N). The noise is MA(1): lag-0 variance 2 sigma² + N² dt, lag-1 covariance -sigma².

Steps of :func:`check_star_tracker_gyro`:

1. Conventions. Each of the eight combinations of {order as given, scalar last} x {q_IS, q_SI} x
   {q_BS, q_SB} is fitted with (c, tau) (tau on a grid over +-max_time_offset_s) on at most
   ``CANDIDATE_INTERVALS`` intervals, and scored by the generalised variance of its residuals,
   det(sum e e^T / P) (the Gaussian likelihood with a free 3x3 noise covariance, log L = -P/2 log det + const:
   made for the anisotropic star-tracker noise whatever axes a reading turns it into, and unchanged when a
   reading merely rotates the noise, so that no reading wins on noise alone, e.g. without motion). When the
   reading as given scores at least ``CONVENTION_RATIO_MIN`` times worse than the best one, the best one is
   reported (``quaternion_convention``), with the readings the data cannot tell from it (within that factor:
   e.g. the transposed mounting when q_BS is close to its own transpose).
   ``convention_determined``: every reading that is not the same rotation scores that much worse.
   Rates that hardly change (a constant rate about a fixed axis, an inertial hold) cannot tell some
   conventions apart: a wrong one then differs by a constant rate that a gyro offset absorbs.
2. Time offset. On the best convention, Gauss-Newton on (c, K, tau), K with a Gaussian prior of
   ``CALIBRATION_PRIOR`` per entry (so that calibration errors of a few 0.1 %, e.g. 000's agile
   satellite, do not look like implausible data while a wrong mounting cannot hide in K), on at most
   ``max_intervals`` intervals (contiguous blocks). Per-axis weights from the residuals; the covariance is
   the sandwich with the lag-0 and lag-1 residual products (exact for MA(1) noise), so sigma_tau comes from
   the residuals, not from an assumed noise. tau is determined when sigma_tau <= time_offset_sigma_max_s;
   its information comes from the rate changes only (a constant rate turns a time offset into a constant
   attitude offset).
3. Consistency. Per sensor axis the residual mean square against the noise it should be:
   2 sigma_st² + N² dt, sigma_st² = -(lag-1 autocovariance of the residuals) (the star-tracker noise seen
   by the data themselves) and N from the gyro's second differences. A smooth systematic disagreement has a
   positive lag-1 autocovariance, so it cannot pass as noise. ``consistency_ratio`` above
   ``CONSISTENCY_MAX`` means the data disagree beyond noise under the best convention: ``implausible_input``.

Warnings (processing.tasks.ResultWarning, in ``PlausibilityResult.warnings``): ``quaternion_convention``
naming the convention that fits and how to re-upload; ``implausible_input`` with the numbers; ``time_offset``
when |tau| > 3 sigma and above ``TIME_OFFSET_MIN_S``. A job that reports the offset adds
``PlausibilityResult.not_observable_warning()`` when the data do not determine it. Clean data raise none
(tests/processing/star_tracker/test_plausibility.py measures it).

Cost: O(N) in the gyro samples (one prefix product of the step quaternions) plus 8 x 41 grid evaluations on
at most 2,000 intervals and a few Gauss-Newton steps on at most ``max_intervals``: ~0.05 s for 20 min of 003
data, ~1.3 s for 24 h of a 10 Hz gyro and a 1 Hz tracker.

Times int64 TAI ns; angles rad; rates rad/s; quaternions scalar first, Hamilton, q_AB maps B to A.
Gyro increments (da over an interval) can be passed as rates da/interval_s at the interval midpoints.

The readings (``Convention``, ``CONVENTIONS``, ``apply_convention``), the gyro attitude, the residuals and the
fits of steps 1 and 2 are in :mod:`processing.star_tracker.plausibility_fit`; this module holds the check, its
result and its warnings.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.star_tracker.plausibility_fit import (
    CONVENTION_RATIO_MIN,
    CONVENTIONS,
    Convention,
    GridFit,
    GyroAttitude,
    block_indices,
    candidate_rotations,
    final_fit,
    pair_intervals,
    rank_conventions,
    spread_indices,
)
from processing.tasks import ResultWarning
from processing.units import ARCSEC_PER_RAD, NS_PER_S

__all__ = [
    "ConventionFit",
    "PlausibilityError",
    "PlausibilityResult",
    "check_star_tracker_gyro",
]

FloatArray = NDArray[np.float64]


def _finite(x: float) -> float | None:
    """JSON has no infinity: None for a non-finite number."""
    return float(x) if np.isfinite(x) else None


CONSISTENCY_MAX = 4.0
"""Residual mean square per axis above this many times the expected noise (rms 2x) is implausible."""
TIME_OFFSET_MIN_S = 1e-3
"""A time offset below this is not worth a warning, however significant."""
CANDIDATE_INTERVALS = 2000
"""Intervals used to compare the conventions (evenly spread); the final fit uses up to max_intervals."""
TAU_GRID_STEP_S = 0.05
"""Step of the grid search of the time offset (then refined by Gauss-Newton)."""


class PlausibilityError(ValueError):
    """Bad input to the plausibility check: shapes, too few samples, no overlap of the two time grids."""


@dataclass(frozen=True)
class ConventionFit:
    """A tested convention: its generalised residual variance relative to the best one's (``fit_ratio`` = 1
    for the best), its residual rms per sensor axis (rad per interval), the time offset and gyro offset (gyro
    frame) it would imply."""

    convention: Convention
    fit_ratio: float
    residual_rms_rad: FloatArray
    time_offset_s: float
    gyro_bias_G_rad_s: FloatArray


@dataclass(frozen=True)
class PlausibilityResult:
    """Result of :func:`check_star_tracker_gyro`.

    warnings: ResultWarning list (empty for clean data); convention: name of the best-fitting convention
    (``as_given`` unless another fits clearly better); convention_determined: whether the rates tell the
    conventions apart; candidates: every tested convention, best first; time_offset_s / _sigma_s (None
    when not determined: time_offset_observable False); gyro_bias_G_rad_s (3,) the offset b of w_meas =
    w + b in the gyro frame (an estimate from the increments, for orientation; gyro_bias_fit is the
    estimator); rate_disagreement_rms_rad_s (3,) residual rms per interval / mean interval, sensor axes;
    expected_noise_rms_rad_s (3,) the same for the noise model; consistency_ratio (3,) residual mean square
    over the expected one; star_tracker_noise_rad (3,) sigma_st per sensor axis from the lag-1
    autocovariance; gyro_arw_rad_sqrt_s (3,) per gyro axis; calibration (3, 3) the fitted K;
    n_intervals used by the final fit; mean_interval_s.
    """

    warnings: list[ResultWarning]
    convention: str
    convention_determined: bool
    candidates: tuple[ConventionFit, ...]
    time_offset_s: float | None
    time_offset_sigma_s: float | None
    time_offset_observable: bool
    gyro_bias_G_rad_s: FloatArray
    rate_disagreement_rms_rad_s: FloatArray
    expected_noise_rms_rad_s: FloatArray
    consistency_ratio: FloatArray
    star_tracker_noise_rad: FloatArray
    gyro_arw_rad_sqrt_s: FloatArray
    calibration: FloatArray
    n_intervals: int
    mean_interval_s: float
    time_offset_estimate_s: float = 0.0
    """The estimate and its sigma (inf when the rates carry no information) even when not determined."""
    time_offset_sigma_estimate_s: float = np.inf
    time_offset_sigma_max_s: float = 0.1

    def not_observable_warning(self) -> ResultWarning | None:
        """The ``not_observable`` warning a job that reports time_offset_s adds when it is null (else None).

        Not in ``warnings``: a job that does not report the offset has nothing undetermined to declare."""
        if self.time_offset_observable:
            return None
        return ResultWarning(
            "not_observable",
            f"the rates change too little to determine the star-tracker time offset against the gyro (sigma "
            f"{self.time_offset_sigma_estimate_s:.3g} s > {self.time_offset_sigma_max_s:g} s): time_offset_s is null",
            {"parameters": ["time_offset_s"], "time_offset_sigma_s": _finite(self.time_offset_sigma_estimate_s),
             "sigma_max_s": self.time_offset_sigma_max_s},
        )

    def summary(self) -> dict[str, Any]:
        """JSON-able summary, units in the keys (rates in arcsec/s, the offset in s)."""
        a = ARCSEC_PER_RAD

        def floats(x: FloatArray) -> list[float]:
            return [float(v) for v in np.asarray(x, dtype=np.float64).reshape(-1)]

        return {
            "convention": self.convention,
            "convention_determined": self.convention_determined,
            "time_offset_s": self.time_offset_s,
            "time_offset_sigma_s": self.time_offset_sigma_s,
            "time_offset_observable": self.time_offset_observable,
            "gyro_bias_G_rad_s": floats(self.gyro_bias_G_rad_s),
            "rate_disagreement_rms_arcsec_s": floats(self.rate_disagreement_rms_rad_s * a),
            "expected_noise_rms_arcsec_s": floats(self.expected_noise_rms_rad_s * a),
            "consistency_ratio": floats(self.consistency_ratio),
            "star_tracker_noise_arcsec": floats(self.star_tracker_noise_rad * a),
            "n_intervals": self.n_intervals,
            "mean_interval_s": self.mean_interval_s,
            "candidates": [{"convention": c.convention.name, "fit_ratio": c.fit_ratio,
                            "residual_rms_arcsec": floats(c.residual_rms_rad * a),
                            "time_offset_s": c.time_offset_s} for c in self.candidates],
        }


# ---------------------------------------------------------------------------------------------------
# The check.


def _inputs(t_st_ns: ArrayLike, q_IS: ArrayLike, q_BS: ArrayLike, t_gyro_ns: ArrayLike, w_G: ArrayLike,
            q_BG: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    ts = np.asarray(t_st_ns)
    tg = np.asarray(t_gyro_ns)
    if ts.dtype.kind not in "iu" or tg.dtype.kind not in "iu":
        raise PlausibilityError(f"times must be integer TAI nanoseconds, got dtypes {ts.dtype} and {tg.dtype}")
    q = np.asarray(q_IS, dtype=np.float64)
    w = np.asarray(w_G, dtype=np.float64)
    if ts.ndim != 1 or q.shape != (ts.size, 4):
        raise PlausibilityError(f"need t_st_ns (M,) and q_IS (M, 4), got {ts.shape} and {q.shape}")
    if tg.ndim != 1 or w.shape != (tg.size, 3) or tg.size < 8:
        raise PlausibilityError(f"need t_gyro_ns (N,) and w_G (N, 3) with N >= 8, got {tg.shape} and {w.shape}")
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(w))):
        raise PlausibilityError("quaternions and rates must be finite")
    if np.any(np.diff(ts) <= 0) or np.any(np.diff(tg) <= 0):
        raise PlausibilityError("star-tracker and gyro times must be strictly increasing")
    m_bs, m_bg = np.asarray(q_BS, dtype=np.float64), np.asarray(q_BG, dtype=np.float64)
    if m_bs.shape != (4,) or m_bg.shape != (4,):
        raise PlausibilityError(f"q_BS and q_BG must have shape (4,), got {m_bs.shape} and {m_bg.shape}")
    epoch = int(tg[0])
    t_s = (ts.astype(np.int64) - epoch).astype(np.float64) / NS_PER_S
    t_g = (tg.astype(np.int64) - epoch).astype(np.float64) / NS_PER_S
    return (t_s, rotations.quat_normalize(q), rotations.quat_normalize(m_bs), t_g, w,
            rotations.quat_normalize(m_bg))


def _choose_convention(fits: list[GridFit]) -> tuple[Convention, bool, float, float]:
    """Step 1's verdict on the ranked grid fits: (the convention the final fit uses, whether it is another
    than the one given, how many times worse the one given fits, the grid offset to start from)."""
    best = fits[0]
    given_ratio = next(f[1] for f in fits if f[0].convention.name == "as_given") / max(best[1], 1e-300)
    switch = best[0].convention.name != "as_given" and given_ratio >= CONVENTION_RATIO_MIN
    chosen = best[0].convention if switch else CONVENTIONS[0]
    tau0 = best[2] if switch else next(f[2] for f in fits if f[0].convention.name == "as_given")
    return chosen, switch, given_ratio, tau0


def _noise_check(r: FloatArray, next_shared: NDArray[np.bool_], dt: FloatArray,
                 arw_S: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Step 3 per sensor axis: (residual mean square, sigma_st² from the lag-1 autocovariance, the mean square
    the noise should give: 2 sigma_st² + N² dt)."""
    ms = np.mean(r**2, axis=0)
    lag1 = r[:-1][next_shared[:-1]] * r[1:][next_shared[:-1]]
    sigma_st2 = np.maximum(-np.mean(lag1, axis=0), 0.0) if lag1.size else np.zeros(3)
    expected = 2.0 * sigma_st2 + arw_S**2 * float(np.mean(dt))
    return ms, sigma_st2, expected


def _convention_fits(fits: list[GridFit]) -> tuple[ConventionFit, ...]:
    """Every tested convention's grid fit as a ConventionFit, best first."""
    best = fits[0]
    return tuple(
        ConventionFit(convention=f[0].convention, fit_ratio=float(f[1] / max(best[1], 1e-300)),
                      residual_rms_rad=np.sqrt(np.mean(f[4] ** 2, axis=0)), time_offset_s=f[2],
                      gyro_bias_G_rad_s=-(rotations.quat_to_dcm(f[0].q_SG).T @ f[3]))
        for f in fits
    )


def check_star_tracker_gyro(
    t_st_ns: ArrayLike,
    q_IS: ArrayLike,
    q_BS: ArrayLike,
    t_gyro_ns: ArrayLike,
    w_G: ArrayLike,
    q_BG: ArrayLike = (1.0, 0.0, 0.0, 0.0),
    *,
    sensor: str = "star tracker",
    max_time_offset_s: float = 1.0,
    time_offset_sigma_max_s: float = 0.1,
    max_intervals: int = 20_000,
) -> PlausibilityResult:
    """Do the star-tracker quaternions agree with the gyro rates, under which convention, at which time offset?

    t_st_ns (M,) int64 TAI ns, strictly increasing; q_IS (M, 4) as stored (sensor -> inertial, scalar first);
    q_BS (4,) the configured mounting (sensor -> body); t_gyro_ns (N,) int64 TAI ns; w_G (N, 3) rad/s in the
    gyro frame; q_BG (4,) gyro -> body. sensor: the tracker's name for the messages. max_time_offset_s: the
    time offset is searched within +-this; time_offset_sigma_max_s: above this sigma the offset counts as
    not determined; max_intervals: the final fit uses at most this many star-tracker intervals (contiguous
    blocks; 24 h of 1 Hz data are decimated). See the module docstring for the model and the tests.
    Returns :class:`PlausibilityResult`; raises :class:`PlausibilityError` on bad input or when fewer than
    10 usable intervals lie within the gyro span.
    """
    t_s, q, m_bs, t_g, w, m_bg = _inputs(t_st_ns, q_IS, q_BS, t_gyro_ns, w_G, q_BG)
    if not max_time_offset_s > 0 or not time_offset_sigma_max_s > 0:
        raise PlausibilityError("max_time_offset_s and time_offset_sigma_max_s must be > 0")
    gyro = GyroAttitude.build(t_g, w)
    step_g = float(np.median(np.diff(t_g)))
    delta_s = 2.0 * step_g
    iv_all = pair_intervals(t_s, gyro, max_time_offset_s + 2.0 * delta_s)
    if iv_all.t_a.size < 10:
        raise PlausibilityError(
            f"need at least 10 pairs of consecutive star-tracker samples within the gyro span, got {iv_all.t_a.size}")
    n_grid = int(np.ceil(max_time_offset_s / TAU_GRID_STEP_S))
    taus = np.linspace(-max_time_offset_s, max_time_offset_s, 2 * n_grid + 1)

    iv_c = iv_all.take(spread_indices(iv_all.t_a.size, CANDIDATE_INTERVALS))
    fits, determined = rank_conventions(gyro, iv_c, candidate_rotations(q, m_bs, m_bg, iv_c), taus)
    chosen, switch, given_ratio, tau0 = _choose_convention(fits)

    iv = iv_all.take(block_indices(iv_all.t_a.size, max_intervals))
    cand = candidate_rotations(q, m_bs, m_bg, iv)[CONVENTIONS.index(chosen)]
    r_SG = rotations.quat_to_dcm(cand.q_SG)
    arw_S = np.sqrt(np.einsum("ij,j,ij->i", r_SG, gyro.arw**2, r_SG))
    fin = final_fit(gyro, iv, cand, tau0, delta_s, max_time_offset_s, arw_S)

    dt = iv.dt
    ms, sigma_st2, expected = _noise_check(fin.r, iv.next_shared, dt, arw_S)
    ratio = ms / np.maximum(expected, 1e-300)
    observable = bool(np.isfinite(fin.tau_sigma) and fin.tau_sigma <= time_offset_sigma_max_s)
    bias_G = -(r_SG.T @ fin.c)
    mean_dt = float(np.mean(dt))

    result = PlausibilityResult(
        warnings=[],
        convention=chosen.name,
        convention_determined=determined,
        candidates=_convention_fits(fits),
        time_offset_s=fin.tau if observable else None,
        time_offset_sigma_s=fin.tau_sigma if observable else None,
        time_offset_observable=observable,
        gyro_bias_G_rad_s=bias_G,
        rate_disagreement_rms_rad_s=np.sqrt(ms) / mean_dt,
        expected_noise_rms_rad_s=np.sqrt(expected) / mean_dt,
        consistency_ratio=ratio,
        star_tracker_noise_rad=np.sqrt(sigma_st2),
        gyro_arw_rad_sqrt_s=gyro.arw,
        calibration=fin.k,
        n_intervals=int(dt.size),
        mean_interval_s=mean_dt,
        time_offset_estimate_s=fin.tau,
        time_offset_sigma_estimate_s=fin.tau_sigma,
        time_offset_sigma_max_s=time_offset_sigma_max_s,
    )
    warnings = _warnings(result, sensor, switch, given_ratio)
    return replace(result, warnings=warnings)


# ---------------------------------------------------------------------------------------------------
# Warnings.


def _repair(conv: Convention, sensor: str) -> str:
    steps = []
    if conv.scalar_last:
        steps.append("the columns hold (x, y, z, w): upload them with the header qx, qy, qz, qw (qw is the "
                     "scalar), not q0..q3")
    if conv.inverse:
        steps.append("the values are q_SI (inertial -> sensor): upload with quaternion_direction=inertial_to_sensor")
    if conv.transposed_mounting:
        steps.append(f"the configured q_BS of {sensor} is q_SB: store its conjugate in star_trackers.{sensor}.q_BS "
                     "(PUT /api/v1/spacecraft/{name}/config)")
    return "; ".join(steps)


def _warnings(res: PlausibilityResult, sensor: str, switch: bool, given_ratio: float) -> list[ResultWarning]:
    out: list[ResultWarning] = []
    a = ARCSEC_PER_RAD
    given = next(c for c in res.candidates if c.convention.name == "as_given")
    if switch:
        conv = res.candidates[0].convention
        quat_fix = conv.scalar_last or conv.inverse
        # readings the rates cannot tell from the best (not those that are the same rotation: a mounting equal
        # to its own transpose)
        near = [c for c in res.candidates[1:] if 1.0 + 1e-9 < c.fit_ratio < CONVENTION_RATIO_MIN]
        alike = [c.convention.name for c in near]
        also = (f" (these rates cannot tell it from {', '.join(alike)}, which fit"
                f" {', '.join(f'{c.fit_ratio:.3g}' for c in near)} times worse)" if near else "")
        out.append(ResultWarning(
            "quaternion_convention",
            f"{sensor}: the star-tracker quaternions agree with the gyro only as {conv.name}{also} (the data as given "
            f"fit {given_ratio:.3g} times worse, residual rms {np.round(given.residual_rms_rad * a, 1).tolist()} "
            f"arcsec per interval against {np.round(res.candidates[0].residual_rms_rad * a, 1).tolist()}): "
            + _repair(conv, sensor)
            + (" (retract the upload first: DELETE /api/v1/spacecraft/{name}/ingests/{id})" if quat_fix else ""),
            {"sensor": sensor, "convention": conv.name, "fit_ratio_as_given": given_ratio,
             "residual_rms_as_given_arcsec": [float(x) for x in given.residual_rms_rad * a],
             "residual_rms_arcsec": [float(x) for x in res.candidates[0].residual_rms_rad * a],
             "alike": alike, "candidates": {c.convention.name: c.fit_ratio for c in res.candidates}},
        ))
    if np.max(res.consistency_ratio) > CONSISTENCY_MAX:
        out.append(ResultWarning(
            "implausible_input",
            f"{sensor}: the star-tracker rates disagree with the gyro rates by "
            f"{np.round(res.rate_disagreement_rms_rad_s * a, 2).tolist()} arcsec/s rms (sensor axes), "
            f"{np.round(np.sqrt(res.consistency_ratio), 1).tolist()} times the noise of both sensors, under "
            f"{'every tested convention' if not switch else 'the best convention ' + res.convention}: check the "
            "mountings (q_BS, q_BG), the gyro units (rad/s) and the time tags",
            {"sensor": sensor, "convention": res.convention,
             "rate_disagreement_rms_arcsec_s": [float(x) for x in res.rate_disagreement_rms_rad_s * a],
             "expected_noise_rms_arcsec_s": [float(x) for x in res.expected_noise_rms_rad_s * a],
             "consistency_ratio": [float(x) for x in res.consistency_ratio], "consistency_max": CONSISTENCY_MAX,
             "candidates": {c.convention.name: c.fit_ratio for c in res.candidates}},
        ))
    if res.time_offset_observable and res.time_offset_s is not None and res.time_offset_sigma_s is not None:
        if abs(res.time_offset_s) > max(3.0 * res.time_offset_sigma_s, TIME_OFFSET_MIN_S):
            out.append(ResultWarning(
                "time_offset",
                f"{sensor}: the star-tracker samples were taken {1e3 * abs(res.time_offset_s):.1f} ± "
                f"{1e3 * res.time_offset_sigma_s:.1f} ms {'after' if res.time_offset_s > 0 else 'before'} their "
                "time tags, on the gyro's clock (time_offset_s "
                f"{res.time_offset_s:+.4f} s; true time = "
                "tag + time_offset_s): correct the time tags, or let the job estimate the offset (gyro_bias_fit: "
                "fit_time_offset; definitive_attitude: estimate_time_offset)",
                {"sensor": sensor, "time_offset_s": res.time_offset_s, "sigma_s": res.time_offset_sigma_s,
                 "threshold_s": max(3.0 * res.time_offset_sigma_s, TIME_OFFSET_MIN_S)},
            ))
    return out
