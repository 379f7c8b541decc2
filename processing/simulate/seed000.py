"""Truth simulator of paper 000's configuration: an agile Earth-observation satellite, star tracker + gyro.

Somov & Butyrin (2016), "In-flight calibration and alignment of an astro-inertial attitude
determination system of a maneuvering land-survey satellite" (000). Pure and deterministic: the same
keyword arguments give bit-identical output; no I/O. Randomness comes from
``numpy.random.Generator(PCG64(...))`` seeded by ``SeedSequence(seed).spawn(...)``, one generator per
random quantity (manoeuvre schedule, star-tracker noise, gyro noise, calibration errors), so that e.g.
changing the gyro noise leaves the manoeuvres unchanged.

Model (defaults from 000, "Имитация работы СОУП"):

- orbit: circular, 720 km, sun-synchronous inclination (processing.orbits.two_body), two-body, inertial frame
  I = GCRS. Orbital frame O of 003 §1.6 (processing.frames.orbital.q_IO_003: axis 3 radial, axis 2
  along r x v); on a circular two-body orbit O turns about its axis 2 at the mean motion n, so the
  rate of O relative to I, in O, is exactly (0, n, 0).
- attitude relative to O: q_OB(t) = q_OB(t_i) o (cos(phi/2), sin(phi/2) e_i) on manoeuvre segment i,
  a rotation about a fixed body axis e_i by the angle phi(tau), tau = t - t_i. Segments: an initial
  hold in orbital orientation (body z to nadir, body x along track: 000 keeps the orbital
  orientation for [0, 870) s), then a chain of slews (000's ПМ: peak rates 2-5 deg/s, 40-60 s; the
  first one 60 s at 5 deg/s, the worst case) and slow scans (000's imaging routes: peak rates
  0.3-0.9 deg/s, 60-120 s, class MT_alpha |w| <= 1 deg/s), separated by short holds, about random
  axes. Rate profile phi'(tau) = w_peak sin^2(pi tau / D): zero rate and acceleration at both ends, so
  the body rate is continuous with a continuous derivative across segments, and phi(D) = w_peak D / 2.
  Body rate (exact): w_B = R(q_OB)^T (0, n, 0) + phi'(tau) e_i.
- star tracker "st1": S = the frame A of 000, mounted with q_BS (boresight 30 deg from anti-nadir);
  q_IS = q_IB o q_BS o exp(n_S) with n_S a rotation vector of std 0.3 arcsec per sensor axis (000:
  sigma^a = 0.3" at 1 Hz), every T_o = 1 s on the gyro grid (000: T_o a multiple of T_q).
- gyro increments (000, eq. 1) in the gyro frame G every T_q = 1/128 s:
  i_s = Int(t_s - T_q, T_q, (1 + m) S^Delta (w_S(t) + b^g(t))) + delta_s, with S^Delta = dcm_GS =
  R(q_GS) the true misalignment (tens of arcseconds; S^Delta ~ I + [Delta x], Delta = rotvec(q_GS)),
  m the scale-factor error (a few tenths of a percent), b^g(t) = b0 + b1 t the drift (000:
  {1, -0.8, 0.3} "/s) and delta_s white noise of std 0.001 arcsec per axis (000: sigma^b). The
  integral over each interval uses 2-point Gauss-Legendre quadrature of the analytic rate (error
  h^5 w^(4) / 4320, below 1e-16 rad per increment for motions on time scales of seconds, and ~1e-14 rad
  in the increments that contain a segment boundary, where w'' jumps; the tests check it against 5
  points). The drift as it appears in the measured rate,
  w_meas,G = (1 + m) S^Delta w_S + b_G, is b_G = (1 + m) S^Delta b^g (``Truth000.drift_G_rad_s``).
- configuration: the gyro is nominally aligned with the star tracker (000: the bases A and G
  nominally coincide), config gyro.q_BG = q_BS; the true q_BG = q_BS o q_GS^-1.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.random import PCG64, Generator, SeedSequence
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.frames.orbital import q_IO_003
from processing.orbits.two_body import circular_orbit_state, mean_motion_rad_s, sun_synchronous_inclination_rad
from processing.units import NS_PER_S, R_EARTH_M, RAD_PER_ARCSEC, RAD_PER_DEG

ALTITUDE_000_M = 720e3
DRIFT_000_RAD_S = (1.0 * RAD_PER_ARCSEC, -0.8 * RAD_PER_ARCSEC, 0.3 * RAD_PER_ARCSEC)
"""Test drift vector b^g of 000 ({1, -0.8, 0.3} arcsec/s)."""
ST_NOISE_000_RAD = 0.3 * RAD_PER_ARCSEC
GYRO_NOISE_000_RAD = 0.001 * RAD_PER_ARCSEC
"""Std of the increment noise delta_s per axis (000: 0.001 arcsec at 128 Hz)."""
GYRO_PERIOD_NS = 7_812_500
"""T_q = 1/128 s exactly."""
ST_SENSOR = "st1"
GYRO_SENSOR = "gyro"
Q_OB_NADIR = np.array([0.0, 1.0, 0.0, 0.0])
"""Orbital orientation of 000's imaging satellite: 180 deg about O axis 1, so body x = O axis 1 (along
track), body z = -O axis 3 (nadir), body y = -O axis 2."""
Q_BS_000 = rotations.quat_from_axis_angle([1.0, 0.0, 0.0], -150.0 * RAD_PER_DEG)
"""Star-tracker mounting: boresight S z = (0, 1/2, -sqrt(3)/2) in B, 30 deg from anti-nadir (-z)."""
_GL_NODES = np.array([-1.0, 1.0]) / np.sqrt(3.0)
_GL_WEIGHTS = np.array([1.0, 1.0])
_CHUNK = 1 << 16


class Seed000ParameterError(ValueError):
    """A simulator parameter outside its domain."""


@dataclass(frozen=True)
class ManeuverPlan:
    """Manoeuvre segments in seconds since the start (arrays of length P, in time order, contiguous).

    kind: "hold" | "slew" | "scan"; start_s, duration_s; axis_B (P, 3) unit body axis; peak_rate_rad_s
    (0 for holds); q_OB_start (P, 4) attitude relative to O at each segment's start; mean_motion_rad_s.
    """

    kind: NDArray
    start_s: NDArray
    duration_s: NDArray
    axis_B: NDArray
    peak_rate_rad_s: NDArray
    q_OB_start: NDArray
    mean_motion_rad_s: float

    def _segment(self, t_s: NDArray) -> tuple[NDArray, NDArray]:
        i = np.clip(np.searchsorted(self.start_s, t_s, side="right") - 1, 0, self.start_s.size - 1)
        tau = np.clip(t_s - self.start_s[i], 0.0, self.duration_s[i])
        return i, tau

    def angle_and_rate(self, t_s: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
        """Segment index, angle phi [rad] and rate phi' [rad/s] about the segment axis at t_s (...)."""
        t = np.asarray(t_s, dtype=float)
        i, tau = self._segment(t)
        d, w = self.duration_s[i], self.peak_rate_rad_s[i]
        arg = 2.0 * np.pi * tau / d
        phi = w * (0.5 * tau - d / (4.0 * np.pi) * np.sin(arg))
        return i, phi, w * 0.5 * (1.0 - np.cos(arg))

    def q_OB(self, t_s: ArrayLike) -> NDArray:
        """Attitude of B relative to O (..., 4) at t_s (...) seconds."""
        i, phi, _ = self.angle_and_rate(t_s)
        return rotations.quat_multiply(self.q_OB_start[i], rotations.quat_from_axis_angle(self.axis_B[i], phi))

    def w_B(self, t_s: ArrayLike) -> NDArray:
        """Body rate relative to I, in B (..., 3) [rad/s]: R(q_OB)^T (0, n, 0) + phi' e_i."""
        return self.w_X(t_s, np.array([1.0, 0.0, 0.0, 0.0]))

    def w_X(self, t_s: ArrayLike, q_BX: ArrayLike) -> NDArray:
        """Rate of a frame X fixed in the body (v_B = q_BX o v_X o q_BX^-1), in X axes (..., 3) [rad/s].

        With q_OB = q_OB(t_i) o exp(phi e_i): R(q_OB)^T (0, n, 0) is u_i = R(q_OB(t_i))^T (0, n, 0) turned
        by -phi about e_i (Rodrigues' formula), so no quaternion is formed per sample.
        """
        i, phi, rate = self.angle_and_rate(t_s)
        q_XB = rotations.quat_conjugate(rotations.quat_normalize(np.asarray(q_BX, dtype=float)))
        w_IO = np.array([0.0, self.mean_motion_rad_s, 0.0])
        u = rotations.quat_rotate(q_XB, rotations.quat_rotate(rotations.quat_conjugate(self.q_OB_start), w_IO))
        e = rotations.quat_rotate(q_XB, self.axis_B)
        ui, ei = u[i], e[i]
        c, s = np.cos(phi)[..., None], np.sin(phi)[..., None]
        e_dot_u = np.sum(ei * ui, axis=-1, keepdims=True)
        return ui * c - np.cross(ei, ui) * s + ei * (e_dot_u * (1.0 - c)) + rate[..., None] * ei


