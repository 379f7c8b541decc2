"""Tests of processing.environment: IGRF-14, the 002 dipole, the Sun, Earth shadow, and the fast Earth
rotation matrix used with them.

Reference values:
- tests/data/igrf14_test_geocentric.txt, igrf14_test_geodetic.txt: output of the official IAGA IGRF-14
  synthesis program igrf14syn (see the files' headers for the source).
- BGS pyIGRF (C. Beggan, British Geological Survey, the IAGA reference Python code distributed with
  IGRF-14), tests/tests_igrf14.py: geocentric X, Y, Z "checked independently against igrf.f".
- IGRF-14 coefficients (IAGA V-MOD 2024, doi:10.5281/zenodo.14012302): g10(2025) = -29350.0 nT,
  g11 = -1410.3, h11 = 4545.5; secular variation 2025-2030 g10 = 12.6, g11 = 10.0, h11 = -21.5 nT/yr.
- Sun: Meeus, Astronomical Algorithms (2nd ed. 1998), example 25.b (VSOP87, 1992 October 13.0 TD):
  apparent alpha = 13h13m30.749s, delta = -7d47'01.74", R = 0.99760853 au (geometric).
  2024 March equinox: 2024-03-20 03:06 UTC (US Naval Observatory, Earth's seasons 2024).
"""

import datetime

import erfa
import numpy as np
import ppigrf
import pytest

from processing.environment import (
    DIPOLE_MOMENT_002_T_M3,
    PENUMBRA,
    SUNLIT,
    UMBRA,
    IGRFValueError,
    decimal_year_utc,
    dipole_field_O002_nT,
    dipole_field_O004_nT,
    dipole_moment_igrf_T_m3,
    eclipse_state,
    igrf14_coefficients,
    igrf_field_E_nT,
    igrf_field_E_nT_at,
    igrf_field_geocentric_nT,
    igrf_field_ned_nT,
    in_shadow_cylindrical,
    sun_direction_from_I,
    sun_direction_I,
    sun_position_I_m,
    sunlit_fraction,
)
from processing.environment.igrf import E_from_geodetic, dcm_E_ned, geodetic_from_E, igrf_gauss_coefficients_nT
from processing.environment.sun import _sun_pv_direct
from processing.frames.earth_orientation import EarthOrientation, gcrs_to_itrs_mat, itrs_to_gcrs_state
from processing.frames.earth_rotation_interp import gcrs_to_itrs_mat_interp, itrs_to_gcrs_state_interp
from processing.frames.orbital import dcm_IO_003, dcm_IO_lvlh_004
from processing.orbits.two_body import circular_orbit_state, mean_motion_rad_s
from processing.time.timescales import TT_MINUS_TAI_NS, iso_to_tai_ns
from processing.units import AU_M, R_EARTH_M
from tests.real_data import REFERENCE

DATA = REFERENCE
ARCSEC = np.pi / (180 * 3600)
DEG = np.pi / 180


def _reference(name: str) -> np.ndarray:
    d = np.loadtxt(DATA / name)
    return d[d[:, 0] <= 2030.0]


# ---------------------------------------------------------------------------------------------- IGRF


def test_packaged_coefficients_are_igrf14() -> None:
    c = igrf14_coefficients()
    assert c.nmax == 13 and c.valid_from_year == 1900.0 and c.valid_to_year == 2030.0
    g, h = igrf_gauss_coefficients_nT(np.array([2025.0, 2030.0]))
    assert (g[0, 1, 0], g[0, 1, 1], h[0, 1, 1]) == (-29350.0, -1410.3, 4545.5)
    sv = (g[1] - g[0]) / 5.0, (h[1] - h[0]) / 5.0
    np.testing.assert_allclose([sv[0][1, 0], sv[0][1, 1], sv[1][1, 1]], [12.6, 10.0, -21.5], atol=1e-9)


