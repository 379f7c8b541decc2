"""Closed-loop truth simulator of paper 004: gravity-gradient + magnetic microsatellite with an on-board
EKF and the energy or averaged-LQR magnetic controller.

Pure and deterministic (same keyword arguments -> bit-identical output; randomness from
``numpy.random.Generator(PCG64)`` seeded by ``SeedSequence(seed).spawn(4)``: magnetometer, sun sensor,
GNSS, spare). No I/O.

Model (defaults from 004):

- orbit: circular two-body, 650 km, inclination 98 deg, inertial frame I = GCRS; the node is put so
  that the orbit is dawn-dusk at the start (orbit normal opposite to the Sun), which makes the Sun
  direction in the orbital frame close to 004's S_orb = (0, 1, 0) and the orbit eclipse-free near the
  equinoxes; ``sun_model="paper"`` uses exactly S_orb = (0, 1, 0) instead of the ephemeris;
- attitude dynamics 004 eq. (1)-(3) (processing.attitude.rigid_body), J = diag(51.44, 51.48, 0.76) kg m^2,
  integrated by RK4 with ``substeps`` per control step T_s = 1 s; gravity gradient with n^2 = mu/r^3;
  the field in O follows the orbit (IGRF-14 at the true position; linear within a step);
- disturbance tau_d = A sin(w0 t) in B, A = (3e-6, -5e-6, 9.8e-7) N m (004; zeros disable it);
- sensors at 1 Hz: magnetometer B_M = dcm_MB dcm_BO (B_O + dB_O) + n, n ~ N(0, sigma^2) per axis [nT],
  dB_O = field_model_error (1, -1, 1) |B_O| (004's 2 % model error: field_model_error = 0.02); sun
  sensor s_S = dcm_SB dcm_BO s_O turned by a random small rotation with sigma per tangent axis,
  absent in the Earth's shadow (conical model, any penumbra) and during periodic outages of
  ``sun_outage_s`` per orbit centred at argument of latitude ``sun_outage_center_u_deg`` (004: 2000 s
  and 1000 s); GNSS ITRF position/velocity with white noise (zero EOP; processing.frames.earth_rotation_interp);
- magnetometer errors (optional, default none; processing.magnetometer.model): the telemetry is
  B_meas = (I + D) B_M + b + C mu_B + n with bias ``magnetometer_bias_nT``, symmetric D from
  ``magnetometer_scale_factor_errors`` (D_xx, D_yy, D_zz) and ``magnetometer_non_orthogonality_rad``
  (D_xy, D_xz, D_yz), and the magnetorquer coupling ``magnetometer_coupling_nT_per_A_m2`` (3x3, rows
  magnetometer axes, columns body dipole axes; mu_B the dipole held from that sample on). They are applied
  to the downlinked stream only: the on-board loop uses a magnetometer calibrated on board (the ideal one),
  so the errors do not change the trajectory. The truth records them and the error-free b_M;
- on board: the EKF of 004 ("ekf"), the MEKF ("mekf") or the true state ("truth") feeds the energy law
  (004 eq. 6, beta = 1e8, alpha = 1e6) or the averaged LQR (004 eq. 7, R = diag(100, 100, 0.1),
  Q = (0.1 deg)^-2 I6, designed on the true field over the first orbit), or no controller ("none");
  the dipole is held over each step (zero-order hold), optionally saturated. The on-board filter is
  initialised by a two-vector (TRIAD) solution of the first measurements and w_BO = 0, and uses the
  IGRF field at the true position as its model (with the measurement noise it is told).
Angles: roll, pitch, yaw of processing.attitude.rigid_body (3-2-1 from O to B); 004 starts its transients at
(-30, 10, -20) deg with w_OB = 0.

Steps of :func:`simulate_seed004`: parameters; orbit and environment on the grid; sensor frames and the
noise drawn up front; the LQR design; the closed loop (processing.simulate.seed004_loop); truth, GNSS
noise and streams.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.random import PCG64, Generator, SeedSequence
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.attitude.rigid_body import (
    DISTURBANCE_004_N_M,
    INERTIA_004_KG_M2,
    RigidBody004,
    roll_pitch_yaw_004,
)
from processing.environment.eclipse import sunlit_fraction
from processing.environment.igrf import igrf_field_E_nT
from processing.environment.sun import sun_direction_I, sun_position_I_m
from processing.frames.earth_orientation import EarthOrientation
from processing.frames.earth_rotation_interp import gcrs_to_itrs_mat_interp
from processing.frames.orbital import dcm_IO_lvlh_004
from processing.gyroless.ekf import FilterTuning
from processing.gyroless.magnetic_control import (
    ENERGY_ALPHA_004,
    ENERGY_BETA_004,
    LQR_Q_004,
    LQR_R_004,
    AveragedLQR,
    design_averaged_lqr,
)
from processing.magnetometer.model import MagnetometerErrors
from processing.orbits.two_body import circular_orbit_state, mean_motion_rad_s
from processing.simulate.seed004_loop import Environment004, History, LoopSetup, Sensors004, closed_loop
from processing.units import NS_PER_S, OMEGA_EARTH_RAD_S, R_EARTH_M, RAD_PER_DEG

__all__ = ["Scenario004", "Seed004ParameterError", "Truth004", "orbit_period_s", "simulate_seed004"]

Controller = Literal["energy", "lqr", "none"]
Estimator = Literal["ekf", "mekf", "truth"]


class Seed004ParameterError(ValueError):
    """A simulator parameter outside its domain."""


def orbit_period_s(altitude_m: float = 650e3) -> float:
    """Period [s] of a circular two-body orbit at the given altitude above R_EARTH_M (650 km: 5863 s)."""
    return float(2.0 * math.pi / mean_motion_rad_s(R_EARTH_M + altitude_m))


@dataclass(frozen=True)
class Truth004:
    """Known truth of a seed-004 run, on the 1 Hz grid time_tai_ns (K,). SI units, angles rad.

    q_OB, q_IB (K, 4); omega_BI_B, omega_BO_B (K, 3); roll/pitch/yaw_rad (K,); B_O_nT (K, 3) true
    field in O; s_O (K, 3) Sun direction in O; sun_visible (K,) bool (sun-sensor sample produced);
    sunlit (K,) visible fraction of the solar disc; mu_B_A_m2 (K, 3) dipole held over [t_k, t_k+1);
    tau_d_B_N_m (K, 3) disturbance; q_OB_onboard (K, 4), omega_BO_onboard_B (K, 3) the on-board
    estimate used by the controller; r_I, v_I, r_E, v_E (K, 3) orbit; w0_rad_s mean motion;
    inclination_rad, raan_rad, u0_rad elements; lqr the controller design (or None);
    magnetometer_errors the injected magnetometer errors (None when none) and b_M_ideal_nT the magnetometer
    stream without them.
    """

    time_tai_ns: NDArray
    q_OB: NDArray
    q_IB: NDArray
    omega_BI_B: NDArray
    omega_BO_B: NDArray
    roll_rad: NDArray
    pitch_rad: NDArray
    yaw_rad: NDArray
    B_O_nT: NDArray
    s_O: NDArray
    sun_visible: NDArray
    sunlit: NDArray
    mu_B_A_m2: NDArray
    tau_d_B_N_m: NDArray
    q_OB_onboard: NDArray
    omega_BO_onboard_B: NDArray
    r_I: NDArray
    v_I: NDArray
    r_E: NDArray
    v_E: NDArray
    w0_rad_s: float
    inclination_rad: float
    raan_rad: float
    u0_rad: float
    lqr: AveragedLQR | None
    magnetometer_errors: MagnetometerErrors | None = None  # injected into the telemetry (None: none)
    b_M_ideal_nT: NDArray | None = None  # (K, 3) the magnetometer stream without the injected errors (with noise)


@dataclass(frozen=True)
class Scenario004:
    """Simulated telemetry and truth: streams {magnetometer, sun_sensor, gnss, magnetorquer} -> columns
    (time_tai_ns int64, sensor str, canonical value columns), config (DESIGN.md JSON shape), truth
    (:class:`Truth004`), parameters (the keyword arguments used)."""

    streams: dict[str, dict[str, NDArray]]
    config: dict[str, Any]
    truth: Truth004
    parameters: dict[str, Any]


def _check(cond: bool, message: str) -> None:
    if not cond:
        raise Seed004ParameterError(message)


def _unit(v: NDArray) -> NDArray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _perturb_direction(s: NDArray, sigma_rad: float, rng: Generator) -> NDArray:
    """Unit vectors s (N, 3) turned by a small random rotation with sigma per tangent axis."""
    n = rng.standard_normal(s.shape) * sigma_rad
    n -= np.sum(n * s, axis=-1, keepdims=True) * s
    return _unit(s + n)


def simulate_seed004(
    *,
    start_tai_ns: int,
    duration_s: float = 2 * 5863.0,
    seed: int = 0,
    controller: Controller = "lqr",
    estimator: Estimator = "ekf",
    initial_angles_deg: tuple[float, float, float] = (-30.0, 10.0, -20.0),
    initial_omega_BO_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
    disturbance_N_m: tuple[float, float, float] = DISTURBANCE_004_N_M,
    sun_model: Literal["ephemeris", "paper"] = "ephemeris",
    sun_outage_s: float = 0.0,
    sun_outage_center_u_deg: float = 180.0,
    field_model_error: float = 0.0,
    magnetometer_noise_nT: float = 100.0,
    sun_sensor_noise_deg: float = 0.5,
    gnss_position_noise_m: float = 5.0,
    gnss_velocity_noise_m_s: float = 0.01,
    altitude_m: float = 650e3,
    inclination_deg: float = 98.0,
    raan_rad: float | None = None,
    u0_rad: float = 0.0,
    inertia_kg_m2: tuple[float, float, float] = INERTIA_004_KG_M2,
    energy_beta: float = ENERGY_BETA_004,
    energy_alpha: float = ENERGY_ALPHA_004,
    lqr_q: float = LQR_Q_004,
    lqr_r: tuple[float, float, float] = LQR_R_004,
    max_dipole_A_m2: float | None = None,
    onboard_tuning: FilterTuning | None = None,
    q_BM: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0),
    q_BS: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0),
    step_s: float = 1.0,
    substeps: int = 1,
    magnetometer_bias_nT: tuple[float, float, float] = (0.0, 0.0, 0.0),
    magnetometer_scale_factor_errors: tuple[float, float, float] = (0.0, 0.0, 0.0),
    magnetometer_non_orthogonality_rad: tuple[float, float, float] = (0.0, 0.0, 0.0),
    magnetometer_coupling_nT_per_A_m2: ArrayLike | None = None,
) -> Scenario004:
    """Simulate the closed loop of 004 for ``duration_s`` at ``step_s`` (all arguments keyword-only).

    start_tai_ns: int64 ns since 1970-01-01 TAI. Angles in the names' units; see the module docstring.
    Returns :class:`Scenario004`.
    """
    parameters = {k: v for k, v in locals().items() if k != "parameters"}
    _check_parameters(parameters)
    tuning = FilterTuning() if onboard_tuning is None else onboard_tuning
    rng_mag, rng_sun, rng_gnss, _ = (Generator(PCG64(s)) for s in SeedSequence(seed).spawn(4))
    body = RigidBody004.from_inertia(inertia_kg_m2)
    J = np.diag([body.Jx, body.Jy, body.Jz])
    K = int(math.floor(duration_s / step_s + 1e-9)) + 1
    start = np.int64(start_tai_ns)
    t_s = np.arange(K) * step_s
    time_ns = start + np.round(t_s * NS_PER_S).astype(np.int64)
    env = _environment004(start, t_s, time_ns, altitude_m, inclination_deg, raan_rad, u0_rad, sun_model,
                          sun_outage_s, sun_outage_center_u_deg)
    sensors = _sensors004(env, q_BM, q_BS, magnetometer_noise_nT, sun_sensor_noise_deg, field_model_error,
                          rng_mag, rng_sun)
    amp = np.asarray(disturbance_N_m, dtype=float)
    _check(amp.shape == (3,), f"disturbance_N_m must have 3 components, got {disturbance_N_m!r}")
    lqr = None
    if controller == "lqr":
        lqr = _design_lqr(env, J, start, step_s, altitude_m, u0_rad, lqr_q, lqr_r)
    loop = LoopSetup(
        body=body, J=J, t_s=t_s, step_s=step_s, substeps=substeps, w0=env.w0, env=env, sensors=sensors,
        tau_all=amp[None, :] * np.sin(env.w0 * (t_s[:, None] + 0.5 * step_s / substeps)), amp=amp,
        controller=controller, estimator=estimator, tuning=tuning, magnetometer_noise_nT=magnetometer_noise_nT,
        sigma_s=max(sun_sensor_noise_deg * RAD_PER_DEG, 1e-4), energy_beta=energy_beta, energy_alpha=energy_alpha,
        K_gain=lqr.K if lqr is not None else None, max_dipole_A_m2=max_dipole_A_m2,
    )
    try:
        mag_errors = MagnetometerErrors.from_components(
            magnetometer_bias_nT, magnetometer_scale_factor_errors, magnetometer_non_orthogonality_rad,
            magnetometer_coupling_nT_per_A_m2)
    except ValueError as exc:
        raise Seed004ParameterError(f"magnetometer errors: {exc}") from exc
    hist = closed_loop(loop, initial_angles_deg, initial_omega_BO_rad_s)
    return _scenario004(env, sensors, loop, hist, J, time_ns, lqr, u0_rad, parameters,
                        (gnss_position_noise_m, gnss_velocity_noise_m_s), rng_gnss,
                        None if mag_errors.is_zero else mag_errors)


def _check_parameters(p: dict[str, Any]) -> None:
    """The parameter domains of :func:`simulate_seed004` (Seed004ParameterError naming the parameter)."""
    _check(p["duration_s"] > 0 and p["step_s"] > 0,
           f"duration_s and step_s must be > 0, got {p['duration_s']}, {p['step_s']}")
    _check(p["substeps"] >= 1, f"substeps must be >= 1, got {p['substeps']}")
    _check(p["controller"] in ("energy", "lqr", "none"), f"controller must be energy|lqr|none, got {p['controller']!r}")
    _check(p["estimator"] in ("ekf", "mekf", "truth"), f"estimator must be ekf|mekf|truth, got {p['estimator']!r}")
    _check(p["sun_model"] in ("ephemeris", "paper"), f"sun_model must be ephemeris|paper, got {p['sun_model']!r}")
    _check(p["magnetometer_noise_nT"] >= 0 and p["sun_sensor_noise_deg"] >= 0, "sensor noise must be >= 0")
    _check(0.0 <= p["sun_outage_s"] < orbit_period_s(p["altitude_m"]), "sun_outage_s must be in [0, orbit period)")


def _environment004(
    start: np.int64, t_s: NDArray, time_ns: NDArray, altitude_m: float, inclination_deg: float,
    raan_rad: float | None, u0_rad: float, sun_model: str, sun_outage_s: float, sun_outage_center_u_deg: float,
) -> Environment004:
    """Orbit (node dawn-dusk at the start unless raan_rad), IGRF-14 field, Sun, shadow and outages."""
    a_m = R_EARTH_M + altitude_m
    w0 = float(mean_motion_rad_s(a_m))
    inc = inclination_deg * RAD_PER_DEG
    s_I0 = sun_direction_I(start)
    raan = float(math.atan2(-s_I0[0], s_I0[1])) % (2 * math.pi) if raan_rad is None else float(raan_rad)
    r_I, v_I = circular_orbit_state(t_s, a_m, inc, raan, u0_rad)
    dcm_IO = dcm_IO_lvlh_004(r_I, v_I)
    dcm_EI = gcrs_to_itrs_mat_interp(time_ns, EarthOrientation())
    r_E = np.einsum("kij,kj->ki", dcm_EI, r_I)
    v_E = np.einsum("kij,kj->ki", dcm_EI, v_I) - np.cross([0.0, 0.0, OMEGA_EARTH_RAD_S], r_E)
    B_E = igrf_field_E_nT(r_E, time_ns)
    B_O = np.einsum("kji,klj,kl->ki", dcm_IO, dcm_EI, B_E)  # dcm_OI dcm_IE B_E
    if sun_model == "paper":
        s_O = np.tile([0.0, 1.0, 0.0], (t_s.size, 1))
        sunlit = np.ones(t_s.size)
    else:
        s_O = np.einsum("kji,kj->ki", dcm_IO, sun_direction_I(time_ns))
        sunlit = sunlit_fraction(r_I, sun_position_I_m(time_ns))
    u = (u0_rad + w0 * t_s) % (2 * math.pi)
    du = (u - sun_outage_center_u_deg * RAD_PER_DEG + math.pi) % (2 * math.pi) - math.pi
    outage = np.abs(du) < 0.5 * w0 * sun_outage_s
    return Environment004(r_I, v_I, r_E, v_E, dcm_IO, B_O, s_O, sunlit, (sunlit >= 1.0) & ~outage, w0, inc, raan,
                           a_m)


def _sensors004(
    env: Environment004, q_BM: ArrayLike, q_BS: ArrayLike, magnetometer_noise_nT: float,
    sun_sensor_noise_deg: float, field_model_error: float, rng_mag: Generator, rng_sun: Generator,
) -> Sensors004:
    K = env.B_O.shape[0]
    q_BM_a = rotations.quat_canonical(rotations.quat_normalize(np.asarray(q_BM, dtype=float)))
    q_BS_a = rotations.quat_canonical(rotations.quat_normalize(np.asarray(q_BS, dtype=float)))
    mag_noise = rng_mag.standard_normal((K, 3)) * magnetometer_noise_nT
    sun_rot_noise = rng_sun.standard_normal((K, 3)) * (sun_sensor_noise_deg * RAD_PER_DEG)
    B_O = env.B_O
    B_O_meas = B_O + field_model_error * np.array([1.0, -1.0, 1.0]) * np.linalg.norm(B_O, axis=1, keepdims=True)
    return Sensors004(
        q_BM=q_BM_a, q_BS=q_BS_a, dcm_MB=rotations.quat_to_dcm(rotations.quat_conjugate(q_BM_a)),
        dcm_SB=rotations.quat_to_dcm(rotations.quat_conjugate(q_BS_a)), mag_noise=mag_noise,
        R_sun_noise=rotations.quat_to_dcm(rotations.rotvec_to_quat(sun_rot_noise)), B_O_meas=B_O_meas,
    )


def _design_lqr(env: Environment004, J: NDArray, start: np.int64, step_s: float, altitude_m: float, u0_rad: float,
                lqr_q: float, lqr_r: tuple[float, float, float]) -> AveragedLQR:
    """The averaged LQR (004 eq. 7) designed on the true field over the first orbit."""
    K = env.B_O.shape[0]
    n_orbit = min(K, int(round(orbit_period_s(altitude_m) / step_s)))
    if n_orbit < K:
        B_design = env.B_O[:n_orbit]
    else:
        r1, v1 = circular_orbit_state(np.arange(n_orbit) * step_s, env.a_m, env.inc, env.raan, u0_rad)
        t1 = start + np.round(np.arange(n_orbit) * step_s * NS_PER_S).astype(np.int64)
        m1 = gcrs_to_itrs_mat_interp(t1, EarthOrientation())
        B_design = np.einsum("kji,klj,kl->ki", dcm_IO_lvlh_004(r1, v1), m1,
                             igrf_field_E_nT(np.einsum("kij,kj->ki", m1, r1), t1))
    return design_averaged_lqr(J, env.w0, B_design * 1e-9, step_s=step_s, Q=lqr_q, R=lqr_r)


def _scenario004(
    env: Environment004, sensors: Sensors004, loop: LoopSetup, hist: History, J: NDArray, time_ns: NDArray,
    lqr: AveragedLQR | None, u0_rad: float, parameters: dict[str, Any], gnss_noise: tuple[float, float],
    rng_gnss: Generator, mag_errors: MagnetometerErrors | None = None,
) -> Scenario004:
    """Truth series, GNSS noise (drawn last), streams and configuration; the magnetometer errors applied
    to the stream (B_meas = (I + D) (b_M - n) + b + C mu + n, n the drawn noise)."""
    K, w0 = time_ns.size, env.w0
    b_M = hist.b_M
    if mag_errors is not None:
        b_M = mag_errors.measure(hist.b_M - sensors.mag_noise, hist.mu) + sensors.mag_noise
    q_OB = rotations.quat_canonical(hist.q)
    q_IB = rotations.quat_canonical(rotations.quat_multiply(rotations.dcm_to_quat(env.dcm_IO), q_OB))
    c2_all = rotations.quat_rotate(rotations.quat_conjugate(q_OB), np.array([0.0, 1.0, 0.0]))
    roll, pitch, yaw = roll_pitch_yaw_004(q_OB)
    gnss_r = env.r_E + rng_gnss.standard_normal(env.r_E.shape) * gnss_noise[0]
    gnss_v = env.v_E + rng_gnss.standard_normal(env.v_E.shape) * gnss_noise[1]
    vis = np.flatnonzero(env.sun_visible)
    streams = {
        "magnetometer": {"time_tai_ns": time_ns, **{c: b_M[:, i].copy() for i, c in enumerate(("bx", "by", "bz"))},
                         "sensor": np.full(K, "magnetometer", dtype=object)},
        "sun_sensor": {"time_tai_ns": time_ns[vis],
                       **{c: hist.s_S[vis, i].copy() for i, c in enumerate(("sx", "sy", "sz"))},
                       "sensor": np.full(vis.size, "sun_sensor", dtype=object)},
        "gnss": {"time_tai_ns": time_ns, **{c: gnss_r[:, i].copy() for i, c in enumerate(("x", "y", "z"))},
                 **{c: gnss_v[:, i].copy() for i, c in enumerate(("vx", "vy", "vz"))},
                 "sensor": np.full(K, "gnss", dtype=object)},
        "magnetorquer": {"time_tai_ns": time_ns, **{c: hist.mu[:, i].copy() for i, c in enumerate(("mx", "my", "mz"))},
                         "sensor": np.full(K, "magnetorquer", dtype=object)},
    }
    config = {"magnetometer": {"q_BM": sensors.q_BM.tolist()}, "sun_sensor": {"q_BS": sensors.q_BS.tolist()},
              "inertia_kg_m2": J.tolist()}
    truth = Truth004(
        time_tai_ns=time_ns, q_OB=q_OB, q_IB=q_IB, omega_BI_B=hist.w, omega_BO_B=hist.w + w0 * c2_all, roll_rad=roll,
        pitch_rad=pitch, yaw_rad=yaw, B_O_nT=env.B_O, s_O=env.s_O, sun_visible=env.sun_visible, sunlit=env.sunlit,
        mu_B_A_m2=hist.mu, tau_d_B_N_m=loop.tau_all, q_OB_onboard=rotations.quat_canonical(hist.q_est),
        omega_BO_onboard_B=hist.w_est, r_I=env.r_I, v_I=env.v_I, r_E=env.r_E, v_E=env.v_E, w0_rad_s=w0,
        inclination_rad=env.inc, raan_rad=env.raan, u0_rad=u0_rad, lqr=lqr, magnetometer_errors=mag_errors,
        b_M_ideal_nT=hist.b_M.copy(),
    )
    return Scenario004(streams=streams, config=config, truth=truth, parameters=parameters)