@dataclass(frozen=True)
class Truth000:
    """Known truth of a seed-000 scenario. Times int64 tai_ns (or s since start_tai_ns); SI units.

    plan: the manoeuvres (:class:`ManeuverPlan`); orbit a_m, inc_rad, raan_rad, u0_rad.
    q_BS: star-tracker mounting; q_GS: true misalignment (v_G = q_GS o v_S o q_GS^-1),
    misalignment_rad = rotvec(q_GS); scale_factor_error m; drift0_rad_s, drift_rate_rad_s2: b^g(t) =
    b0 + b1 t of eq. (1) (frame A = S); gyro_noise_std_rad per increment; st_noise_std_rad (3,).
    Star tracker: st_time_tai_ns (K,), q_IB_st, q_IS_st (noise-free), w_S_st (K,3), st_noise_rotvec_S.
    Gyro: gyro_time_tai_ns (N,) ends of the increments, gyro_period_s.
    """

    start_tai_ns: int
    plan: ManeuverPlan
    a_m: float
    inc_rad: float
    raan_rad: float
    u0_rad: float
    q_BS: NDArray
    q_GS: NDArray
    misalignment_rad: NDArray
    scale_factor_error: float
    drift0_rad_s: NDArray
    drift_rate_rad_s2: NDArray
    gyro_noise_std_rad: float
    st_noise_std_rad: NDArray
    st_time_tai_ns: NDArray
    q_IB_st: NDArray
    q_IS_st: NDArray
    w_S_st: NDArray
    st_noise_rotvec_S: NDArray
    gyro_time_tai_ns: NDArray
    gyro_period_s: float

    def seconds(self, t_tai_ns: ArrayLike) -> NDArray:
        """Seconds since start_tai_ns (float64) of int64 TAI ns."""
        return (np.asarray(t_tai_ns, dtype=np.int64) - np.int64(self.start_tai_ns)).astype(np.float64) / NS_PER_S

    def drift_rad_s(self, t_s: ArrayLike) -> NDArray:
        """b^g(t) of eq. (1) (..., 3) at t_s seconds since the start."""
        t = np.asarray(t_s, dtype=float)[..., None]
        return self.drift0_rad_s + self.drift_rate_rad_s2 * t

    def drift_G_rad_s(self, t_s: ArrayLike) -> NDArray:
        """Drift in the measured rate, gyro frame: b_G = (1 + m) S^Delta b^g(t) (..., 3)."""
        return (1.0 + self.scale_factor_error) * rotations.quat_rotate(self.q_GS, self.drift_rad_s(t_s))

    def q_IB(self, t_s: ArrayLike) -> NDArray:
        """True attitude q_IB (..., 4) at t_s seconds since the start."""
        t = np.asarray(t_s, dtype=float)
        r, v = circular_orbit_state(t, self.a_m, self.inc_rad, self.raan_rad, self.u0_rad)
        return rotations.quat_canonical(rotations.quat_multiply(q_IO_003(r, v), self.plan.q_OB(t)))

    def q_IS(self, t_s: ArrayLike) -> NDArray:
        """True (noise-free) star-tracker attitude q_IS (..., 4) at t_s seconds since the start."""
        return rotations.quat_canonical(rotations.quat_multiply(self.q_IB(t_s), self.q_BS))

    def w_S(self, t_s: ArrayLike) -> NDArray:
        """True rate of S relative to I, in S (..., 3) [rad/s]."""
        return self.plan.w_X(t_s, self.q_BS)

    def segments(self, kind: str) -> NDArray:
        """(P, 2) [start, end] seconds of the plan's segments of one kind ("hold", "slew", "scan")."""
        sel = self.plan.kind == kind
        return np.stack([self.plan.start_s[sel], self.plan.start_s[sel] + self.plan.duration_s[sel]], axis=-1)