def test_igrf14syn_geocentric_reference_values() -> None:
    d = _reference("igrf14_test_geocentric.txt")
    assert len(d) > 50
    b_r, b_t, b_p = igrf_field_geocentric_nT(d[:, 0], d[:, 1] * 1e3, d[:, 2] * DEG, d[:, 3] * DEG)
    xyz = np.column_stack([-b_t, b_p, -b_r])
    # igrf14syn prints 5 decimals but computes in single precision: agreement to 0.02 nT
    np.testing.assert_allclose(xyz, d[:, 4:7], rtol=0, atol=0.02)
    np.testing.assert_allclose(np.linalg.norm(xyz, axis=1), d[:, 7], rtol=0, atol=0.02)


def test_igrf14syn_geodetic_reference_values() -> None:
    d = _reference("igrf14_test_geodetic.txt")
    lat, lon = (90.0 - d[:, 2]) * DEG, d[:, 3] * DEG
    r_E = E_from_geodetic(lat, lon, d[:, 1] * 1e3)
    ned = np.einsum("kji,kj->ki", dcm_E_ned(lat, lon), igrf_field_E_nT_at(r_E, d[:, 0]))
    # igrf14syn's own geodetic conversion (b = 6356.752 km) differs from WGS 84 by 0.3 m: 0.1 nT
    np.testing.assert_allclose(ned, d[:, 4:7], rtol=0, atol=0.1)


@pytest.mark.parametrize(
    ("year", "colat_deg", "lon_deg", "r_km", "xyz"),
    [
        (1960, 95, -30, 6500, (23647.00, -9302.27, -3610.73)),
        (2005, 35, 60, 6650, (14718.37, 2842.99, 46050.88)),
        (2020, 15, 90, 6700, (3734.07, 1294.17, 50833.13)),
        (2025, 90, 45, 6900, (25587.26, -826.43, -7422.32)),
    ],
)
def test_bgs_pyigrf_reference_values(year: int, colat_deg: float, lon_deg: float, r_km: float, xyz: tuple) -> None:
    b_r, b_t, b_p = igrf_field_geocentric_nT(year, r_km * 1e3, colat_deg * DEG, lon_deg * DEG)
    np.testing.assert_allclose([-b_t, b_p, -b_r], xyz, rtol=0, atol=0.1)


def test_agrees_with_ppigrf_synthesis() -> None:
    """Independent synthesis code (ppigrf's) on the same coefficients, one date, many points."""
    rng = np.random.default_rng(4)
    r_km = rng.uniform(6400, 8000, 40)
    colat, lon = rng.uniform(1, 179, 40), rng.uniform(-180, 180, 40)
    br, bt, bp = ppigrf.igrf_gc(r_km, colat, lon, datetime.datetime(2025, 1, 1))
    ours = igrf_field_geocentric_nT(2025.0, r_km * 1e3, colat * DEG, lon * DEG)
    np.testing.assert_allclose(np.stack(ours), np.stack([br[0], bt[0], bp[0]]), rtol=0, atol=1e-6)


def test_field_E_matches_spherical_components_and_tai_path() -> None:
    t = iso_to_tai_ns(["2025-07-02T12:00:00"])[0]
    year = decimal_year_utc(t)
    assert year == pytest.approx(2025 + (31 + 28 + 31 + 30 + 31 + 30 + 1 + 0.5) / 365, abs=1e-12)
    r_E = np.array([[7.0e6, 0.0, 0.0], [0.0, 0.0, 6.9e6], [3e6, -4e6, 5e6]])
    b = igrf_field_E_nT(r_E, np.full(3, t))
    np.testing.assert_allclose(b, igrf_field_E_nT_at(r_E, year), rtol=0, atol=1e-9)
    # on the x axis: east = +y, south = -z, up = +x
    b_r, b_t, b_p = igrf_field_geocentric_nT(year, 7.0e6, np.pi / 2, 0.0)
    np.testing.assert_allclose(b[0], [b_r, b_p, -b_t], atol=1e-9)
    # a single position gives the same as the batch
    np.testing.assert_allclose(igrf_field_E_nT(r_E[2], t), b[2], atol=1e-9)
    # at the pole (guarded) the field is continuous
    near = igrf_field_E_nT_at(np.array([[1e-3, 0.0, 6.9e6], [0.0, 0.0, 6.9e6]]), year)
    np.testing.assert_allclose(near[0], near[1], atol=1e-3)


