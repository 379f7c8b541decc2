"""Tests of processing.orbits.two_body: circular two-body states, J2_EARTH node rate, sun-synchronous inclination."""

import numpy as np
import pytest

from processing.orbits.two_body import (
    SUN_MEAN_MOTION_RAD_S,
    OrbitInputError,
    circular_orbit_state,
    j2_raan_rate_rad_s,
    mean_motion_rad_s,
    specific_energy_j_kg,
    sun_synchronous_inclination_rad,
)
from processing.units import J2_EARTH, MU_EARTH_M3_S2, R_EARTH_M

A_830_M = R_EARTH_M + 830e3


def test_constants_are_the_published_values():
    # GM and a of WGS 84 (NGA.STND.0036); J2_EARTH of EGM96 from its normalised C20bar = -0.484165371736e-3.
    assert MU_EARTH_M3_S2 == 3.986004418e14
    assert R_EARTH_M == 6378137.0
    assert J2_EARTH == pytest.approx(-np.sqrt(5.0) * -0.484165371736e-3, rel=1e-8)
    assert SUN_MEAN_MOTION_RAD_S == pytest.approx(2 * np.pi / (365.2421897 * 86400.0), rel=1e-15)


def test_circular_orbit_radius_energy_and_angular_momentum_are_constant():
    t = np.linspace(0.0, 12000.0, 5001)
    r, v = circular_orbit_state(t, A_830_M, np.deg2rad(98.7), np.deg2rad(40.0), np.deg2rad(10.0))
    assert r.shape == v.shape == (t.size, 3)
    np.testing.assert_allclose(np.linalg.norm(r, axis=-1), A_830_M, rtol=1e-15)
    energy = specific_energy_j_kg(r, v)
    expected = -MU_EARTH_M3_S2 / (2.0 * A_830_M)
    np.testing.assert_allclose(energy, expected, rtol=1e-14)
    h = np.cross(r, v)
    np.testing.assert_allclose(h, np.broadcast_to(h[0], h.shape), atol=1e-13 * np.linalg.norm(h[0]))
    # circular: velocity perpendicular to radius, |v| = sqrt(mu / a)
    np.testing.assert_allclose(np.sum(r * v, axis=-1) / (A_830_M * np.sqrt(MU_EARTH_M3_S2 / A_830_M)), 0, atol=1e-15)


def test_circular_orbit_elements_hand_computed():
    # u0 = 0 at t = 0: at the ascending node, r along the node line (cos raan, sin raan, 0)
    raan, inc = np.deg2rad(30.0), np.deg2rad(60.0)
    r, v = circular_orbit_state(0.0, A_830_M, inc, raan, 0.0)
    np.testing.assert_allclose(r, A_830_M * np.array([np.cos(raan), np.sin(raan), 0.0]), rtol=1e-15)
    speed = np.sqrt(MU_EARTH_M3_S2 / A_830_M)
    expected_v = speed * np.array([-np.sin(raan) * np.cos(inc), np.cos(raan) * np.cos(inc), np.sin(inc)])
    np.testing.assert_allclose(v, expected_v, rtol=1e-14)
    # a quarter period later: at the northernmost point, z = a sin i
    quarter = 0.5 * np.pi / mean_motion_rad_s(A_830_M)
    r_q, _ = circular_orbit_state(quarter, A_830_M, inc, raan, 0.0)
    assert r_q[2] == pytest.approx(A_830_M * np.sin(inc), rel=1e-14)


@pytest.mark.parametrize("raan_rate", [0.0, 1e-4])
def test_velocity_is_the_time_derivative_of_position(raan_rate):
    t = np.linspace(0.0, 6000.0, 61)
    h = 0.01
    args = (A_830_M, np.deg2rad(98.7), 1.0, 0.3, raan_rate)
    r_p, _ = circular_orbit_state(t + h, *args)
    r_m, _ = circular_orbit_state(t - h, *args)
    _, v = circular_orbit_state(t, *args)
    # central difference: truncation h^2/6 |r'''| <= h^2/6 (n + raan_rate)^3 a ~ 2e-6 m/s
    np.testing.assert_allclose((r_p - r_m) / (2 * h), v, atol=1e-5)