@dataclass(frozen=True)
class Scenario000:
    """Simulated telemetry and its truth.

    streams: {"star_tracker", "gyro_increments"} -> column mapping in the canonical stream schemas
    (processing.streams): time_tai_ns (int64), sensor (str "st1" / "gyro"), value columns (float64).
    config: spacecraft configuration in the DESIGN.md JSON shape (nominal gyro mounting).
    truth: :class:`Truth000`. parameters: the keyword arguments used (after drawing the random ones).
    """

    streams: dict[str, dict[str, NDArray]]
    config: dict[str, Any]
    truth: Truth000
    parameters: dict[str, Any]


def _check(cond: bool, message: str) -> None:
    if not cond:
        raise Seed000ParameterError(message)


def _unit_vector(rng: Generator) -> NDArray:
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v)


def plan_maneuvers(
    duration_s: float,
    rng: Generator,
    *,
    mean_motion: float,
    initial_hold_s: float,
    slew_duration_s: tuple[float, float],
    slew_peak_rate_rad_s: tuple[float, float],
    scan_duration_s: tuple[float, float],
    scan_peak_rate_rad_s: tuple[float, float],
    hold_duration_s: tuple[float, float],
    maneuver_axis_B: tuple[float, float, float] | None = None,
) -> ManeuverPlan:
    """A hold, then slew / hold / scan / hold ... until duration_s (the last segment may run past it).

    The first slew has the longest duration and the highest peak rate of the ranges (worst case for
    the drift prediction); the others are uniform in the ranges, about uniformly random body axes, or
    all about ``maneuver_axis_B`` (in either sense, the random draws unchanged) when it is given.
    """
    fixed = None if maneuver_axis_B is None else np.asarray(maneuver_axis_B, dtype=float)
    if fixed is not None:
        fixed = fixed / np.linalg.norm(fixed)
    kinds, starts, durations, axes, peaks = ["hold"], [0.0], [initial_hold_s], [np.array([1.0, 0.0, 0.0])], [0.0]
    t = initial_hold_s
    first = True
    while t < duration_s:
        cycle = (
            ("slew", slew_duration_s, slew_peak_rate_rad_s),
            ("hold", hold_duration_s, (0.0, 0.0)),
            ("scan", scan_duration_s, scan_peak_rate_rad_s),
            ("hold", hold_duration_s, (0.0, 0.0)),
        )
        for kind, (d_lo, d_hi), (w_lo, w_hi) in cycle:
            if t >= duration_s:
                break
            if kind == "slew" and first:
                d, w = d_hi, w_hi
                first = False
            else:
                d, w = rng.uniform(d_lo, d_hi), rng.uniform(w_lo, w_hi)
            axis = _unit_vector(rng)
            if fixed is not None:
                axis = fixed if axis[0] >= 0 else -fixed
            if d <= 0.0:
                continue
            kinds.append(kind)
            starts.append(t)
            durations.append(d)
            axes.append(axis)
            peaks.append(w)
            t += d
    axis_arr, peak_arr, dur_arr = np.array(axes), np.array(peaks), np.array(durations)
    q_start = np.empty((len(kinds), 4))
    q = Q_OB_NADIR.copy()
    for i in range(len(kinds)):  # a few dozen segments: chain each end attitude into the next start
        q_start[i] = q
        q = rotations.quat_normalize(
            rotations.quat_multiply(q, rotations.quat_from_axis_angle(axis_arr[i], 0.5 * peak_arr[i] * dur_arr[i]))
        )
    return ManeuverPlan(
        kind=np.array(kinds, dtype=object),
        start_s=np.array(starts),
        duration_s=dur_arr,
        axis_B=axis_arr,
        peak_rate_rad_s=peak_arr,
        q_OB_start=q_start,
        mean_motion_rad_s=float(mean_motion),
    )


