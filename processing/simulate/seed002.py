"""Truth simulator of paper 002's configuration: a small low-orbit satellite with a GNSS receiver,
a three-axis magnetometer and body-mounted solar panels, with injected gross faults.

Pure and deterministic: the same keyword arguments give bit-identical output; no I/O (the broadcast
ephemerides are passed in as rinex_nav columns). Randomness from ``numpy.random.Generator(PCG64)``
seeded by ``SeedSequence(seed).spawn(8)``: attitude phases, magnetometer noise, current noise, GNSS
noise, visibility misses, and the faults of each of the three streams.

Model:

- orbit: sun-synchronous, initially circular at ``altitude_m`` (550 km), node placed at local time
  ``ltan_h`` (10:30, so a third of the orbit is in the Earth's shadow), integrated in the GCRS with
  the central field and J2_EARTH about the true pole (DOP853, rtol 1e-11), so the two-body energy of the
  truth oscillates as a real orbit's does; ITRS by processing.frames.earth_rotation_interp (IAU 2006/2000A,
  zero EOP);
- attitude relative to the orbital frame O of 002 (Z2 radial, Y2 orbital angular momentum, X2
  completes): pitch J = J0 + A_J sin(.), yaw psi = A_psi sin(.), roll phi = phi0 + rate * t (a slow spin
  about the longitudinal axis X1, which carries the GNSS antenna), with 002's matrix (3);
- magnetometer (1 Hz, frame M, q_BM from the configuration): IGRF-14 field at the true position,
  plus white noise of ``magnetometer_noise_nT`` per axis;
- panel currents (1 Hz, six panels along +-X, +-Y, +-Z): I = I_max nu max(0, n . s_B) + white noise,
  nu the visible fraction of the solar disc (conical shadow model);
- GNSS (1 Hz): ITRS position/velocity plus white noise;
- GNSS visibility (every ``visibility_period_s``): the GPS satellites of the navigation data whose
  line of sight is within ``cone_half_angle_rad`` of the true antenna axis and not hidden by the
  Earth (plus ``GRAZING_ALTITUDE_M``), each missed with probability ``visibility_miss_probability``;
  only tracked satellites are reported (rows with visible = True);
- faults (truth labels in ``Truth002.faults``): GNSS bursts of 1-3 samples with position errors of
  0.5-5 km and/or velocity errors of 5-50 m/s in random directions; magnetometer spikes of
  1500-10000 nT (>= 15 sigma) in random directions; panel currents replaced by a value in
  [0, 1.3 I_max] at least 0.3 I_max away from the true one. Faults of one stream are at least
  ``FAULT_SPACING`` samples apart.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.random import PCG64, Generator, SeedSequence
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from processing.attitude import rotations
from processing.environment import igrf_field_E_nT, sun_position_I_m, sunlit_fraction
from processing.frames.earth_orientation import gcrs_to_itrs_mat
from processing.frames.earth_rotation_interp import gcrs_to_itrs_mat_interp
from processing.frames.orbital import dcm_IO_003
from processing.orbits.gnss_ephemeris import satellite_positions_E
from processing.orbits.two_body import sun_synchronous_inclination_rad
from processing.time.timescales import iso_to_tai_ns
from processing.units import J2_EARTH, MU_EARTH_M3_S2, NS_PER_S, OMEGA_EARTH_RAD_S, R_EARTH_M, RAD_PER_DEG
from processing.vector_attitude.antenna_axis import dcm_EO_002, earth_occulted, line_of_sight_O

GRAZING_ALTITUDE_M = 50e3
FAULT_SPACING = 25
DEFAULT_START_UTC = "2015-10-07T06:00:00"
"""Inside the RINEX 2 GPS file data/gnss-nav/brdc2800.15n (2015-10-07)."""
PANEL_NORMALS_B = ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0),
                   (0.0, 0.0, -1.0))
Q_BM_002 = (np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5))
"""Magnetometer mounting: turned by 90 deg about the body z axis."""


class Seed002ParameterError(ValueError):
    """A simulator parameter outside its domain."""


@dataclass(frozen=True)
class Truth002:
    """Known truth. One row per epoch of the common 1 Hz grid ``time_tai_ns`` (T,):

    r_I, v_I (GCRS), r_E, v_E (ITRS) m, m/s; q_OB (T, 4) (v_O = q_OB o v_B o q_OB^-1) with the 002
    angles pitch_rad, yaw_rad, roll_rad (matrix (3) = dcm_BO); field_O_nT, field_E_nT (T, 3); sun_O
    (T, 3) unit direction from the spacecraft; sunlit_fraction (T,); antenna_O (T, 3) true antenna
    axis in O. Visibility epochs ``visibility_time_tai_ns`` (V,). faults[stream]: (n_rows,) bool per
    row of that stream; fault_kind[stream]: (n_rows,) str ("" where clean). clean_*: the stream values
    before the faults were injected.
    """

    time_tai_ns: NDArray[np.int64]
    r_I: NDArray[np.float64]
    v_I: NDArray[np.float64]
    r_E: NDArray[np.float64]
    v_E: NDArray[np.float64]
    q_OB: NDArray[np.float64]
    pitch_rad: NDArray[np.float64]
    yaw_rad: NDArray[np.float64]
    roll_rad: NDArray[np.float64]
    field_E_nT: NDArray[np.float64]
    field_O_nT: NDArray[np.float64]
    sun_O: NDArray[np.float64]
    sunlit_fraction: NDArray[np.float64]
    antenna_O: NDArray[np.float64]
    visibility_time_tai_ns: NDArray[np.int64]
    faults: dict[str, NDArray[np.bool_]]
    fault_kind: dict[str, NDArray[np.object_]]
    clean: dict[str, dict[str, NDArray[Any]]]
    magnetometer_noise_nT: float
    current_noise_a: float
    gnss_position_noise_m: float
    gnss_velocity_noise_m_s: float


@dataclass(frozen=True)
class Scenario002:
    """streams: {"gnss", "magnetometer", "panel_currents", "gnss_visibility"} -> canonical columns;
    config: DESIGN.md JSON (magnetometer.q_BM, solar_panels, gnss_antenna_axis_B; the antenna cone is
    the processing default of 80 deg unless ``cone_half_angle_rad`` is changed, then pass it to the
    job); truth: :class:`Truth002`; parameters: the arguments used."""

    streams: dict[str, dict[str, NDArray[Any]]]
    config: dict[str, Any]
    truth: Truth002
    parameters: dict[str, Any]


def _check(cond: bool, message: str) -> None:
    if not cond:
        raise Seed002ParameterError(message)


def _unit(x: NDArray[np.float64]) -> NDArray[np.float64]:
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def _random_unit(rng: Generator, n: int) -> NDArray[np.float64]:
    return _unit(rng.standard_normal((n, 3)))


def _fault_rows(rng: Generator, n: int, fraction: float, spacing: int = FAULT_SPACING) -> NDArray[np.int64]:
    """About fraction * n row indices, at least ``spacing`` apart, away from the first/last ``spacing``."""
    k = int(round(fraction * n))
    if k == 0 or n <= 2 * spacing:
        return np.zeros(0, dtype=np.int64)
    slots = np.arange(spacing, n - spacing, spacing)
    k = min(k, slots.size)
    chosen = np.sort(rng.choice(slots, size=k, replace=False))
    return chosen + rng.integers(0, max(1, spacing - 4), size=k)


def _propagate_j2(r0: NDArray[np.float64], v0: NDArray[np.float64], t_s: NDArray[np.float64],
                  pole_I: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Central field + J2_EARTH about the unit pole (GCRS), DOP853; states at t_s (s from the start)."""
    k = 1.5 * J2_EARTH * MU_EARTH_M3_S2 * R_EARTH_M**2

    def rhs(_t: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
        r = y[:3]
        rn2 = float(r @ r)
        rn = np.sqrt(rn2)
        zc = float(r @ pole_I)
        a = -MU_EARTH_M3_S2 * r / (rn2 * rn)
        a += -k / rn2**2 * ((1.0 - 5.0 * zc * zc / rn2) * r / rn + 2.0 * zc / rn * pole_I)
        return np.concatenate([y[3:], a])

    sol = solve_ivp(rhs, (float(t_s[0]), float(t_s[-1])), np.concatenate([r0, v0]), method="DOP853",
                    t_eval=t_s, rtol=1e-11, atol=1e-6)
    if not sol.success:  # pragma: no cover - DOP853 on a smooth LEO problem does not fail
        raise Seed002ParameterError(f"orbit propagation failed: {sol.message}")
    return sol.y[:3].T.copy(), sol.y[3:].T.copy()


def simulate_seed002(
    *,
    nav: Mapping[str, Any],
    start_tai_ns: int | None = None,
    duration_s: float = 5800.0,
    seed: int = 0,
    period_s: float = 1.0,
    visibility_period_s: float = 1.0,
    altitude_m: float = 550e3,
    ltan_h: float = 10.5,
    u0_rad: float = 30.0 * RAD_PER_DEG,
    pitch_mean_rad: float = -40.0 * RAD_PER_DEG,
    pitch_amplitude_rad: float = 10.0 * RAD_PER_DEG,
    yaw_amplitude_rad: float = 20.0 * RAD_PER_DEG,
    roll_rate_rad_s: float = 0.3 * RAD_PER_DEG,
    magnetometer_noise_nT: float = 100.0,
    q_BM: tuple[float, float, float, float] = Q_BM_002,
    max_current_a: float = 1.2,
    current_noise_a: float = 0.01,
    gnss_position_noise_m: float = 5.0,
    gnss_velocity_noise_m_s: float = 0.05,
    antenna_axis_B: tuple[float, float, float] = (1.0, 0.0, 0.0),
    cone_half_angle_rad: float = 80.0 * RAD_PER_DEG,
    visibility_miss_probability: float = 0.01,
    gnss_fault_fraction: float = 0.005,
    magnetometer_fault_fraction: float = 0.005,
    panel_fault_fraction: float = 0.003,
) -> Scenario002:
    """Simulate a 002 segment: GNSS, magnetometer, panel currents and GNSS visibility with truth.

    nav: rinex_nav columns (processing.formats.rinex_nav) of GPS broadcast ephemerides covering the
    segment (data/gnss-nav/brdc2800.15n covers 2015-10-07); start_tai_ns default 2015-10-07T06:00:00 UTC.
    All other arguments keyword-only, SI units (angles rad); see the module docstring.
    Returns :class:`Scenario002`.
    """
    parameters = {k: v for k, v in locals().items() if k not in ("nav", "parameters")}
    _check_parameters(parameters)
    (rng_att, rng_mag, rng_cur, rng_gnss, rng_vis, rng_fg, rng_fm, rng_fp) = (
        Generator(PCG64(s)) for s in SeedSequence(seed).spawn(8))
    start = int(iso_to_tai_ns([DEFAULT_START_UTC])[0]) if start_tai_ns is None else int(start_tai_ns)
    n = int(np.floor(duration_s / period_s + 1e-9)) + 1
    t_s = np.asarray(np.arange(n) * period_s, dtype=np.float64)
    time_ns = start + np.round(t_s * NS_PER_S).astype(np.int64)
    orbit = _orbit(start, t_s, time_ns, altitude_m, ltan_h, u0_rad)
    att = _attitude(t_s, pitch_mean_rad, pitch_amplitude_rad, yaw_amplitude_rad, roll_rate_rad_s, rng_att)
    env = _environment(orbit, time_ns)
    q_BM_arr = rotations.quat_normalize(np.asarray(q_BM, dtype=float))
    b_M = _magnetometer(att, env, q_BM_arr, magnetometer_noise_nT, rng_mag)
    cur = _panel_currents(att, env, max_current_a, current_noise_a, rng_cur)
    gnss_r = orbit.r_E + rng_gnss.standard_normal((n, 3)) * gnss_position_noise_m
    gnss_v = orbit.v_E + rng_gnss.standard_normal((n, 3)) * gnss_velocity_noise_m_s
    a_B = _unit(np.asarray(antenna_axis_B, dtype=float))
    antenna_O = np.einsum("nji,j->ni", att.dcm_BO, a_B)
    vis = _visibility(nav, orbit, time_ns, antenna_O, visibility_period_s / period_s, cone_half_angle_rad,
                      visibility_miss_probability, rng_vis)
    gf = _gnss_faults(gnss_r, gnss_v, gnss_fault_fraction, rng_fg)
    mf = _magnetometer_faults(b_M, magnetometer_fault_fraction, rng_fm)
    pf = _panel_faults(cur, panel_fault_fraction, max_current_a, rng_fp)
    streams = _streams002(time_ns, gf.r, gf.v, mf.values, pf.values, vis)
    faults = {"gnss": gf.fault, "magnetometer": mf.fault, "panel_currents": pf.fault.reshape(-1),
              "gnss_visibility": np.zeros(vis.time_index.size, bool)}
    kinds = {"gnss": gf.kind, "magnetometer": mf.kind,
             "panel_currents": np.where(faults["panel_currents"], "current", "").astype(object),
             "gnss_visibility": np.full(vis.time_index.size, "", dtype=object)}
    config = {
        "magnetometer": {"q_BM": q_BM_arr.tolist()},
        "solar_panels": [{"normal_B": list(nrm), "max_current_a": max_current_a} for nrm in PANEL_NORMALS_B],
        "gnss_antenna_axis_B": a_B.tolist(),
    }
    truth = Truth002(
        time_tai_ns=time_ns, r_I=orbit.r_I, v_I=orbit.v_I, r_E=orbit.r_E, v_E=orbit.v_E, q_OB=att.q_OB,
        pitch_rad=att.pitch, yaw_rad=att.yaw, roll_rad=att.roll, field_E_nT=env.field_E, field_O_nT=env.field_O,
        sun_O=env.sun_O, sunlit_fraction=env.sunlit, antenna_O=antenna_O, visibility_time_tai_ns=time_ns[vis.rows],
        faults=faults, fault_kind=kinds,
        clean={"gnss": {"r_E": gnss_r, "v_E": gnss_v}, "magnetometer": {"b_M": b_M},
               "panel_currents": {"current_a": cur.reshape(-1)}},
        magnetometer_noise_nT=magnetometer_noise_nT, current_noise_a=current_noise_a,
        gnss_position_noise_m=gnss_position_noise_m, gnss_velocity_noise_m_s=gnss_velocity_noise_m_s,
    )
    return Scenario002(streams=streams, config=config, truth=truth, parameters=parameters)


def _check_parameters(p: dict[str, Any]) -> None:
    """The parameter domains of :func:`simulate_seed002` (Seed002ParameterError naming the parameter)."""
    _check(p["duration_s"] > 10 * p["period_s"], f"duration_s must exceed 10 periods, got {p['duration_s']}")
    _check(p["period_s"] > 0 and p["visibility_period_s"] > 0, "periods must be > 0")
    _check(p["altitude_m"] > 100e3, f"altitude_m must be > 100 km, got {p['altitude_m']}")
    for name in ("gnss_fault_fraction", "magnetometer_fault_fraction", "panel_fault_fraction",
                 "visibility_miss_probability"):
        _check(0.0 <= p[name] < 0.04, f"{name} must be in [0, 0.04), got {p[name]}")
    _check(min(p["magnetometer_noise_nT"], p["current_noise_a"], p["gnss_position_noise_m"],
               p["gnss_velocity_noise_m_s"]) >= 0, "noise levels must be >= 0")
    _check(0 < p["cone_half_angle_rad"] < np.pi, "cone_half_angle_rad must be in (0, pi)")


@dataclass(frozen=True)
class _Orbit:
    """The true orbit on the grid: GCRS r_I, v_I and ITRS r_E, v_E (n, 3), GCRS -> ITRS matrices (n, 3, 3)."""

    r_I: NDArray[np.float64]
    v_I: NDArray[np.float64]
    r_E: NDArray[np.float64]
    v_E: NDArray[np.float64]
    dcm_EI: NDArray[np.float64]


def _orbit(start: int, t_s: NDArray[np.float64], time_ns: NDArray[np.int64], altitude_m: float, ltan_h: float,
           u0_rad: float) -> _Orbit:
    """Sun-synchronous, node at local time ltan_h, J2_EARTH about the true pole; ITRS with zero EOP."""
    a = R_EARTH_M + altitude_m
    inc = float(sun_synchronous_inclination_rad(a))
    sun0 = sun_position_I_m(np.array([start]))[0]
    raan = float(np.arctan2(sun0[1], sun0[0])) + (ltan_h - 12.0) * 15.0 * RAD_PER_DEG
    node = np.array([np.cos(raan), np.sin(raan), 0.0])
    normal = np.array([np.sin(raan) * np.sin(inc), -np.cos(raan) * np.sin(inc), np.cos(inc)])
    along = np.cross(normal, node)
    r0 = a * (np.cos(u0_rad) * node + np.sin(u0_rad) * along)
    v0 = np.sqrt(MU_EARTH_M3_S2 / a) * (-np.sin(u0_rad) * node + np.cos(u0_rad) * along)
    pole_I = np.asarray(gcrs_to_itrs_mat(np.array([start]))[0][2], dtype=np.float64)  # ITRS z axis in the GCRS
    r_I, v_I = _propagate_j2(r0, v0, t_s, pole_I)
    dcm_EI = gcrs_to_itrs_mat_interp(time_ns)  # zero EOP: the rotation axis is the ITRS z axis
    r_E = np.einsum("nij,nj->ni", dcm_EI, r_I)
    v_E = np.einsum("nij,nj->ni", dcm_EI, v_I) - np.cross([0.0, 0.0, OMEGA_EARTH_RAD_S], r_E)
    return _Orbit(r_I, v_I, r_E, v_E, dcm_EI)


@dataclass(frozen=True)
class _Attitude:
    """The 002 angles (n,) rad, dcm_BO (n, 3, 3) (matrix (3)) and q_OB (n, 4)."""

    pitch: NDArray[np.float64]
    yaw: NDArray[np.float64]
    roll: NDArray[np.float64]
    dcm_BO: NDArray[np.float64]
    q_OB: NDArray[np.float64]


def _attitude(t_s: NDArray[np.float64], pitch_mean_rad: float, pitch_amplitude_rad: float, yaw_amplitude_rad: float,
              roll_rate_rad_s: float, rng: Generator) -> _Attitude:
    """Pitch and yaw oscillations with random phases, roll spinning at roll_rate_rad_s (002 angles)."""
    ph = rng.uniform(0.0, 2.0 * np.pi, size=3)
    pitch = pitch_mean_rad + pitch_amplitude_rad * np.sin(2 * np.pi * t_s / 1300.0 + ph[0])
    yaw = yaw_amplitude_rad * np.sin(2 * np.pi * t_s / 2100.0 + ph[1])
    roll = rotations._wrap_pi(ph[2] + roll_rate_rad_s * t_s)
    dcm_BO = rotations.dcm_from_angles_002(pitch, yaw, roll)
    q_OB = rotations.quat_canonical(rotations.quat_conjugate(rotations.quat_from_angles_002(pitch, yaw, roll)))
    return _Attitude(pitch, yaw, roll, dcm_BO, q_OB)


@dataclass(frozen=True)
class _Environment:
    """Along the true orbit: IGRF-14 field in E and O (n, 3) nT, the Sun direction in O and the sunlit
    fraction of the solar disc (n,)."""

    field_E: NDArray[np.float64]
    field_O: NDArray[np.float64]
    sun_O: NDArray[np.float64]
    sunlit: NDArray[np.float64]


def _environment(orbit: _Orbit, time_ns: NDArray[np.int64]) -> _Environment:
    dcm_IO = dcm_IO_003(orbit.r_I, orbit.v_I)
    field_E = igrf_field_E_nT(orbit.r_E, time_ns)
    field_I = np.einsum("nji,nj->ni", orbit.dcm_EI, field_E)
    field_O = np.einsum("nji,nj->ni", dcm_IO, field_I)
    r_sun = sun_position_I_m(time_ns)
    nu = sunlit_fraction(orbit.r_I, r_sun)
    sun_O = np.einsum("nji,nj->ni", dcm_IO, _unit(r_sun - orbit.r_I))
    return _Environment(field_E, field_O, sun_O, nu)


def _magnetometer(att: _Attitude, env: _Environment, q_BM: NDArray[np.float64], noise_nT: float,
                  rng: Generator) -> NDArray[np.float64]:
    """The field in the magnetometer frame (n, 3) nT plus white noise."""
    dcm_MB = rotations.quat_to_dcm(q_BM).T
    b_B = np.einsum("nij,nj->ni", att.dcm_BO, env.field_O)
    return b_B @ dcm_MB.T + rng.standard_normal((b_B.shape[0], 3)) * noise_nT


def _panel_currents(att: _Attitude, env: _Environment, max_current_a: float, noise_a: float,
                    rng: Generator) -> NDArray[np.float64]:
    """I = I_max nu max(0, n . s_B) + white noise (n, 6) A."""
    normals = np.array(PANEL_NORMALS_B)
    s_B = np.einsum("nij,nj->ni", att.dcm_BO, env.sun_O)
    cur = max_current_a * env.sunlit[:, None] * np.maximum(0.0, s_B @ normals.T)
    return cur + rng.standard_normal(cur.shape) * noise_a


@dataclass(frozen=True)
class _Visibility:
    """GNSS visibility: the grid rows of the visibility epochs, the satellites considered, and the
    (epoch, satellite) indices of the tracked ones."""

    rows: NDArray[np.int64]
    sats: list[str]
    time_index: NDArray[np.intp]
    sat_index: NDArray[np.intp]


def _visibility(nav: Mapping[str, Any], orbit: _Orbit, time_ns: NDArray[np.int64], antenna_O: NDArray[np.float64],
                steps_per_epoch: float, cone_half_angle_rad: float, miss_probability: float,
                rng: Generator) -> _Visibility:
    """GPS satellites within the antenna cone, not hidden by the Earth, each missed with a probability."""
    vi = np.arange(0, time_ns.size, max(1, int(round(steps_per_epoch))))
    sats = sorted({str(s) for s in np.asarray(nav["sat"]).astype(str) if s.startswith("G")})
    pos = satellite_positions_E(nav, time_ns[vi], sats)
    g = line_of_sight_O(pos.r_E, orbit.r_E[vi], dcm_EO_002(orbit.r_E[vi], orbit.v_E[vi]))
    cosang = np.einsum("tsi,ti->ts", np.nan_to_num(g), antenna_O[vi])
    occ = earth_occulted(g, np.linalg.norm(orbit.r_E[vi], axis=1), GRAZING_ALTITUDE_M)
    visible = pos.valid & ~occ & (cosang >= np.cos(cone_half_angle_rad))
    visible &= rng.random(visible.shape) >= miss_probability
    ti, si = np.nonzero(visible)
    return _Visibility(vi, sats, ti, si)


@dataclass(frozen=True)
class _GnssFaults:
    """GNSS with the faults: r, v (n, 3), the faulty rows (n,) and their kind ("" where clean)."""

    r: NDArray[np.float64]
    v: NDArray[np.float64]
    fault: NDArray[np.bool_]
    kind: NDArray[np.object_]


def _gnss_faults(gnss_r: NDArray[np.float64], gnss_v: NDArray[np.float64], fraction: float,
                 rng: Generator) -> _GnssFaults:
    """Bursts of 1-3 samples with position errors of 0.5-5 km and/or velocity errors of 5-50 m/s."""
    n = gnss_r.shape[0]
    starts = _fault_rows(rng, n, fraction / 2.0)  # bursts of 2 samples on average
    lengths = rng.integers(1, 4, size=starts.size)
    burst = np.unique(np.concatenate([np.zeros(0, np.int64)] + [s + np.arange(k) for s, k in
                                                                zip(starts, lengths, strict=True)]))
    burst = burst[burst < n]
    gkind = rng.integers(0, 3, size=burst.size)  # 0 position, 1 velocity, 2 both
    dpos = _random_unit(rng, burst.size) * rng.uniform(500.0, 5000.0, size=(burst.size, 1))
    dvel = _random_unit(rng, burst.size) * rng.uniform(5.0, 50.0, size=(burst.size, 1))
    r, v = gnss_r.copy(), gnss_v.copy()
    r[burst] += np.where((gkind != 1)[:, None], dpos, 0.0)
    v[burst] += np.where((gkind != 0)[:, None], dvel, 0.0)
    fault = np.zeros(n, bool)
    fault[burst] = True
    kind = np.full(n, "", dtype=object)
    kind[burst] = np.array(["position", "velocity", "position+velocity"], dtype=object)[gkind]
    return _GnssFaults(r, v, fault, kind)


@dataclass(frozen=True)
class _Faults:
    """A stream's values with the faults injected, the faulty entries and (magnetometer) their kind."""

    values: NDArray[np.float64]
    fault: NDArray[np.bool_]
    kind: NDArray[np.object_]


def _magnetometer_faults(b_M: NDArray[np.float64], fraction: float, rng: Generator) -> _Faults:
    """Spikes of 1500-10000 nT in random directions."""
    n = b_M.shape[0]
    m_rows = _fault_rows(rng, n, fraction)
    values = b_M.copy()
    values[m_rows] += _random_unit(rng, m_rows.size) * rng.uniform(1500.0, 10000.0, size=(m_rows.size, 1))
    fault = np.zeros(n, bool)
    fault[m_rows] = True
    return _Faults(values, fault, np.where(fault, "spike", "").astype(object))


def _panel_faults(cur: NDArray[np.float64], fraction: float, max_current_a: float, rng: Generator) -> _Faults:
    """Epochs spaced apart, one panel each, the current replaced by a value in [0, 1.3 I_max] at least
    0.3 I_max from the true one."""
    n, n_p = cur.shape
    p_epochs = _fault_rows(rng, n, fraction * n_p)
    p_panel = rng.integers(0, n_p, size=p_epochs.size)
    true_cur = cur[p_epochs, p_panel]
    bad_val = true_cur.copy()
    todo = np.ones(p_epochs.size, bool)
    while np.any(todo):
        bad_val[todo] = rng.uniform(0.0, 1.3 * max_current_a, size=int(todo.sum()))
        todo = np.abs(bad_val - true_cur) < 0.3 * max_current_a
    values = cur.copy()
    values[p_epochs, p_panel] = bad_val
    fault = np.zeros(cur.shape, bool)
    fault[p_epochs, p_panel] = True
    return _Faults(values, fault, np.zeros(0, dtype=object))


def _streams002(
    time_ns: NDArray[np.int64], gnss_r: NDArray[np.float64], gnss_v: NDArray[np.float64], b_M: NDArray[np.float64],
    cur: NDArray[np.float64], vis: _Visibility,
) -> dict[str, dict[str, NDArray[Any]]]:
    """The four streams in their canonical columns."""
    n, n_p = cur.shape
    ti, si = vis.time_index, vis.sat_index
    return {
        "gnss": {"time_tai_ns": time_ns, **{c: gnss_r[:, i].copy() for i, c in enumerate("xyz")},
                 **{c: gnss_v[:, i].copy() for i, c in enumerate(("vx", "vy", "vz"))},
                 "sensor": np.full(n, "gnss", dtype=object)},
        "magnetometer": {"time_tai_ns": time_ns, **{c: b_M[:, i].copy() for i, c in enumerate(("bx", "by", "bz"))},
                         "sensor": np.full(n, "mag1", dtype=object)},
        "panel_currents": {"time_tai_ns": np.repeat(time_ns, n_p), "panel": np.tile(np.arange(n_p, dtype=np.int64), n),
                           "current_a": cur.reshape(-1).copy(), "sensor": np.full(n * n_p, "panel_currents",
                                                                                   dtype=object)},
        "gnss_visibility": {"time_tai_ns": time_ns[vis.rows][ti], "system": np.full(ti.size, "G", dtype=object),
                            "prn": np.array([int(vis.sats[k][1:]) for k in si], dtype=np.int64),
                            "visible": np.ones(ti.size, dtype=bool),
                            "sensor": np.full(ti.size, "gnss_visibility", dtype=object)},
    }