def test_ned_helpers_round_trip() -> None:
    lat, lon, h = np.array([0.3, -1.2]), np.array([2.0, -0.5]), np.array([650e3, 10.0])
    r_E = E_from_geodetic(lat, lon, h)
    lat2, lon2, h2 = geodetic_from_E(r_E)
    np.testing.assert_allclose([lat2, lon2, h2], [lat, lon, h], atol=1e-9)
    m = dcm_E_ned(lat, lon)
    np.testing.assert_allclose(np.einsum("kji,kjl->kil", m, m), np.broadcast_to(np.eye(3), (2, 3, 3)), atol=1e-15)
    t = iso_to_tai_ns(["2025-01-01T00:00:00", "2025-01-01T00:00:00"])
    ned = igrf_field_ned_nT(lat, lon, h, t)
    np.testing.assert_allclose(np.linalg.norm(ned, axis=1), np.linalg.norm(igrf_field_E_nT(r_E, t), axis=1))


def test_out_of_range_and_bad_shapes_raise() -> None:
    d = np.loadtxt(DATA / "igrf14_test_geocentric.txt")
    late = d[d[:, 0] > 2030.0]
    with pytest.raises(IGRFValueError, match="outside the model's validity 1900.0-2030.0"):
        igrf_field_geocentric_nT(late[:, 0], late[:, 1] * 1e3, late[:, 2] * DEG, late[:, 3] * DEG)
    with pytest.raises(IGRFValueError, match=r"must have shape \(\.\.\., 3\)"):
        igrf_field_E_nT_at(np.zeros((4, 2)), 2025.0)
    with pytest.raises(IGRFValueError, match="r_m must be > 0"):
        igrf_field_geocentric_nT(2025.0, 0.0, 1.0, 1.0)


# ---------------------------------------------------------------------------------------------- dipole


def test_dipole_eq2_is_the_axial_dipole_on_a_circular_orbit() -> None:
    """002 eq. (2) equals B = m/r^3 (3 (z.r) r - z)... of a south-pointing axial dipole, in the 002 frame."""
    a, inc = R_EARTH_M + 650e3, 98.0 * DEG
    t = np.linspace(0.0, 6000.0, 50)
    r_I, v_I = circular_orbit_state(t, a, inc, 0.7, 0.2)
    u = 0.2 + mean_motion_rad_s(a) * t
    rh = r_I / a
    m_hat = np.array([0.0, 0.0, -1.0])
    B_I = 1e9 * DIPOLE_MOMENT_002_T_M3 / a**3 * (3 * (rh @ m_hat)[:, None] * rh - m_hat)
    B_O002 = np.einsum("kji,kj->ki", dcm_IO_003(r_I, v_I), B_I)  # 002 frame = 003's axes (radial, normal)
    expected = np.column_stack([B_O002[:, 0], B_O002[:, 1], B_O002[:, 2]])
    np.testing.assert_allclose(dipole_field_O002_nT(a, inc, u), expected, atol=1e-6)
    B_O004 = np.einsum("kji,kj->ki", dcm_IO_lvlh_004(r_I, v_I), B_I)
    np.testing.assert_allclose(dipole_field_O004_nT(a, inc, u), B_O004, atol=1e-6)