def _gyro_increments(
    plan: ManeuverPlan, t_end_s: NDArray, h_s: float, q_BS: NDArray, q_GS: NDArray, m: float,
    drift0: NDArray, drift_rate: NDArray,
) -> NDArray:
    """Noise-free (1 + m) S^Delta Int(w_S + b^g) over [t - h, t] for each t (N,), by 2-point Gauss-Legendre."""
    out = np.empty((t_end_s.size, 3))
    for a in range(0, t_end_s.size, _CHUNK):  # chunks bound the temporary arrays (~50 MB), not the speed
        t_mid = t_end_s[a : a + _CHUNK] - 0.5 * h_s
        nodes = t_mid[:, None] + 0.5 * h_s * _GL_NODES  # (n, 2 nodes)
        w_S = plan.w_X(nodes, q_BS)  # (n, 2 nodes, 3)
        integral = 0.5 * h_s * np.einsum("j,njk->nk", _GL_WEIGHTS, w_S)
        integral += h_s * (drift0 + drift_rate * t_mid[:, None])  # linear drift: the midpoint rule is exact
        out[a : a + _CHUNK] = integral
    return (1.0 + m) * rotations.quat_rotate(q_GS, out)


def simulate_seed000(
    *,
    start_tai_ns: int,
    duration_s: float = 1200.0,
    seed: int = 0,
    st_period_s: float = 1.0,
    altitude_m: float = ALTITUDE_000_M,
    raan_rad: float = 100.0 * RAD_PER_DEG,
    u0_rad: float = 0.0,
    initial_hold_s: float = 120.0,
    slew_duration_s: tuple[float, float] = (40.0, 60.0),
    slew_peak_rate_rad_s: tuple[float, float] = (2.0 * RAD_PER_DEG, 5.0 * RAD_PER_DEG),
    scan_duration_s: tuple[float, float] = (60.0, 120.0),
    scan_peak_rate_rad_s: tuple[float, float] = (0.3 * RAD_PER_DEG, 0.9 * RAD_PER_DEG),
    hold_duration_s: tuple[float, float] = (0.0, 10.0),
    misalignment_rad: tuple[float, float, float] | None = None,
    scale_factor_error: float | None = None,
    drift_rad_s: tuple[float, float, float] = DRIFT_000_RAD_S,
    drift_rate_rad_s2: tuple[float, float, float] = (0.0, 0.0, 0.0),
    gyro_noise_std_rad: float = GYRO_NOISE_000_RAD,
    st_noise_std_rad: tuple[float, float, float] = (ST_NOISE_000_RAD,) * 3,
    maneuver_axis_B: tuple[float, float, float] | None = None,
) -> Scenario000:
    """Simulate a 000 agile-satellite segment: star-tracker quaternions and gyro increments with truth.

    All arguments keyword-only; angles rad, rates rad/s, times s except ``start_tai_ns`` (int64 ns
    since 1970-01-01T00:00:00 TAI). The gyro period is T_q = 1/128 s; ``st_period_s`` must be a
    multiple of it. ``misalignment_rad`` (rotation vector of q_GS) and ``scale_factor_error`` default
    to values drawn from the seed: each misalignment component +-U(20, 60) arcsec, m = +-U(0.1, 0.5) %.
    u0_rad = 0 starts at the ascending node (000 counts time from it). ``maneuver_axis_B``: every slew and
    scan about this body axis (e.g. (0, 1, 0): pitch only, with the orbital rate a one-axis arc); None:
    random axes. A nadir-pointing arc at the orbital rate only: ``initial_hold_s`` >= ``duration_s``. The
    increments end at start + s T_q, s = 1..N (N = duration / T_q); star-tracker samples at start + k T_o, k = 0..K.
    Returns :class:`Scenario000`.
    """
    parameters = {k: v for k, v in locals().items() if k != "parameters"}
    _check_parameters(parameters)
    rng_plan, rng_st, rng_gyro, rng_cal = (Generator(PCG64(s)) for s in SeedSequence(seed).spawn(4))
    cal = _calibration_errors(misalignment_rad, scale_factor_error, rng_cal)
    parameters.update(misalignment_rad=cal.misalignment_rad, scale_factor_error=cal.scale_factor_error)
    a_m = R_EARTH_M + altitude_m
    inc = float(sun_synchronous_inclination_rad(a_m))
    plan = plan_maneuvers(
        duration_s, rng_plan, mean_motion=float(mean_motion_rad_s(a_m)), initial_hold_s=initial_hold_s,
        slew_duration_s=slew_duration_s, slew_peak_rate_rad_s=slew_peak_rate_rad_s, scan_duration_s=scan_duration_s,
        scan_peak_rate_rad_s=scan_peak_rate_rad_s, hold_duration_s=hold_duration_s, maneuver_axis_B=maneuver_axis_B,
    )
    start = np.int64(start_tai_ns)
    q_BS = rotations.quat_canonical(Q_BS_000)
    drift0 = np.asarray(drift_rad_s, dtype=float)
    drift_rate = np.asarray(drift_rate_rad_s2, dtype=float)
    gyro = _gyro_stream(start, duration_s, plan, q_BS, cal, drift0, drift_rate, gyro_noise_std_rad, rng_gyro)
    st = _star_tracker_stream(start, duration_s, int(round(st_period_s * NS_PER_S)), plan, q_BS,
                              (a_m, inc, raan_rad, u0_rad), st_noise_std_rad, rng_st)
    config = {"star_trackers": {ST_SENSOR: {"q_BS": q_BS.tolist()}}, "gyro": {"q_BG": q_BS.tolist()}}
    truth = Truth000(
        start_tai_ns=int(start), plan=plan, a_m=a_m, inc_rad=inc, raan_rad=raan_rad, u0_rad=u0_rad, q_BS=q_BS,
        q_GS=cal.q_GS, misalignment_rad=rotations.quat_to_rotvec(cal.q_GS),
        scale_factor_error=float(cal.scale_factor_error), drift0_rad_s=drift0, drift_rate_rad_s2=drift_rate,
        gyro_noise_std_rad=float(gyro_noise_std_rad), st_noise_std_rad=np.asarray(st_noise_std_rad, dtype=float),
        st_time_tai_ns=st.time_tai_ns, q_IB_st=st.q_IB, q_IS_st=st.q_IS_true, w_S_st=st.w_S,
        st_noise_rotvec_S=st.noise_S, gyro_time_tai_ns=gyro.time_tai_ns, gyro_period_s=gyro.period_s,
    )
    streams = {"star_tracker": st.columns(), "gyro_increments": gyro.columns()}
    return Scenario000(streams=streams, config=config, truth=truth, parameters=parameters)


