"""Small two-body orbit tools: circular orbits, J2_EARTH nodal rate, sun-synchronous inclination, energy.

Used by the scenario simulators and by screening (specific energy, 002 eq. 15). Pure numpy,
vectorised over samples; SI units (m, s, rad).

Constants
---------
- ``MU_EARTH_M3_S2 = 3.986004418e14``: geocentric gravitational constant GM of WGS 84 / EGM2008
  (NGA.STND.0036, WGS 84, 2014; identical to the IERS Conventions 2010 value).
- ``R_EARTH_M = 6378137.0``: WGS 84 / GRS 80 equatorial radius.
- ``J2_EARTH = 1.08262668e-3``: unnormalised second zonal harmonic of EGM96 (J2_EARTH = -sqrt(5) C20bar with
  the normalised C20bar = -0.484165371736e-3), the value tabulated by Vallado. (WGS 84's
  J2_EARTH = 1.0826298e-3; the 3e-6 relative difference moves the sun-synchronous inclination by ~3e-5 deg.)
- ``SUN_MEAN_MOTION_RAD_S``: 2 pi per tropical year of 365.2421897 days, the rate at which the
  mean Sun moves in right ascension; a sun-synchronous node precesses at this rate.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.units import J2_EARTH, MU_EARTH_M3_S2, R_EARTH_M, S_PER_DAY, TROPICAL_YEAR_DAYS

SUN_MEAN_MOTION_RAD_S = 2.0 * np.pi / (TROPICAL_YEAR_DAYS * S_PER_DAY)


class OrbitInputError(ValueError):
    """Orbit tool input of the wrong shape or outside the physical domain."""


def mean_motion_rad_s(a_m: ArrayLike, mu_m3_s2: float = MU_EARTH_M3_S2) -> NDArray:
    """Keplerian mean motion n = sqrt(mu / a^3) [rad/s] for semi-major axis ``a_m`` [m]."""
    a = np.asarray(a_m, dtype=float)
    if np.any(a <= 0.0):
        raise OrbitInputError(f"semi-major axis must be > 0 m, got min {np.min(a)!r}")
    return np.sqrt(mu_m3_s2 / a**3)


def circular_orbit_state(
    t_s: ArrayLike,
    a_m: float,
    inc_rad: float,
    raan_rad: float,
    u0_rad: float,
    raan_rate_rad_s: float = 0.0,
    *,
    mu_m3_s2: float = MU_EARTH_M3_S2,
) -> tuple[NDArray, NDArray]:
    """Position and velocity on a circular orbit, in the inertial frame of the elements.

    Parameters
    ----------
    t_s : (...) seconds since the epoch at which the argument of latitude is ``u0_rad``.
    a_m : orbit radius [m].
    inc_rad, raan_rad : inclination and right ascension of the ascending node at t = 0 [rad].
    u0_rad : argument of latitude at t = 0 [rad] (angle from the ascending node along the orbit).
    raan_rate_rad_s : secular node rate [rad/s]; 0 gives an exact two-body (Keplerian) orbit.

    Returns
    -------
    r_I, v_I : (..., 3) [m], [m/s]. With u = u0 + n t and RAAN = raan + raan_rate t,
        r_I = a (cos RAAN cos u - sin RAAN cos i sin u, sin RAAN cos u + cos RAAN cos i sin u, sin i sin u)
    and v_I = dr_I/dt exactly, i.e. v_I = n dr/du + raan_rate z x r_I (the second term is absent for
    a two-body orbit). With a non-zero node rate the state is a kinematic model of a J2_EARTH-precessing
    circular orbit, not a solution of the two-body problem: its specific energy then varies by
    about (raan_rate a sin i)^2 / 2 (~1e-3 J/kg at 830 km, 4e-11 relative).
    """
    t = np.asarray(t_s, dtype=float)
    n = mean_motion_rad_s(a_m, mu_m3_s2)
    u = u0_rad + n * t
    raan = raan_rad + raan_rate_rad_s * t
    cu, su = np.cos(u), np.sin(u)
    co, so = np.cos(raan), np.sin(raan)
    ci, si = np.cos(inc_rad), np.sin(inc_rad)
    # Unit vectors along the node line rotated by u (radial) and its derivative wrt u (transversal).
    radial = np.stack([co * cu - so * ci * su, so * cu + co * ci * su, si * su], axis=-1)
    transversal = np.stack([-co * su - so * ci * cu, -so * su + co * ci * cu, si * cu], axis=-1)
    r_I = a_m * radial
    v_I = a_m * n * transversal
    if raan_rate_rad_s != 0.0:
        z_cross_r = np.stack([-r_I[..., 1], r_I[..., 0], np.zeros_like(r_I[..., 0])], axis=-1)
        v_I = v_I + raan_rate_rad_s * z_cross_r
    return r_I, v_I


def j2_raan_rate_rad_s(
    a_m: ArrayLike,
    inc_rad: ArrayLike,
    e: ArrayLike = 0.0,
    *,
    mu_m3_s2: float = MU_EARTH_M3_S2,
    r_earth_m: float = R_EARTH_M,
    j2: float = J2_EARTH,
) -> NDArray:
    """Secular J2_EARTH rate of the right ascension of the ascending node [rad/s].

    dRAAN/dt = -3/2 n J2_EARTH (R / p)^2 cos i, with p = a (1 - e^2) (first-order secular J2_EARTH theory,
    e.g. Vallado, Fundamentals of Astrodynamics and Applications, chapter 9).
    """
    a = np.asarray(a_m, dtype=float)
    e_arr = np.asarray(e, dtype=float)
    if np.any((e_arr < 0.0) | (e_arr >= 1.0)):
        raise OrbitInputError(f"eccentricity must be in [0, 1), got {e!r}")
    p = a * (1.0 - e_arr**2)
    return -1.5 * mean_motion_rad_s(a, mu_m3_s2) * j2 * (r_earth_m / p) ** 2 * np.cos(inc_rad)


def sun_synchronous_inclination_rad(
    a_m: ArrayLike,
    e: ArrayLike = 0.0,
    *,
    mu_m3_s2: float = MU_EARTH_M3_S2,
    r_earth_m: float = R_EARTH_M,
    j2: float = J2_EARTH,
) -> NDArray:
    """Inclination [rad] whose J2_EARTH secular node rate equals the Sun's mean motion.

    Solves j2_raan_rate_rad_s(a, i, e) = SUN_MEAN_MOTION_RAD_S (2 pi / 365.2421897 d):
    cos i = -SUN_MEAN_MOTION_RAD_S / (3/2 n J2_EARTH (R / p)^2). Raises OrbitInputError where no
    sun-synchronous orbit exists (|cos i| > 1, i.e. p above about 12 350 km).
    """
    a = np.asarray(a_m, dtype=float)
    e_arr = np.asarray(e, dtype=float)
    if np.any((e_arr < 0.0) | (e_arr >= 1.0)):
        raise OrbitInputError(f"eccentricity must be in [0, 1), got {e!r}")
    p = a * (1.0 - e_arr**2)
    cos_i = -SUN_MEAN_MOTION_RAD_S / (1.5 * mean_motion_rad_s(a, mu_m3_s2) * j2 * (r_earth_m / p) ** 2)
    if np.any(np.abs(cos_i) > 1.0):
        raise OrbitInputError(
            f"no sun-synchronous inclination for a_m={a_m!r}, e={e!r}: required cos i = {cos_i!r}"
        )
    return np.arccos(cos_i)


def specific_energy_j_kg(r: ArrayLike, v: ArrayLike, *, mu_m3_s2: float = MU_EARTH_M3_S2) -> NDArray:
    """Two-body specific orbital energy |v|^2 / 2 - mu / |r| [J/kg] for r (...,3) [m], v (...,3) [m/s].

    Valid in any inertial frame (in an Earth-fixed frame use the inertial velocity). 002 eq. 15
    uses h = v^2 - 2 mu / r = 2 * this value.
    """
    r_arr = np.asarray(r, dtype=float)
    v_arr = np.asarray(v, dtype=float)
    if r_arr.shape[-1:] != (3,) or v_arr.shape[-1:] != (3,):
        raise OrbitInputError(f"expected r and v of shape (..., 3), got {r_arr.shape} and {v_arr.shape}")
    return 0.5 * np.sum(v_arr**2, axis=-1) - mu_m3_s2 / np.linalg.norm(r_arr, axis=-1)
