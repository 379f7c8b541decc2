"""Realistic-telemetry mode of the seed-003 simulator: what a real downlink does to the clean streams.

Real attitude telemetry (issue 23: a day of a large crewed station, about 1 Hz) differs from the
clean seed-003 scenario (processing.simulate.seed003) in ways that break naive processing:

- **quantisation**: every value is a multiple of its least significant bit (``*_lsb``): quaternion
  components, gyro rates, GNSS positions and velocities are rounded to their LSB;
- **irregular sampling**: each time tag is the nominal grid time plus a uniform jitter of
  +-``jitter_fraction`` of the period (the samples are taken at the tags: jitter is not an error);
- **dropouts**: each sample is lost independently with probability ``dropout_probability`` (many
  one- or two-sample gaps), plus ``n_long_gaps`` gaps per stream of 2..``long_gap_max_s`` s (the
  longest exactly ``long_gap_max_s``), placed at random, never at the ends;
- **a yaw manoeuvre**: a rotation by ``manoeuvre_angle_rad`` about the orbital axis 3 (the local
  vertical) with a cycloidal profile (zero rate and acceleration at both ends) of
  ``manoeuvre_duration_s``, starting at ``manoeuvre_start_s`` (None: no manoeuvre);
- **late GNSS time tags**: in ``n_late_blocks`` runs of ``late_block_s`` s the GNSS state reported
  at tag t is the state of t - ``late_tag_s`` (the receiver stamped an old fix with the current
  time: 3.4 s in the recorded data).

The attitude model is seed 003's (orbit, slow oscillations, 0.4 Hz vibration, the 003 mounting,
star-tracker noise about the sensor axes, gyro bias and noise, GNSS noise), with the manoeuvre
composed on the orbital side: q_OB = q_z(psi(t)) o q_OB,003(pitch, yaw, roll), so that psi is the
yaw of a 3-2-1 (yaw, pitch, roll) sequence. Body rate w_B = R_BO (w_IO + psi' e3) + w_OB,003 --
exact (the kinematics hold to rounding). Deterministic per ``seed``; pure; no I/O.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
from numpy.random import PCG64, Generator, SeedSequence
from numpy.typing import NDArray

from processing.attitude import rotations
from processing.frames.earth_orientation import EarthOrientation, gcrs_to_itrs_state
from processing.orbits.two_body import sun_synchronous_inclination_rad
from processing.simulate.orbital_attitude_model import AttitudeState, OrbitalAttitudeModel
from processing.simulate.seed003 import (
    GYRO_BIAS_003_RAD_S,
    ST_NOISE_STD_003_RAD,
    ST_SENSOR,
    Seed003ParameterError,
    _seconds,
    _series,
    mounting_q_BS_003,
)
from processing.units import NS_PER_S, R_EARTH_M, RAD_PER_ARCSEC, RAD_PER_DEG

QUATERNION_LSB = 2.0 ** -20
"""Default LSB of a quaternion component (9.5e-7, about 0.4 arcsec of rotation)."""
GYRO_LSB_RAD_S = 2.0 ** -17
"""Default LSB of a gyro rate (7.6e-6 rad/s, 1.6 arcsec/s: the size of the gyro noise)."""
GNSS_POSITION_LSB_M = 1.0
GNSS_VELOCITY_LSB_M_S = 1e-3


@dataclass(frozen=True)
class YawManoeuvre:
    """psi(t) = angle (s - sin(2 pi s) / (2 pi)), s = (t - start) / duration clipped to [0, 1] [rad]."""

    start_s: float
    duration_s: float
    angle_rad: float

    def value_and_rate(self, t_s: NDArray) -> tuple[NDArray, NDArray]:
        s = np.clip((np.asarray(t_s, dtype=float) - self.start_s) / self.duration_s, 0.0, 1.0)
        psi = self.angle_rad * (s - np.sin(2.0 * np.pi * s) / (2.0 * np.pi))
        rate = self.angle_rad / self.duration_s * (1.0 - np.cos(2.0 * np.pi * s))
        return psi, rate

    def interval_s(self) -> tuple[float, float]:
        return self.start_s, self.start_s + self.duration_s


@dataclass(frozen=True)
class ManoeuvreModel:
    """The seed-003 model with a yaw manoeuvre about the orbital axis 3 (module docstring).

    evaluate(t_s) -> AttitudeState whose pitch/yaw/roll are the 2-3-1 angles of the total q_OB and whose
    angle rates are NaN (the manoeuvre is not a 2-3-1 motion); q_OB, q_IB and w_B are exact.
    """

    base: OrbitalAttitudeModel
    manoeuvre: YawManoeuvre | None

    def orbit(self, t_s: NDArray) -> tuple[NDArray, NDArray]:
        return self.base.orbit(t_s)

    def evaluate(self, t_s: NDArray) -> AttitudeState:
        st = self.base.evaluate(t_s)
        if self.manoeuvre is None:
            return st
        psi, psi_dot = self.manoeuvre.value_and_rate(t_s)
        q_z = rotations.quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), psi)
        q_OB = rotations.quat_canonical(rotations.quat_multiply(q_z, st.q_OB))
        q_IB = rotations.quat_canonical(rotations.quat_multiply(st.q_IO, q_OB))
        # rate of the turned orbital frame O' relative to O is psi' e3 (e3 of O = e3 of O'), in B via q_O'B
        extra_B = rotations.quat_rotate(rotations.quat_conjugate(st.q_OB),
                                        np.stack([np.zeros_like(psi), np.zeros_like(psi), psi_dot], axis=-1))
        # the orbit rate w_IO (in O) seen from B through the whole q_OB instead of the 003 part only
        h = np.linalg.norm(np.cross(st.r_I, st.v_I), axis=-1)
        rate = h / np.sum(st.r_I * st.r_I, axis=-1)
        w_IO_O = np.stack([np.zeros_like(rate), rate, np.zeros_like(rate)], axis=-1)
        w_base_OB = st.w_B - rotations.quat_rotate(rotations.quat_conjugate(st.q_OB), w_IO_O)
        w_B = rotations.quat_rotate(rotations.quat_conjugate(q_OB), w_IO_O) + extra_B + w_base_OB
        pitch, yaw, roll = rotations.pitch_yaw_roll_from_quat(q_OB)
        nan = np.full(np.shape(psi), np.nan)
        return AttitudeState(r_I=st.r_I, v_I=st.v_I, q_IO=st.q_IO, q_OB=q_OB, q_IB=q_IB, w_B=w_B,
                             pitch_rad=pitch, yaw_rad=yaw, roll_rad=roll, pitch_rate_rad_s=nan,
                             yaw_rate_rad_s=nan, roll_rate_rad_s=nan)


@dataclass(frozen=True)
class RealisticTruth:
    """Truth of a realistic scenario (times int64 tai_ns; SI).

    st_*: at the star-tracker rows (q_OB, q_IB, q_IS noise-free); gyro_*: at the gyro rows (w_B, bias in G);
    gnss_*: at the GNSS rows, gnss_true_time_tai_ns the time whose state was reported (tag - late_tag_s
    for the late rows), gnss_late (K,) bool, r_E/v_E at the tags (what a correct receiver reports);
    manoeuvre_tai_ns (2,) start/end or None; lsb: the quantisation steps; long_gaps_tai_ns: {stream:
    (G, 2) [last sample before, first after]}.
    """

    model: ManoeuvreModel
    start_tai_ns: int
    q_BS: NDArray
    q_BG: NDArray
    st_time_tai_ns: NDArray
    st_q_OB: NDArray
    st_q_IB: NDArray
    st_q_IS: NDArray
    gyro_time_tai_ns: NDArray
    gyro_w_B: NDArray
    gyro_bias_rad_s: NDArray
    gnss_time_tai_ns: NDArray
    gnss_true_time_tai_ns: NDArray
    gnss_late: NDArray
    r_E: NDArray
    v_E: NDArray
    late_tag_s: float
    manoeuvre_tai_ns: tuple[int, int] | None
    lsb: dict[str, float]
    long_gaps_tai_ns: dict[str, NDArray]


@dataclass(frozen=True)
class RealisticScenario:
    """streams (canonical columns as seed 003's), config (DESIGN.md JSON), truth, parameters."""

    streams: dict[str, dict[str, NDArray]]
    config: dict[str, Any]
    truth: RealisticTruth
    parameters: dict[str, Any]


def quantise(x: NDArray, lsb: float) -> NDArray:
    """x rounded to a multiple of lsb (lsb = 0: unchanged)."""
    return x if lsb <= 0 else np.round(x / lsb) * lsb


def irregular_times(start_tai_ns: int, duration_s: float, period_s: float, jitter_fraction: float,
                    rng: Generator) -> NDArray:
    """Nominal grid start + k period (inside [start, start + duration]) plus uniform jitter of +-jitter_fraction
    period (the first and last tags stay inside the span), int64 ns, strictly increasing."""
    n = int(np.floor(duration_s / period_s + 1e-9)) + 1
    nominal = np.arange(n) * period_s
    jitter = rng.uniform(-jitter_fraction, jitter_fraction, n) * period_s
    t = np.clip(nominal + jitter, 0.0, duration_s)
    return np.int64(start_tai_ns) + np.round(t * NS_PER_S).astype(np.int64)


def dropout_mask(t_ns: NDArray, probability: float, n_long: int, long_max_s: float, rng: Generator
                 ) -> tuple[NDArray, NDArray]:
    """Keep-mask (n,) with single dropouts (independent, ``probability``) and ``n_long`` long gaps of
    uniform 2..long_max_s s (the first exactly long_max_s); returns (keep, (n_long, 2) tai_ns of the last kept
    sample before and first after each long gap). The first and last samples are always kept."""
    n = t_ns.size
    keep = rng.random(n) >= probability
    span_s = (t_ns[-1] - t_ns[0]) / NS_PER_S
    lengths = rng.uniform(2.0, long_max_s, n_long)
    if n_long:
        lengths[0] = long_max_s
    starts = rng.uniform(0.05, 0.95, n_long) * span_s
    for a, length in zip(starts, lengths, strict=True):
        t0 = t_ns[0] + int(a * NS_PER_S)
        keep &= ~((t_ns > t0) & (t_ns < t0 + int(length * NS_PER_S)))
    keep[0] = keep[-1] = True
    kept = t_ns[keep]
    gaps = []
    for a in starts:
        t0 = t_ns[0] + int(a * NS_PER_S)
        i = int(np.searchsorted(kept, t0, side="right")) - 1
        if 0 <= i < kept.size - 1:
            gaps.append((kept[i], kept[i + 1]))
    return keep, np.asarray(gaps, dtype=np.int64).reshape(-1, 2)


def _base_model(altitude_m: float, att: Generator) -> OrbitalAttitudeModel:
    """The station-like orbit (sun-synchronous inclination) and slowly varying orbital attitude of
    :func:`simulate_realistic` (its sine series drawn from ``att``)."""
    a_m = R_EARTH_M + altitude_m
    return OrbitalAttitudeModel(
        a_m=a_m, inc_rad=float(sun_synchronous_inclination_rad(a_m)), raan_rad=100.0 * RAD_PER_DEG,
        u0_rad=20.0 * RAD_PER_DEG,
        pitch=_series(0.0, 0.3 * RAD_PER_DEG, 3.0 * RAD_PER_ARCSEC, 0.4, att),
        yaw=_series(1.2 * RAD_PER_DEG, 0.25 * RAD_PER_DEG, 3.0 * RAD_PER_ARCSEC, 0.4, att),
        roll=_series(0.0, 0.3 * RAD_PER_DEG, 3.0 * RAD_PER_ARCSEC, 0.4, att))


def _check_realistic(jitter_fraction: float, dropout_probability: float, duration_s: float,
                     periods_s: tuple[float, float, float]) -> None:
    """The parameter domains of :func:`simulate_realistic` (Seed003ParameterError naming the parameter)."""
    if not (0.0 <= jitter_fraction < 0.5):
        raise Seed003ParameterError(f"jitter_fraction must be in [0, 0.5), got {jitter_fraction}")
    if not (0.0 <= dropout_probability < 0.5):
        raise Seed003ParameterError(f"dropout_probability must be in [0, 0.5), got {dropout_probability}")
    if duration_s <= 0 or min(periods_s) <= 0:
        raise Seed003ParameterError("duration and periods must be > 0")


def _star_tracker_q(q_IB: NDArray, q_BS: NDArray, rng: Generator, noise_std_rad: tuple[float, float, float],
                    lsb: float) -> tuple[NDArray, NDArray]:
    """(true q_IS, measured q_IS): the true one turned by white noise (per sensor axis), quantised to ``lsb``."""
    q_IS_true = rotations.quat_canonical(rotations.quat_multiply(q_IB, q_BS))
    noise = rng.standard_normal((q_IB.shape[0], 3)) * np.asarray(noise_std_rad)
    q_IS = rotations.quat_canonical(rotations.quat_multiply(q_IS_true, rotations.rotvec_to_quat(noise)))
    return q_IS_true, quantise(q_IS, lsb)


def _late_tags(t_n: NDArray, start_tai_ns: int, duration_s: float, rng: Generator, n_blocks: int, block_s: float,
               late_tag_s: float) -> tuple[NDArray, NDArray]:
    """(late (K,), true fix times (K,)): ``n_blocks`` blocks of ``block_s`` at random starts whose states are those
    of tag - late_tag_s."""
    late = np.zeros(t_n.size, dtype=bool)
    for a in rng.uniform(0.1, 0.9, n_blocks) * duration_s:
        t0 = np.int64(start_tai_ns) + int(a * NS_PER_S)
        late |= (t_n >= t0) & (t_n < t0 + int(block_s * NS_PER_S))
    return late, t_n - np.where(late, int(round(late_tag_s * NS_PER_S)), 0)


def _manoeuvre_tai_ns(man: YawManoeuvre | None, start_tai_ns: int) -> tuple[int, int] | None:
    """(start, end) tai_ns of the manoeuvre, None without one."""
    man_ns = None if man is None else tuple(int(np.int64(start_tai_ns) + round(x * NS_PER_S))
                                            for x in man.interval_s())
    return None if man_ns is None else (man_ns[0], man_ns[1])


def _gnss_states(model: ManoeuvreModel, secs: Callable[[NDArray], NDArray], t_n: NDArray, t_true: NDArray,
                 rng_r: Generator, rng_v: Generator, noise_std: tuple[float, float], lsb: tuple[float, float]
                 ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """(r_E, v_E) true ITRF states at the tags t_n and the measured (r, v): the states of the fix times t_true
    (late tags) plus noise (position, velocity std), quantised to ``lsb``."""
    eop = EarthOrientation()
    r_I_true, v_I_true = model.orbit(secs(t_true))
    r_E_rep, v_E_rep = gcrs_to_itrs_state(r_I_true, v_I_true, t_true, eop)  # Earth-fixed state of the fix time
    r_I_tag, v_I_tag = model.orbit(secs(t_n))
    r_E, v_E = gcrs_to_itrs_state(r_I_tag, v_I_tag, t_n, eop)
    r_meas = quantise(r_E_rep + rng_r.standard_normal(r_E.shape) * noise_std[0], lsb[0])
    v_meas = quantise(v_E_rep + rng_v.standard_normal(v_E.shape) * noise_std[1], lsb[1])
    return r_E, v_E, r_meas, v_meas


def _streams(t_st: NDArray, q_IS: NDArray, t_g: NDArray, w_G: NDArray, t_n: NDArray, r_meas: NDArray,
             v_meas: NDArray) -> dict[str, dict[str, NDArray]]:
    """The telemetry streams (column dicts) of :func:`simulate_realistic`."""
    return {
        "star_tracker": {"time_tai_ns": t_st, **{f"q{i}": q_IS[:, i].copy() for i in range(4)},
                         "sensor": np.full(t_st.size, ST_SENSOR, dtype=object)},
        "gyro": {"time_tai_ns": t_g, **{c: w_G[:, i].copy() for i, c in enumerate(("wx", "wy", "wz"))},
                 "sensor": np.full(t_g.size, "gyro", dtype=object)},
        "gnss": {"time_tai_ns": t_n, **{c: r_meas[:, i].copy() for i, c in enumerate(("x", "y", "z"))},
                 **{c: v_meas[:, i].copy() for i, c in enumerate(("vx", "vy", "vz"))},
                 "sensor": np.full(t_n.size, "gnss", dtype=object)},
    }


def simulate_realistic(
    *,
    start_tai_ns: int,
    duration_s: float = 3600.0,
    seed: int = 0,
    st_period_s: float = 1.0,
    gyro_period_s: float = 1.0,
    gnss_period_s: float = 1.0,
    jitter_fraction: float = 0.2,
    dropout_probability: float = 0.05,
    n_long_gaps: int = 3,
    long_gap_max_s: float = 135.0,
    quaternion_lsb: float = QUATERNION_LSB,
    gyro_lsb_rad_s: float = GYRO_LSB_RAD_S,
    gnss_position_lsb_m: float = GNSS_POSITION_LSB_M,
    gnss_velocity_lsb_m_s: float = GNSS_VELOCITY_LSB_M_S,
    manoeuvre_start_s: float | None = None,
    manoeuvre_duration_s: float = 900.0,
    manoeuvre_angle_rad: float = np.pi,
    late_tag_s: float = 3.4,
    n_late_blocks: int = 2,
    late_block_s: float = 60.0,
    altitude_m: float = 420e3,
    st_noise_std_rad: tuple[float, float, float] = ST_NOISE_STD_003_RAD,
    gyro_bias_rad_s: tuple[float, float, float] = GYRO_BIAS_003_RAD_S,
    gyro_noise_std_rad_s: float = 1.5 * RAD_PER_ARCSEC,
    gnss_position_noise_std_m: float = 1.0,
    gnss_velocity_noise_std_m_s: float = 1e-3,
) -> RealisticScenario:
    """Star tracker, gyro and GNSS telemetry of a station-like spacecraft with real-data defects (module doc).

    Keyword-only; angles rad, rates rad/s, times s except ``start_tai_ns``. manoeuvre_start_s None: no
    manoeuvre; n_late_blocks 0: no late tags; lsb 0: no quantisation; jitter_fraction 0: regular grid.
    """
    parameters = {k: v for k, v in locals().items() if k != "parameters"}
    _check_realistic(jitter_fraction, dropout_probability, duration_s, (st_period_s, gyro_period_s, gnss_period_s))
    rngs = [Generator(PCG64(s)) for s in SeedSequence(seed).spawn(12)]
    base = _base_model(altitude_m, rngs[0])
    man = None if manoeuvre_start_s is None else YawManoeuvre(manoeuvre_start_s, manoeuvre_duration_s,
                                                             manoeuvre_angle_rad)
    model = ManoeuvreModel(base, man)
    q_BS = mounting_q_BS_003()
    q_BG = np.array([1.0, 0.0, 0.0, 0.0])
    secs = partial(_seconds, start_tai_ns=start_tai_ns)
    long_gaps: dict[str, NDArray] = {}
    # star tracker
    t_st = irregular_times(start_tai_ns, duration_s, st_period_s, jitter_fraction, rngs[1])
    keep, long_gaps["star_tracker"] = dropout_mask(t_st, dropout_probability, n_long_gaps, long_gap_max_s, rngs[2])
    t_st = t_st[keep]
    s_st = model.evaluate(secs(t_st))
    q_IS_true, q_IS = _star_tracker_q(s_st.q_IB, q_BS, rngs[3], st_noise_std_rad, quaternion_lsb)
    # gyro
    t_g = irregular_times(start_tai_ns, duration_s, gyro_period_s, jitter_fraction, rngs[4])
    keep, long_gaps["gyro"] = dropout_mask(t_g, dropout_probability, n_long_gaps, long_gap_max_s, rngs[5])
    t_g = t_g[keep]
    s_g = model.evaluate(secs(t_g))
    bias = np.broadcast_to(np.asarray(gyro_bias_rad_s, dtype=float), (t_g.size, 3))
    w_G = quantise(s_g.w_B + bias + rngs[6].standard_normal((t_g.size, 3)) * gyro_noise_std_rad_s, gyro_lsb_rad_s)
    # GNSS: tags on their own grid; late blocks report the state of tag - late_tag_s
    t_n = irregular_times(start_tai_ns, duration_s, gnss_period_s, jitter_fraction, rngs[7])
    keep, long_gaps["gnss"] = dropout_mask(t_n, dropout_probability, 0, long_gap_max_s, rngs[8])
    t_n = t_n[keep]
    late, t_true = _late_tags(t_n, start_tai_ns, duration_s, rngs[9], n_late_blocks, late_block_s, late_tag_s)
    r_E, v_E, r_meas, v_meas = _gnss_states(
        model, secs, t_n, t_true, rngs[10], rngs[11], (gnss_position_noise_std_m, gnss_velocity_noise_std_m_s),
        (gnss_position_lsb_m, gnss_velocity_lsb_m_s))
    streams = _streams(t_st, q_IS, t_g, w_G, t_n, r_meas, v_meas)
    config = {"star_trackers": {ST_SENSOR: {"q_BS": q_BS.tolist()}}, "gyro": {"q_BG": q_BG.tolist()}}
    truth = RealisticTruth(
        model=model, start_tai_ns=int(start_tai_ns), q_BS=q_BS, q_BG=q_BG, st_time_tai_ns=t_st, st_q_OB=s_st.q_OB,
        st_q_IB=s_st.q_IB, st_q_IS=q_IS_true, gyro_time_tai_ns=t_g, gyro_w_B=s_g.w_B,
        gyro_bias_rad_s=np.asarray(gyro_bias_rad_s, dtype=float), gnss_time_tai_ns=t_n, gnss_true_time_tai_ns=t_true,
        gnss_late=late, r_E=r_E, v_E=v_E, late_tag_s=late_tag_s,
        manoeuvre_tai_ns=_manoeuvre_tai_ns(man, start_tai_ns),
        lsb={"quaternion": quaternion_lsb, "gyro_rad_s": gyro_lsb_rad_s, "gnss_position_m": gnss_position_lsb_m,
             "gnss_velocity_m_s": gnss_velocity_lsb_m_s},
        long_gaps_tai_ns=long_gaps,
    )
    return RealisticScenario(streams=streams, config=config, truth=truth, parameters=parameters)