def _check_parameters(p: dict[str, Any]) -> None:
    """The parameter domains of :func:`simulate_seed000` (Seed000ParameterError naming the parameter)."""
    _check(p["duration_s"] > 0, f"duration_s must be > 0, got {p['duration_s']}")
    st_period_ns = int(round(p["st_period_s"] * NS_PER_S))
    _check(
        st_period_ns > 0 and st_period_ns % GYRO_PERIOD_NS == 0,
        f"st_period_s must be a positive multiple of the gyro period 1/128 s, got {p['st_period_s']}",
    )
    _check(p["altitude_m"] > 0, f"altitude_m must be > 0, got {p['altitude_m']}")
    _check(p["initial_hold_s"] >= 0, f"initial_hold_s must be >= 0, got {p['initial_hold_s']}")
    for name in ("slew_duration_s", "slew_peak_rate_rad_s", "scan_duration_s", "scan_peak_rate_rad_s",
                 "hold_duration_s"):
        lo, hi = p[name]
        _check(0 <= lo <= hi, f"{name} must be a range (lo, hi) with 0 <= lo <= hi, got {p[name]!r}")
    _check(p["slew_duration_s"][0] > 0 and p["scan_duration_s"][0] > 0, "slew and scan durations must be > 0")
    for name in ("drift_rad_s", "drift_rate_rad_s2", "st_noise_std_rad"):
        _check(np.shape(p[name]) == (3,), f"{name} must have 3 components, got {p[name]!r}")
    _check(p["maneuver_axis_B"] is None or (np.shape(p["maneuver_axis_B"]) == (3,)
                                           and float(np.linalg.norm(p["maneuver_axis_B"])) > 0),
           f"maneuver_axis_B must be a non-zero 3-vector or None, got {p['maneuver_axis_B']!r}")
    _check(p["misalignment_rad"] is None or np.shape(p["misalignment_rad"]) == (3,),
           f"misalignment_rad must have 3 components, got {p['misalignment_rad']!r}")
    _check(p["scale_factor_error"] is None or abs(p["scale_factor_error"]) < 0.1,
           f"scale_factor_error must be below 0.1 in magnitude, got {p['scale_factor_error']}")
    _check(p["gyro_noise_std_rad"] >= 0 and min(p["st_noise_std_rad"]) >= 0, "noise standard deviations must be >= 0")