def test_scalar_and_array_time_agree():
    args = (A_830_M, 1.7, 0.2, 0.4, 2e-7)
    r_arr, v_arr = circular_orbit_state(np.array([0.0, 100.0]), *args)
    r_s, v_s = circular_orbit_state(100.0, *args)
    np.testing.assert_array_equal(r_arr[1], r_s)
    np.testing.assert_array_equal(v_arr[1], v_s)


def test_sun_synchronous_inclination_textbook_values():
    # Wikipedia "Sun-synchronous orbit" (section "Technical details"): a = 7200 km, i.e. ~800 km
    # altitude, gives a sun-synchronous inclination of 98.7 deg.
    assert np.rad2deg(sun_synchronous_inclination_rad(7200e3)) == pytest.approx(98.7, abs=0.05)
    # Meteor-M (003): ~830 km circular sun-synchronous orbit, 98.7-98.8 deg.
    inc_830 = np.rad2deg(sun_synchronous_inclination_rad(A_830_M))
    assert 98.7 <= inc_830 <= 98.8


def test_sun_synchronous_node_rate_equals_sun_mean_motion():
    a = np.array([6878e3, A_830_M, 7500e3])
    inc = sun_synchronous_inclination_rad(a)
    np.testing.assert_allclose(j2_raan_rate_rad_s(a, inc), SUN_MEAN_MOTION_RAD_S, rtol=1e-13)
    # ~0.9856 deg/day
    assert np.rad2deg(SUN_MEAN_MOTION_RAD_S) * 86400.0 == pytest.approx(0.98565, abs=1e-5)


def test_j2_raan_rate_hand_computed():
    # -3/2 n J2_EARTH (R/p)^2 cos i at a = 7000 km, e = 0.1, i = 50 deg, written out
    a, e, inc = 7000e3, 0.1, np.deg2rad(50.0)
    n = np.sqrt(3.986004418e14 / a**3)
    p = a * (1 - e**2)
    expected = -1.5 * n * 1.08262668e-3 * (6378137.0 / p) ** 2 * np.cos(inc)
    assert j2_raan_rate_rad_s(a, inc, e) == pytest.approx(expected, rel=1e-15)
    assert j2_raan_rate_rad_s(a, np.pi / 2) == pytest.approx(0.0, abs=1e-20)


def test_sun_synchronous_inclination_eccentric_uses_semi_latus_rectum():
    a, e = 7200e3, 0.05
    inc = sun_synchronous_inclination_rad(a, e)
    assert j2_raan_rate_rad_s(a, inc, e) == pytest.approx(SUN_MEAN_MOTION_RAD_S, rel=1e-13)


def test_errors():
    with pytest.raises(OrbitInputError, match="no sun-synchronous inclination"):
        sun_synchronous_inclination_rad(20000e3)
    with pytest.raises(OrbitInputError, match="semi-major axis must be > 0"):
        circular_orbit_state(0.0, -1.0, 0.0, 0.0, 0.0)
    with pytest.raises(OrbitInputError, match="eccentricity"):
        sun_synchronous_inclination_rad(7000e3, 1.2)
    with pytest.raises(OrbitInputError, match=r"shape \(\.\.\., 3\)"):
        specific_energy_j_kg(np.zeros(2), np.zeros(3))


def test_specific_energy_hand_computed():
    r = np.array([7000e3, 0.0, 0.0])
    v = np.array([0.0, 7500.0, 0.0])
    assert specific_energy_j_kg(r, v) == pytest.approx(0.5 * 7500.0**2 - 3.986004418e14 / 7000e3, rel=1e-15)