def test_dipole_against_igrf_along_an_orbit() -> None:
    """The paper's dipole is a coarse model: same magnitude within ~30 %, directions within ~30 deg."""
    m = dipole_moment_igrf_T_m3(2025.0)
    assert 7.5e15 < m < 7.8e15 < DIPOLE_MOMENT_002_T_M3
    a, inc = R_EARTH_M + 650e3, 98.0 * DEG
    t_s = np.arange(0.0, 5863.0, 60.0)
    t_ns = iso_to_tai_ns(["2025-03-20T12:00:00"])[0] + (t_s * 1e9).astype(np.int64)
    r_I, v_I = circular_orbit_state(t_s, a, inc, 1.0, 0.0)
    dcm_EI = gcrs_to_itrs_mat(t_ns)
    B_I = np.einsum("kji,kj->ki", dcm_EI, igrf_field_E_nT(np.einsum("kij,kj->ki", dcm_EI, r_I), t_ns))
    B_igrf = np.einsum("kji,kj->ki", dcm_IO_lvlh_004(r_I, v_I), B_I)
    B_dip = dipole_field_O004_nT(a, inc, mean_motion_rad_s(a) * t_s)
    ratio = np.linalg.norm(B_dip, axis=1) / np.linalg.norm(B_igrf, axis=1)
    ang = np.degrees(np.arccos(np.sum(B_dip * B_igrf, axis=1) / np.linalg.norm(B_dip, axis=1)
                               / np.linalg.norm(B_igrf, axis=1)))
    assert 0.7 < ratio.min() and ratio.max() < 1.4
    assert np.median(ang) < 15.0 and ang.max() < 35.0


# ---------------------------------------------------------------------------------------------- Sun


def _tt_jd_to_tai(jd: float) -> np.int64:
    return np.int64(round((jd - 2440587.5) * 86400)) * 10**9 - TT_MINUS_TAI_NS


def test_sun_against_meeus_example_25b() -> None:
    tai = _tt_jd_to_tai(2448908.5)
    assert np.linalg.norm(sun_position_I_m(tai)) / AU_M == pytest.approx(0.99760853, abs=2e-8)
    v = erfa.pnm06a(2448908.5, 0.0) @ sun_direction_I(tai, apparent=True)  # true equator and equinox of date
    ra = np.arctan2(v[1], v[0]) % (2 * np.pi)
    dec = np.arcsin(v[2])
    ra_ref = (13 + 13 / 60 + 30.749 / 3600) * 15 * DEG
    dec_ref = -(7 + 47 / 60 + 1.74 / 3600) * DEG
    assert abs(ra - ra_ref) * np.cos(dec) < 0.1 * ARCSEC
    assert abs(dec - dec_ref) < 0.1 * ARCSEC
    # the geometric direction differs by the annual aberration, ~20.5 arcsec
    ab = np.arccos(sun_direction_I(tai) @ sun_direction_I(tai, apparent=True))
    assert 19 * ARCSEC < ab < 21.5 * ARCSEC


def test_sun_at_the_2024_march_equinox() -> None:
    tai = iso_to_tai_ns(["2024-03-20T03:06:00"])[0]
    tt = (tai + TT_MINUS_TAI_NS) / 86400e9 + 2440587.5
    v = erfa.pnm06a(tt, 0.0) @ sun_direction_I(tai, apparent=True)
    eps = erfa.obl06(tt, 0.0) + erfa.nut06a(tt, 0.0)[1]
    lon = np.arctan2(v[1] * np.cos(eps) + v[2] * np.sin(eps), v[0])  # ecliptic longitude of date
    assert abs(lon) < 3 * ARCSEC  # the instant is given to the minute (the Sun moves 2.5"/min)


def test_sun_interpolation_matches_epv00_and_shapes() -> None:
    t0 = iso_to_tai_ns(["2025-06-01T00:00:00"])[0]
    t = t0 + np.arange(0, 3 * 86400, 977, dtype=np.int64) * 10**9
    direct, _ = _sun_pv_direct(t + TT_MINUS_TAI_NS)
    np.testing.assert_allclose(sun_position_I_m(t), direct, rtol=0, atol=0.01)  # 1 cm
    assert sun_position_I_m(t.reshape(-1, 1)).shape == (t.size, 1, 3)
    np.testing.assert_allclose(np.linalg.norm(sun_direction_I(t), axis=-1), 1.0, atol=1e-15)
    with pytest.raises(ValueError, match="integer nanoseconds"):
        sun_position_I_m(np.array([1.5]))