@dataclass(frozen=True)
class _Calibration:
    """The true misalignment (rotation vector of q_GS, rad, and q_GS) and scale-factor error."""

    misalignment_rad: tuple[float, float, float]
    scale_factor_error: float
    q_GS: NDArray


def _calibration_errors(misalignment_rad: tuple[float, float, float] | None, scale_factor_error: float | None,
                        rng: Generator) -> _Calibration:
    """The given errors, or drawn: each misalignment component +-U(20, 60) arcsec, m = +-U(0.1, 0.5) %."""
    if misalignment_rad is None:
        signs = rng.choice([-1.0, 1.0], size=3)
        drawn = (signs * rng.uniform(20.0, 60.0, size=3) * RAD_PER_ARCSEC).tolist()
        misalignment_rad = (drawn[0], drawn[1], drawn[2])
    if scale_factor_error is None:
        scale_factor_error = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.001, 0.005))
    q_GS = rotations.quat_canonical(rotations.rotvec_to_quat(np.asarray(misalignment_rad, dtype=float)))
    return _Calibration(misalignment_rad, scale_factor_error, q_GS)


@dataclass(frozen=True)
class _GyroStream:
    """Gyro increments (eq. 1) ending at time_tai_ns (N,), (N, 3) rad in G, every period_s."""

    time_tai_ns: NDArray
    increments: NDArray
    period_s: float

    def columns(self) -> dict[str, NDArray]:
        n = self.time_tai_ns.size
        return {
            "time_tai_ns": self.time_tai_ns,
            **{c: self.increments[:, i].copy() for i, c in enumerate(("dax", "day", "daz"))},
            "interval_s": np.full(n, self.period_s),
            "sensor": np.full(n, GYRO_SENSOR, dtype=object),
        }


