"""Truth simulator of paper 003's configuration: Meteor-M in orbital orientation, BOKZ-M + gyros + GNSS.

Pure and deterministic: the same keyword arguments give bit-identical output; no I/O. Randomness
comes from ``numpy.random.Generator(PCG64(...))`` seeded by ``SeedSequence(seed).spawn(...)``, one
independent generator per random quantity (attitude phases, star-tracker noise, gaps, gyro noise,
GNSS noise), so that e.g. changing the gyro rate does not change the star-tracker noise.

Model (defaults from 003):

- orbit: circular, 830 km, sun-synchronous inclination (processing.orbits.two_body), two-body (no J2 node
  drift: 0.014 deg over 20 min), inertial frame I = GCRS;
- attitude: q_IB = q_IO_003 o q_OB(pitch, yaw, roll) (003 §1.6), pitch and roll slow oscillations
  within +-0.3 deg (003: |alpha|, |gamma| < 0.4 deg), yaw 1.2 deg +- 0.25 deg (003: oscillation of
  less than 0.3 deg about 1.0-1.4 deg), each a sum of three sinusoids with periods of hundreds of
  seconds and random phases, plus a 0.4 Hz oscillation of 3 arcsec on each angle (003 §1.5:
  rotating mirror; the paper's 2-2.7" about y1, y2, y3). The angles' axes are the body axes to
  within the yaw angle, so the vibration is about the body axes to ~2.5 % (sin 1.45 deg);
- body rate w_B: analytic, exactly consistent with q_IB (processing.simulate.orbital_attitude_model);
- star tracker "st1": mounting of 003 §1.1 (:func:`mounting_q_BS_003`), q_IS = q_IB o q_BS o
  exp(n_S) with n_S a rotation vector about the sensor axes x1 x2 x3 of std (2.5, 5, 15) arcsec
  (003 §1.4: 2.5"/5.1"/13.1", conclusion about 3", 7", 15-20"), every 3 s, its grid shifted by
  ``st_time_offset_s`` from the gyro grid (003 §1.2: the grids do not share nodes); a fraction of
  the samples removed in a few contiguous blocks (gaps);
- gyro: every 0.1 s in the gyro frame G (q_BG), w_G = dcm_GB w_B + b(t) + white noise, with
  b(t) = b0 + b_dot (t - t0) in G, b0 = (-1.84, 4.52, 0.55) arcsec/s: the numbers of 003 §2.4
  Delta*, used as a realistic size only. (In 003, Delta is a correction added to the measured rate,
  w' = w_gyro + Delta, i.e. b = -Delta, and §2.4 expresses it in the star-tracker axes x1x2x3;
  here the same numbers are the bias b of w_meas = w_true + b in the gyro frame.)
- GNSS: every 1 s, ITRS state from the inertial truth by processing.frames.earth_orientation.gcrs_to_itrs_state
  with zero EOP, plus white noise 1 m and 1 mm/s per axis (003 §1.6 smoothing errors).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.signal
from numpy.random import PCG64, Generator, SeedSequence
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.frames.earth_orientation import EarthOrientation, gcrs_to_itrs_state
from processing.orbits.two_body import mean_motion_rad_s, sun_synchronous_inclination_rad
from processing.simulate.orbital_attitude_model import AttitudeState, OrbitalAttitudeModel, SinusoidSeries
from processing.units import NS_PER_S, R_EARTH_M, RAD_PER_ARCSEC, RAD_PER_DEG

ALPHA_003_RAD = 15.0 * RAD_PER_DEG
"""Mounting angle alpha of 003 §1.1."""
ST_NOISE_STD_003_RAD = (2.5 * RAD_PER_ARCSEC, 5.0 * RAD_PER_ARCSEC, 15.0 * RAD_PER_ARCSEC)
GYRO_BIAS_003_RAD_S = (-1.84 * RAD_PER_ARCSEC, 4.52 * RAD_PER_ARCSEC, 0.55 * RAD_PER_ARCSEC)
ATTITUDE_PERIODS_S = (900.0, 420.0, 230.0)
"""Nominal periods of the slow attitude sinusoids; each is scaled by a factor in [0.8, 1.2] from the seed."""
ATTITUDE_WEIGHTS = (0.5, 0.3, 0.2)
"""Shares of the slow amplitude carried by the three sinusoids (sum 1, so |angle - mean| <= amp)."""
ST_SENSOR = "st1"


class Seed003ParameterError(ValueError):
    """A simulator parameter outside its domain."""


def mounting_dcm_BS_003(alpha_rad: float = ALPHA_003_RAD) -> NDArray:
    """dcm_BS (3, 3) of 003 §1.1: body coordinates y from sensor coordinates x, y = dcm_BS @ x.

    y1 = -x2, y2 = x1 sin a - x3 cos a, y3 = x1 cos a + x3 sin a (the paper's "formulas of the
    transition from x1x2x3 to y1y2y3", confirmed by its rate relations w1 = -w^2,
    w2 = w^1 sin a - w^3 cos a, w3 = w^1 cos a + w^3 sin a). det = sin^2 a + cos^2 a = +1. The rows of
    dcm_BS are the body axes in sensor coordinates (y3 = (cos a, 0, sin a) in S); its columns are the
    sensor axes in body coordinates: the boresight x3 is (0, -cos a, sin a), in the y2-y3 plane, turned
    by alpha from -y2 (minus the orbit normal in orbital orientation) towards y3 (the zenith).
    """
    s, c = np.sin(alpha_rad), np.cos(alpha_rad)
    return np.array([[0.0, -1.0, 0.0], [s, 0.0, -c], [c, 0.0, s]])


def mounting_q_BS_003(alpha_rad: float = ALPHA_003_RAD) -> NDArray:
    """q_BS (4,) canonical, scalar first, of the 003 §1.1 mounting (see :func:`mounting_dcm_BS_003`)."""
    return rotations.dcm_to_quat(mounting_dcm_BS_003(alpha_rad))


@dataclass(frozen=True)
class Truth003:
    """Known truth of a seed-003 scenario. Times int64 tai_ns; angles rad; rates rad/s; SI.

    Gyro grid: gyro_time_tai_ns (N,), q_IB_gyro (N,4), w_B_gyro (N,3), pitch/yaw/roll_rad (N,) (003
    §1.6 angles), gyro_bias_rad_s (N,3) bias in the gyro frame at each sample (constant unless
    gyro_bias_drift_rad_s2 != 0), gyro_bias0_rad_s (3,) at the start time.
    Star tracker (rows of the star_tracker stream): st_time_tai_ns (M,), q_IB_st (M,4), w_B_st (M,3),
    q_IS_st (M,4) noise-free, st_noise_rotvec_S (M,3) the noise rotation about the sensor axes that
    was applied, st_noise_std_rad (3,) configured std per sensor axis; st_nominal_time_tai_ns all
    nominal times, st_removed_time_tai_ns the removed ones, st_gap_intervals_tai_ns (G,2) pairs
    (last sample before, first sample after) of each gap.
    GNSS: gnss_time_tai_ns (K,), r_I, v_I (GCRS), r_E, v_E (ITRS, zero EOP) noise-free (K,3).
    Failure-case options (all off by default): st_outlier_mask (M,) the star-tracker samples moved by an
    outlier rotation st_outlier_rotvec_S (M,3) (zero elsewhere, not part of st_noise_rotvec_S);
    st_noise_tau_s the correlation time of first-order Gauss-Markov star-tracker noise (None: white);
    gyro_line_rad_s (N,3) the gyro-only oscillation added to the gyro rates in G (not attitude motion).
    """

    model: OrbitalAttitudeModel
    start_tai_ns: int
    q_BS: NDArray
    q_BG: NDArray
    alpha_rad: float
    mean_motion_rad_s: float
    gyro_time_tai_ns: NDArray
    q_IB_gyro: NDArray
    w_B_gyro: NDArray
    pitch_rad: NDArray
    yaw_rad: NDArray
    roll_rad: NDArray
    gyro_bias_rad_s: NDArray
    gyro_bias0_rad_s: NDArray
    gyro_bias_drift_rad_s2: NDArray
    gyro_noise_std_rad_s: float
    st_time_tai_ns: NDArray
    q_IB_st: NDArray
    w_B_st: NDArray
    q_IS_st: NDArray
    st_noise_rotvec_S: NDArray
    st_noise_std_rad: NDArray
    st_nominal_time_tai_ns: NDArray
    st_removed_time_tai_ns: NDArray
    st_gap_intervals_tai_ns: NDArray
    gnss_time_tai_ns: NDArray
    r_I: NDArray
    v_I: NDArray
    r_E: NDArray
    v_E: NDArray
    gnss_position_noise_std_m: float
    gnss_velocity_noise_std_m_s: float
    eop: EarthOrientation
    st_outlier_mask: NDArray | None = None
    st_outlier_rotvec_S: NDArray | None = None
    st_noise_tau_s: float | None = None
    gyro_line_rad_s: NDArray | None = None


@dataclass(frozen=True)
class Scenario003:
    """Simulated telemetry and its truth.

    streams: {"star_tracker", "gyro", "gnss"} -> column mapping in the canonical stream schemas
    (processing.streams): time_tai_ns (int64), sensor (str: "st1", "gyro", "gnss", the default
    sensor names of the service), value columns (float64).
    config: spacecraft configuration in the DESIGN.md JSON shape.
    truth: :class:`Truth003`. parameters: the keyword arguments used.
    """

    streams: dict[str, dict[str, NDArray]]
    config: dict[str, Any]
    truth: Truth003
    parameters: dict[str, Any]


def time_grid_tai_ns(start_tai_ns: int, duration_s: float, period_s: float, offset_s: float = 0.0) -> NDArray:
    """start + offset + k period for k = 0.. while <= start + duration, int64 ns (rounded to the ns)."""
    n = int(np.floor((duration_s - offset_s) / period_s + 1e-9)) + 1
    return np.int64(start_tai_ns) + np.round((offset_s + np.arange(n) * period_s) * NS_PER_S).astype(np.int64)


def _composition(total: int, parts: int, rng: Generator) -> NDArray:
    """Random split of ``total`` into ``parts`` positive integers (uniform over compositions)."""
    cuts = np.sort(rng.choice(np.arange(1, total), size=parts - 1, replace=False))
    return np.diff(np.concatenate([[0], cuts, [total]]))


def gap_mask(n: int, gap_fraction: float, n_gaps: int, rng: Generator) -> NDArray:
    """Boolean keep-mask (n,) with round(gap_fraction n) samples removed in ``n_gaps`` contiguous
    blocks at random positions, never touching the first or last sample, blocks separated by at
    least one kept sample (fewer blocks if fewer samples are removed)."""
    m = int(round(gap_fraction * n))
    n_gaps = min(n_gaps, m)
    if m == 0 or n_gaps == 0:
        return np.ones(n, dtype=bool)
    kept = n - m
    if kept < n_gaps + 1:
        raise Seed003ParameterError(f"cannot place {n_gaps} gaps of {m} samples in {n} samples")
    lengths = np.empty(2 * n_gaps + 1, dtype=np.int64)
    lengths[0::2] = _composition(kept, n_gaps + 1, rng)
    lengths[1::2] = _composition(m, n_gaps, rng)
    flags = np.arange(2 * n_gaps + 1) % 2 == 0
    return np.repeat(flags, lengths)


def _series(mean: float, amp: float, vib_amp: float, vib_hz: float, rng: Generator) -> SinusoidSeries:
    periods = np.asarray(ATTITUDE_PERIODS_S) * rng.uniform(0.8, 1.2, size=3)
    phases = rng.uniform(0.0, 2.0 * np.pi, size=4)
    return SinusoidSeries(
        mean_rad=mean,
        amplitudes_rad=(*(amp * np.asarray(ATTITUDE_WEIGHTS)).tolist(), vib_amp),
        periods_s=(*periods.tolist(), 1.0 / vib_hz),
        phases_rad=tuple(phases.tolist()),
    )


def _check(cond: bool, message: str) -> None:
    if not cond:
        raise Seed003ParameterError(message)


def simulate_seed003(
    *,
    start_tai_ns: int,
    duration_s: float = 1200.0,
    seed: int = 0,
    st_period_s: float = 3.0,
    gyro_period_s: float = 0.1,
    gnss_period_s: float = 1.0,
    gap_fraction: float = 0.03,
    n_st_gaps: int = 3,
    st_time_offset_s: float = 0.037,
    altitude_m: float = 830e3,
    raan_rad: float = 100.0 * RAD_PER_DEG,
    u0_rad: float = 20.0 * RAD_PER_DEG,
    pitch_mean_rad: float = 0.0,
    pitch_amplitude_rad: float = 0.3 * RAD_PER_DEG,
    yaw_mean_rad: float = 1.2 * RAD_PER_DEG,
    yaw_amplitude_rad: float = 0.25 * RAD_PER_DEG,
    roll_mean_rad: float = 0.0,
    roll_amplitude_rad: float = 0.3 * RAD_PER_DEG,
    vibration_hz: float = 0.4,
    vibration_amplitude_rad: tuple[float, float, float] = (3.0 * RAD_PER_ARCSEC,) * 3,
    alpha_rad: float = ALPHA_003_RAD,
    st_noise_std_rad: tuple[float, float, float] = ST_NOISE_STD_003_RAD,
    q_BG: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0),
    gyro_bias_rad_s: tuple[float, float, float] = GYRO_BIAS_003_RAD_S,
    gyro_bias_drift_rad_s2: tuple[float, float, float] = (0.0, 0.0, 0.0),
    gyro_noise_std_rad_s: float = 1.5 * RAD_PER_ARCSEC,
    gnss_position_noise_std_m: float = 1.0,
    gnss_velocity_noise_std_m_s: float = 1e-3,
    st_outlier_fraction: float = 0.0,
    st_outlier_size_rad: float = 300.0 * RAD_PER_ARCSEC,
    st_noise_tau_s: float | None = None,
    gyro_line_hz: float = 0.25,
    gyro_line_amplitude_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> Scenario003:
    """Simulate a 003 (Meteor-M) segment: star tracker, gyro and GNSS telemetry with known truth.

    All arguments keyword-only; angles rad, rates rad/s, times s except ``start_tai_ns`` (int64 ns
    since 1970-01-01T00:00:00 TAI). vibration_amplitude_rad is per angle (pitch, yaw, roll);
    st_noise_std_rad per sensor axis (x1, x2, x3); gyro biases in the gyro frame. Grids include the
    start and every sample up to start + duration_s. See the module docstring for the model.
    Failure cases (issue 17; defaults off, and the default output unchanged): ``st_outlier_fraction`` of
    the star-tracker samples (chosen at random) turned by ``st_outlier_size_rad`` about a random axis;
    ``st_noise_tau_s``: first-order Gauss-Markov star-tracker noise, x_k = phi x_{k-1} + sqrt(1 - phi^2)
    sigma w_k, phi = exp(-dt/tau), on the nominal grid (stationary std st_noise_std_rad) instead of
    white; ``gyro_line_amplitude_rad_s`` (per gyro axis) at ``gyro_line_hz``: an oscillation of the gyro
    output only (e.g. a resonance of its mounting), not of the attitude. Returns :class:`Scenario003`.
    """
    parameters = {k: v for k, v in locals().items() if k != "parameters"}
    _check_parameters(parameters)
    rng_attitude, rng_st, rng_gaps, rng_gyro, rng_gnss, rng_outliers, rng_gyro_line = (
        Generator(PCG64(s)) for s in SeedSequence(seed).spawn(7)  # the first five as before (spawn keys)
    )
    a_m = R_EARTH_M + altitude_m
    model = OrbitalAttitudeModel(
        a_m=a_m,
        inc_rad=float(sun_synchronous_inclination_rad(a_m)),
        raan_rad=raan_rad,
        u0_rad=u0_rad,
        pitch=_series(pitch_mean_rad, pitch_amplitude_rad, vibration_amplitude_rad[0], vibration_hz, rng_attitude),
        yaw=_series(yaw_mean_rad, yaw_amplitude_rad, vibration_amplitude_rad[1], vibration_hz, rng_attitude),
        roll=_series(roll_mean_rad, roll_amplitude_rad, vibration_amplitude_rad[2], vibration_hz, rng_attitude),
    )
    q_BS = mounting_q_BS_003(alpha_rad)
    st = _star_tracker(model, start_tai_ns, duration_s, st_period_s, st_time_offset_s, q_BS, st_noise_std_rad,
                       (gap_fraction, n_st_gaps), rng_gaps, rng_st, st_noise_tau_s,
                       (st_outlier_fraction, st_outlier_size_rad), rng_outliers)
    gyro = _gyro(model, start_tai_ns, duration_s, gyro_period_s, q_BG, gyro_bias_rad_s, gyro_bias_drift_rad_s2,
                 gyro_noise_std_rad_s, rng_gyro, (gyro_line_hz, gyro_line_amplitude_rad_s), rng_gyro_line)
    gnss = _gnss(model, start_tai_ns, duration_s, gnss_period_s, gnss_position_noise_std_m,
                 gnss_velocity_noise_std_m_s, rng_gnss)
    streams = {"star_tracker": st.columns(), "gyro": gyro.columns(), "gnss": gnss.columns()}
    config = {"star_trackers": {ST_SENSOR: {"q_BS": q_BS.tolist()}}, "gyro": {"q_BG": gyro.q_BG.tolist()}}
    truth = _truth(model, start_tai_ns, a_m, alpha_rad, q_BS, st, gyro, gnss, gyro_bias_rad_s=gyro_bias_rad_s,
                   gyro_bias_drift_rad_s2=gyro_bias_drift_rad_s2, gyro_noise_std_rad_s=gyro_noise_std_rad_s,
                   st_noise_std_rad=st_noise_std_rad, st_noise_tau_s=st_noise_tau_s,
                   gnss_noise_std=(gnss_position_noise_std_m, gnss_velocity_noise_std_m_s))
    return Scenario003(streams=streams, config=config, truth=truth, parameters=parameters)


def _truth(model: OrbitalAttitudeModel, start_tai_ns: int, a_m: float, alpha_rad: float, q_BS: NDArray,
           st: _StarTracker, gyro: _Gyro, gnss: _Gnss, *, gyro_bias_rad_s: tuple[float, float, float],
           gyro_bias_drift_rad_s2: tuple[float, float, float], gyro_noise_std_rad_s: float,
           st_noise_std_rad: tuple[float, float, float], st_noise_tau_s: float | None,
           gnss_noise_std: tuple[float, float]) -> Truth003:
    """The :class:`Truth003` of :func:`simulate_seed003` from its model, samples and noise parameters
    (gnss_noise_std: position [m], velocity [m/s])."""
    return Truth003(
        model=model, start_tai_ns=int(np.int64(start_tai_ns)), q_BS=q_BS, q_BG=gyro.q_BG, alpha_rad=alpha_rad,
        mean_motion_rad_s=float(mean_motion_rad_s(a_m)), gyro_time_tai_ns=gyro.time_tai_ns,
        q_IB_gyro=gyro.state.q_IB, w_B_gyro=gyro.state.w_B, pitch_rad=gyro.state.pitch_rad,
        yaw_rad=gyro.state.yaw_rad, roll_rad=gyro.state.roll_rad, gyro_bias_rad_s=gyro.bias_rad_s,
        gyro_bias0_rad_s=np.asarray(gyro_bias_rad_s, dtype=float),
        gyro_bias_drift_rad_s2=np.asarray(gyro_bias_drift_rad_s2, dtype=float),
        gyro_noise_std_rad_s=gyro_noise_std_rad_s, st_time_tai_ns=st.time_tai_ns, q_IB_st=st.state.q_IB,
        w_B_st=st.state.w_B, q_IS_st=st.q_IS_true, st_noise_rotvec_S=st.noise_S,
        st_noise_std_rad=np.asarray(st_noise_std_rad, dtype=float), st_nominal_time_tai_ns=st.nominal_tai_ns,
        st_removed_time_tai_ns=st.nominal_tai_ns[~st.keep], st_gap_intervals_tai_ns=st.gap_intervals_tai_ns,
        gnss_time_tai_ns=gnss.time_tai_ns, r_I=gnss.r_I, v_I=gnss.v_I, r_E=gnss.r_E, v_E=gnss.v_E,
        gnss_position_noise_std_m=gnss_noise_std[0], gnss_velocity_noise_std_m_s=gnss_noise_std[1],
        eop=gnss.eop, st_outlier_mask=st.outlier_mask, st_outlier_rotvec_S=st.outlier_S,
        st_noise_tau_s=st_noise_tau_s, gyro_line_rad_s=gyro.line_rad_s,
    )


def _check_parameters(p: dict[str, Any]) -> None:
    """The parameter domains of :func:`simulate_seed003` (Seed003ParameterError naming the parameter)."""
    _check(p["duration_s"] > 0, f"duration_s must be > 0, got {p['duration_s']}")
    for name in ("st_period_s", "gyro_period_s", "gnss_period_s", "vibration_hz"):
        _check(p[name] > 0, f"{name} must be > 0, got {p[name]}")
    _check(0.0 <= p["gap_fraction"] < 0.5, f"gap_fraction must be in [0, 0.5), got {p['gap_fraction']}")
    _check(p["n_st_gaps"] >= 0, f"n_st_gaps must be >= 0, got {p['n_st_gaps']}")
    _check(
        0.0 <= p["st_time_offset_s"] < p["st_period_s"],
        f"st_time_offset_s must be in [0, st_period_s={p['st_period_s']}), got {p['st_time_offset_s']}",
    )
    _check(p["altitude_m"] > 0, f"altitude_m must be > 0, got {p['altitude_m']}")
    for name in ("st_noise_std_rad", "vibration_amplitude_rad", "gyro_bias_rad_s", "gyro_bias_drift_rad_s2"):
        _check(np.shape(p[name]) == (3,), f"{name} must have 3 components, got {p[name]!r}")
    _check(min(p["st_noise_std_rad"]) >= 0 and p["gyro_noise_std_rad_s"] >= 0, "noise standard deviations must be >= 0")
    _check(p["gnss_position_noise_std_m"] >= 0 and p["gnss_velocity_noise_std_m_s"] >= 0, "GNSS noise must be >= 0")
    _check(np.shape(p["q_BG"]) == (4,), f"q_BG must have 4 components, got {p['q_BG']!r}")
    _check(0.0 <= p["st_outlier_fraction"] <= 0.5, f"st_outlier_fraction must be in [0, 0.5], got "
           f"{p['st_outlier_fraction']}")
    _check(p["st_noise_tau_s"] is None or p["st_noise_tau_s"] > 0, "st_noise_tau_s must be None or > 0")
    _check(p["gyro_line_hz"] > 0 and np.shape(p["gyro_line_amplitude_rad_s"]) == (3,),
           "gyro_line_hz must be > 0 and gyro_line_amplitude_rad_s have 3 components")


def _seconds(t_ns: NDArray, start_tai_ns: int) -> NDArray:
    return (t_ns - np.int64(start_tai_ns)).astype(np.float64) / NS_PER_S


@dataclass(frozen=True)
class _StarTracker:
    """Star-tracker samples: nominal times and the keep mask (gaps), kept times (M,), the model state
    there, true and measured q_IS (M, 4), the applied noise rotation vectors, and the gap intervals."""

    nominal_tai_ns: NDArray
    keep: NDArray
    time_tai_ns: NDArray
    state: AttitudeState
    q_IS_true: NDArray
    q_IS: NDArray
    noise_S: NDArray
    gap_intervals_tai_ns: NDArray
    outlier_mask: NDArray
    outlier_S: NDArray

    def columns(self) -> dict[str, NDArray]:
        return {
            "time_tai_ns": self.time_tai_ns,
            **{f"q{i}": self.q_IS[:, i].copy() for i in range(4)},
            "sensor": np.full(self.time_tai_ns.size, ST_SENSOR, dtype=object),
        }


def _star_tracker(
    model: OrbitalAttitudeModel, start_tai_ns: int, duration_s: float, period_s: float, offset_s: float,
    q_BS: NDArray, noise_std_rad: tuple[float, float, float], gaps: tuple[float, int], rng_gaps: Generator,
    rng_st: Generator, tau_s: float | None = None, outliers: tuple[float, float] = (0.0, 0.0),
    rng_outliers: Generator | None = None,
) -> _StarTracker:
    """q_IS = q_IB o q_BS o exp(noise about the sensor axes) (white, or Gauss-Markov with tau_s) o
    exp(outlier rotation on a fraction of the samples), gaps (fraction, count) removed."""
    nominal = time_grid_tai_ns(start_tai_ns, duration_s, period_s, offset_s)
    keep = gap_mask(nominal.size, gaps[0], gaps[1], rng_gaps)
    st_time = nominal[keep]
    state = model.evaluate(_seconds(st_time, start_tai_ns))
    q_IS_true = rotations.quat_canonical(rotations.quat_multiply(state.q_IB, q_BS))
    if tau_s is None:
        noise_S = rng_st.standard_normal((st_time.size, 3)) * np.asarray(noise_std_rad)
    else:
        noise_S = _gauss_markov(rng_st.standard_normal((nominal.size, 3)), period_s, tau_s)[keep] * np.asarray(
            noise_std_rad)
    outlier_mask = np.zeros(st_time.size, dtype=bool)
    outlier_S = np.zeros((st_time.size, 3))
    if outliers[0] > 0 and rng_outliers is not None:
        idx = rng_outliers.choice(st_time.size, size=int(round(outliers[0] * st_time.size)), replace=False)
        axis = rng_outliers.standard_normal((idx.size, 3))
        outlier_mask[idx] = True
        outlier_S[idx] = outliers[1] * axis / np.linalg.norm(axis, axis=1, keepdims=True)
    q_IS = rotations.quat_canonical(rotations.quat_multiply(
        q_IS_true, rotations.quat_multiply(rotations.rotvec_to_quat(noise_S), rotations.rotvec_to_quat(outlier_S))))
    edges = np.flatnonzero(np.diff(keep.astype(np.int8)))  # index before each change keep <-> removed
    gap_intervals = np.stack([nominal[edges[0::2]], nominal[edges[1::2] + 1]], axis=-1)
    return _StarTracker(nominal, keep, st_time, state, q_IS_true, q_IS, noise_S, gap_intervals, outlier_mask,
                        outlier_S)


def _gauss_markov(w: NDArray, period_s: float, tau_s: float) -> NDArray:
    """Unit-variance first-order Gauss-Markov sequence (stationary from the first row) from white w (n, k)."""
    phi = float(np.exp(-period_s / tau_s))
    drive = w * np.sqrt(1.0 - phi**2)
    drive[0] = w[0]
    return scipy.signal.lfilter([1.0], [1.0, -phi], drive, axis=0)


@dataclass(frozen=True)
class _Gyro:
    """Gyro samples: times (N,), the model state there, bias (N, 3) and measured w_G (N, 3) in G, q_BG."""

    time_tai_ns: NDArray
    state: AttitudeState
    bias_rad_s: NDArray
    w_G: NDArray
    q_BG: NDArray
    line_rad_s: NDArray

    def columns(self) -> dict[str, NDArray]:
        return {
            "time_tai_ns": self.time_tai_ns,
            **{c: self.w_G[:, i].copy() for i, c in enumerate(("wx", "wy", "wz"))},
            "sensor": np.full(self.time_tai_ns.size, "gyro", dtype=object),
        }


def _gyro(
    model: OrbitalAttitudeModel, start_tai_ns: int, duration_s: float, period_s: float, q_BG: ArrayLike,
    bias_rad_s: ArrayLike, bias_drift_rad_s2: ArrayLike, noise_std_rad_s: float, rng: Generator,
    line: tuple[float, tuple[float, float, float]] = (1.0, (0.0, 0.0, 0.0)), rng_line: Generator | None = None,
) -> _Gyro:
    """w_G = dcm_GB w_B + b(t) + noise (+ a gyro-only line (frequency, amplitude per axis), random phases)."""
    q_BG_arr = rotations.quat_canonical(rotations.quat_normalize(np.asarray(q_BG, dtype=float)))
    gyro_time = time_grid_tai_ns(start_tai_ns, duration_s, period_s)
    t_gyro = _seconds(gyro_time, start_tai_ns)
    state = model.evaluate(t_gyro)
    bias = np.asarray(bias_rad_s, dtype=float) + np.asarray(bias_drift_rad_s2, dtype=float) * t_gyro[:, None]
    w_G_true = rotations.quat_rotate(rotations.quat_conjugate(q_BG_arr), state.w_B)
    w_G = w_G_true + bias + rng.standard_normal((gyro_time.size, 3)) * noise_std_rad_s
    line_rad_s = np.zeros_like(w_G)
    if np.any(np.asarray(line[1])) and rng_line is not None:
        phases = rng_line.uniform(0.0, 2.0 * np.pi, size=3)
        line_rad_s = np.asarray(line[1], dtype=float) * np.sin(2.0 * np.pi * line[0] * t_gyro[:, None] + phases)
        w_G = w_G + line_rad_s
    return _Gyro(gyro_time, state, bias, w_G, q_BG_arr, line_rad_s)


@dataclass(frozen=True)
class _Gnss:
    """GNSS samples: times (K,), the inertial and (zero-EOP) ITRS truth (K, 3), the measured r, v."""

    time_tai_ns: NDArray
    r_I: NDArray
    v_I: NDArray
    r_E: NDArray
    v_E: NDArray
    r_E_meas: NDArray
    v_E_meas: NDArray
    eop: EarthOrientation

    def columns(self) -> dict[str, NDArray]:
        return {
            "time_tai_ns": self.time_tai_ns,
            **{c: self.r_E_meas[:, i].copy() for i, c in enumerate(("x", "y", "z"))},
            **{c: self.v_E_meas[:, i].copy() for i, c in enumerate(("vx", "vy", "vz"))},
            "sensor": np.full(self.time_tai_ns.size, "gnss", dtype=object),
        }


def _gnss(
    model: OrbitalAttitudeModel, start_tai_ns: int, duration_s: float, period_s: float, position_noise_m: float,
    velocity_noise_m_s: float, rng: Generator,
) -> _Gnss:
    """ITRS state from the inertial truth, zero EOP, plus white noise."""
    eop = EarthOrientation()
    gnss_time = time_grid_tai_ns(start_tai_ns, duration_s, period_s)
    r_I, v_I = model.orbit(_seconds(gnss_time, start_tai_ns))
    r_E, v_E = gcrs_to_itrs_state(r_I, v_I, gnss_time, eop)
    r_E_meas = r_E + rng.standard_normal(r_E.shape) * position_noise_m
    v_E_meas = v_E + rng.standard_normal(v_E.shape) * velocity_noise_m_s
    return _Gnss(gnss_time, r_I, v_I, r_E, v_E, r_E_meas, v_E_meas, eop)