def test_sun_direction_from_spacecraft_includes_parallax() -> None:
    t = iso_to_tai_ns(["2025-06-01T00:00:00"])[0]
    s = sun_direction_I(t)
    r = np.cross(s, [0.0, 0.0, 1.0])
    r *= 7e6 / np.linalg.norm(r)
    ang = np.arccos(np.clip(sun_direction_from_I(r, t) @ s, -1, 1))
    assert ang == pytest.approx(7e6 / np.linalg.norm(sun_position_I_m(t)), rel=1e-3)


# ---------------------------------------------------------------------------------------------- eclipse


def test_shadow_geometry_simple_points() -> None:
    sun = np.array([AU_M, 0.0, 0.0])
    r = np.array([[-7e6, 0, 0], [7e6, 0, 0], [0, 7e6, 0], [-7e6, 6.3e6, 0]])
    nu = sunlit_fraction(r, sun)
    np.testing.assert_array_equal(nu[:3], [0.0, 1.0, 1.0])
    np.testing.assert_array_equal(eclipse_state(r[:3], sun), [UMBRA, SUNLIT, SUNLIT])
    np.testing.assert_array_equal(in_shadow_cylindrical(r, sun), [True, False, False, True])
    # behind the Earth at 6.3e6 m from the axis (< R_E): in the cylinder; the umbra cone has narrowed by
    # ~7e6 * tan(0.267 deg) = 33 km there, so it is still umbra
    assert nu[3] == 0.0


def test_shadow_on_a_circular_orbit_with_beta_zero() -> None:
    """Durations against the cylindrical closed form 2 asin(R/r)/n; the conical umbra is shorter and the
    penumbra (partial sunlight) adds ~8-10 s at each crossing at 650 km."""
    a = R_EARTH_M + 650e3
    n = float(mean_motion_rad_s(a))
    t = np.arange(0.0, 2 * np.pi / n, 0.25)
    r_I, _ = circular_orbit_state(t, a, 0.0, 0.0, 0.0)
    sun = np.array([AU_M, 0.0, 0.0])
    cyl = in_shadow_cylindrical(r_I, sun)
    state = eclipse_state(r_I, sun)
    expected = 2 * np.arcsin(R_EARTH_M / a) / n
    assert cyl.sum() * 0.25 == pytest.approx(expected, abs=0.5)
    umbra, pen = (state == UMBRA).sum() * 0.25, (state == PENUMBRA).sum() * 0.25
    assert umbra < expected < umbra + pen
    assert 2 * 6.0 < pen < 2 * 12.0
    nu = sunlit_fraction(r_I, sun)
    assert np.all(np.diff(nu[state == PENUMBRA]) != 0)  # partial, varying
    assert np.all((nu > 0) & (nu < 1) == (state == PENUMBRA))


# ---------------------------------------------------------------------------------------------- Earth rotation


def test_interpolated_earth_rotation_matches_frames() -> None:
    t0 = iso_to_tai_ns(["2025-03-20T12:00:00"])[0]
    t = t0 + np.arange(0, 7300, 7, dtype=np.int64) * 10**9
    eop = EarthOrientation(dut1_s=-0.1, xp_rad=0.2 * ARCSEC, yp_rad=0.3 * ARCSEC)
    d = np.einsum("kij,kil->kjl", gcrs_to_itrs_mat_interp(t, eop), gcrs_to_itrs_mat(t, eop))
    assert np.abs(d - np.eye(3)).max() < 1e-10
    rng = np.random.default_rng(0)
    r, v = rng.normal(size=(t.size, 3)) * 7e6, rng.normal(size=(t.size, 3)) * 7e3
    r_I, v_I, _ = itrs_to_gcrs_state_interp(r, v, t, eop)
    r_ref, v_ref = itrs_to_gcrs_state(r, v, t, eop)
    assert np.abs(r_I - r_ref).max() < 2e-3 and np.abs(v_I - v_ref).max() < 1e-6