def _gyro_stream(
    start: np.int64, duration_s: float, plan: ManeuverPlan, q_BS: NDArray, cal: _Calibration, drift0: NDArray,
    drift_rate: NDArray, noise_std_rad: float, rng: Generator,
) -> _GyroStream:
    """Gyro increments (eq. 1), ending at start + s T_q, s = 1..N, with white noise."""
    h_s = GYRO_PERIOD_NS / NS_PER_S
    n_gyro = int(np.floor(duration_s * NS_PER_S / GYRO_PERIOD_NS + 1e-9))
    steps = np.arange(1, n_gyro + 1, dtype=np.int64)
    gyro_time = start + steps * np.int64(GYRO_PERIOD_NS)
    t_gyro = (steps * GYRO_PERIOD_NS).astype(np.float64) / NS_PER_S
    incr = _gyro_increments(plan, t_gyro, h_s, q_BS, cal.q_GS, cal.scale_factor_error, drift0, drift_rate)
    incr += rng.standard_normal(incr.shape) * noise_std_rad
    return _GyroStream(gyro_time, incr, h_s)


@dataclass(frozen=True)
class _StarTrackerStream:
    """Star-tracker samples: times (K,), measured q_IS, true q_IB and q_IS (K, 4), the noise rotation
    vectors about the sensor axes and the true rate w_S (K, 3)."""

    time_tai_ns: NDArray
    q_IS: NDArray
    q_IB: NDArray
    q_IS_true: NDArray
    noise_S: NDArray
    w_S: NDArray

    def columns(self) -> dict[str, NDArray]:
        return {
            "time_tai_ns": self.time_tai_ns,
            **{f"q{i}": self.q_IS[:, i].copy() for i in range(4)},
            "sensor": np.full(self.time_tai_ns.size, ST_SENSOR, dtype=object),
        }


def _star_tracker_stream(
    start: np.int64, duration_s: float, st_period_ns: int, plan: ManeuverPlan, q_BS: NDArray,
    orbit: tuple[float, float, float, float], noise_std_rad: tuple[float, float, float], rng: Generator,
) -> _StarTrackerStream:
    """q_IS = q_IB o q_BS o exp(noise about the sensor axes) at start + k T_o, k = 0..K; orbit (a, i, RAAN, u0)."""
    n_st = int(np.floor(duration_s * NS_PER_S / st_period_ns + 1e-9)) + 1
    st_k = np.arange(n_st, dtype=np.int64)
    st_time = start + st_k * np.int64(st_period_ns)
    t_st = (st_k * st_period_ns).astype(np.float64) / NS_PER_S
    r_I, v_I = circular_orbit_state(t_st, *orbit)
    q_IB = rotations.quat_canonical(rotations.quat_multiply(q_IO_003(r_I, v_I), plan.q_OB(t_st)))
    q_IS_true = rotations.quat_canonical(rotations.quat_multiply(q_IB, q_BS))
    noise_S = rng.standard_normal((n_st, 3)) * np.asarray(noise_std_rad, dtype=float)
    q_IS = rotations.quat_canonical(rotations.quat_multiply(q_IS_true, rotations.rotvec_to_quat(noise_S)))
    return _StarTrackerStream(st_time, q_IS, q_IB, q_IS_true, noise_S, plan.w_X(t_st, q_BS))
