"""Broadcast ephemerides: IS-GPS-200 Keplerian orbits and GLONASS ICD integration on the shared files."""

from __future__ import annotations

import numpy as np
import pytest

from processing.formats.rinex_nav import parse_rinex_nav
from processing.orbits import gnss_ephemeris as ge
from processing.units import OMEGA_EARTH_RAD_S
from tests.real_data import GNSS_NAV

NAV_DIR = GNSS_NAV


@pytest.fixture(scope="module")
def gps():
    return parse_rinex_nav((NAV_DIR / "brdc2800.15n").read_bytes()).columns


@pytest.fixture(scope="module")
def mixed():
    return parse_rinex_nav((NAV_DIR / "BRDM00DLR_R_20130010000_01D_MN.rnx").read_bytes()).columns


def test_consecutive_gps_records_agree_at_the_later_epoch(gps) -> None:
    """Two consecutive records of one satellite, both evaluated at the later toe, agree to metres
    (the broadcast orbit error); the one corrupt record of the file (G10, 09:59:27, e = 0.00036 instead
    of 0.0101, the satellite otherwise unhealthy) is the only exception and is detected."""
    prev, nxt = ge.record_jumps_m(gps)
    bad = ge.inconsistent_records(gps)
    assert gps["sat"][bad].tolist() == ["G10"] and gps["e"][bad][0] == pytest.approx(0.000359439523891)
    pairs = np.isfinite(nxt)
    clean = pairs & ~bad & ~np.isin(np.arange(nxt.size), np.flatnonzero(bad) - 1)  # pair into the bad one
    d = nxt[clean]
    assert d.size > 350
    assert np.median(d) < 1.0 and np.max(d) < 6.0
    # direct evaluation of one pair, G05 at 02:00 GPST
    rows = np.flatnonzero(gps["sat"] == "G05")[:2]
    t = gps["ref_tai_ns"][rows[1]]
    r = ge.kepler_positions_E(gps, rows, [t, t])
    assert np.linalg.norm(r[0] - r[1]) < 3.0
    assert 26.4e6 < np.linalg.norm(r[0]) < 26.7e6  # GPS orbit radius (a = 26 560 km, e < 0.02)


def test_gps_orbit_period_is_half_a_sidereal_day(gps) -> None:
    """Positions a sidereal half day apart from one record coincide in inertial space to within the
    orbit's drift; in Earth-fixed coordinates the track repeats after one sidereal day."""
    i = np.flatnonzero(gps["sat"] == "G12")[0]
    t0 = gps["ref_tai_ns"][i]
    dt = np.arange(-1800, 1801, 60) * 10**9
    r = ge.kepler_positions_E(gps, np.full(dt.size, i), t0 + dt)
    speed_E = np.linalg.norm(np.diff(r, axis=0), axis=1) / 60.0
    assert np.all((speed_E > 2.5e3) & (speed_E < 3.9e3))  # ~3.9 km/s inertial, less in the rotating frame
    a = gps["sqrt_a_sqrt_m"][i] ** 2
    period = 2 * np.pi * np.sqrt(a**3 / ge.GM_GPS_M3_S2)
    assert period == pytest.approx(86164.0905 / 2, rel=2e-3)


def test_glonass_integration(mixed) -> None:
    """R01/R02: integrating the 00:15 record over 30 min reproduces the 00:45 record to metres; radius
    and period (from the inertial state) are those of GLONASS (25 510 km, 11 h 15 min 44 s)."""
    for sat in ("R01", "R02"):
        a, b = np.flatnonzero(mixed["sat"] == sat)
        s0 = np.array([[mixed[c][a] for c in ("x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s")]])
        acc = np.array([[mixed[c][a] for c in ("ax_m_s2", "ay_m_s2", "az_m_s2")]])
        dt = (mixed["ref_tai_ns"][b] - mixed["ref_tai_ns"][a]) / 1e9
        out = ge.glonass_integrate(s0, acc, [[dt, -dt, 0.0]])
        rb = np.array([mixed[c][b] for c in ("x_m", "y_m", "z_m")])
        vb = np.array([mixed[c][b] for c in ("vx_m_s", "vy_m_s", "vz_m_s")])
        assert np.linalg.norm(out[0, 0, :3] - rb) < 5.0
        assert np.linalg.norm(out[0, 0, 3:] - vb) < 0.01
        np.testing.assert_allclose(out[0, 2], s0[0], atol=1e-9)
        r = s0[0, :3]
        v_i = s0[0, 3:] + np.cross([0, 0, OMEGA_EARTH_RAD_S], r)
        sma = 1.0 / (2.0 / np.linalg.norm(r) - v_i @ v_i / ge.GM_GLO_M3_S2)
        assert np.linalg.norm(r) == pytest.approx(25.51e6, rel=2e-3)
        assert 2 * np.pi * np.sqrt(sma**3 / ge.GM_GLO_M3_S2) == pytest.approx(40544.0, rel=3e-3)
    # a finer step changes the result by well under a metre (RK4 + Hermite converged)
    a = np.flatnonzero(mixed["sat"] == "R01")[0]
    s0 = np.array([[mixed[c][a] for c in ("x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s")]])
    acc = np.zeros((1, 3))
    coarse = ge.glonass_integrate(s0, acc, [[1234.5]], step_s=60.0)
    fine = ge.glonass_integrate(s0, acc, [[1234.5]], step_s=5.0)
    assert np.linalg.norm(coarse[0, 0, :3] - fine[0, 0, :3]) < 0.05


def test_satellite_positions_grid(gps, mixed) -> None:
    t0 = int(gps["ref_tai_ns"].min())
    t = t0 + np.arange(0, 4 * 3600, 600) * 10**9
    pos = ge.satellite_positions_E(gps, t)
    assert pos.r_E.shape == (t.size, 32, 3) and pos.sats[0] == "G01"
    radius = np.linalg.norm(pos.r_E[pos.valid], axis=-1)
    assert np.all((radius > 25.9e6) & (radius < 27.3e6))
    assert np.all(np.abs(pos.age_s[pos.valid]) <= 7200)
    assert not pos.valid[:, list(pos.sats).index("G10")].any()  # unhealthy, and its healthy record is corrupt
    # scalar-per-record agreement with kepler_positions_E
    j = list(pos.sats).index("G07")
    idx, _ = ge.select_records(gps, ["G07"], t)
    np.testing.assert_allclose(pos.r_E[:, j], ge.kepler_positions_E(gps, idx[:, 0], t), atol=1e-6)
    mt = int(mixed["ref_tai_ns"][mixed["sat"] == "R01"][0]) + np.arange(-900, 2700, 300) * 10**9
    mp = ge.satellite_positions_E(mixed, mt)
    assert mp.sats.tolist() == ["G01", "G02", "J01", "R01", "R02"]
    assert mp.valid[:, 3].all() and not mp.valid[:, 2].any()  # J01 unhealthy
    qz = ge.satellite_positions_E(mixed, mt[:2], ["J01"], healthy_only=False)
    j01 = np.flatnonzero(mixed["sat"] == "J01")[0]
    a, e = mixed["sqrt_a_sqrt_m"][j01] ** 2, mixed["e"][j01]
    assert a == pytest.approx(42.16e6, rel=1e-3)  # QZSS: geosynchronous, e = 0.075
    assert a * (1 - e) < np.linalg.norm(qz.r_E[0, 0]) < a * (1 + e)


def test_missing_columns_error() -> None:
    with pytest.raises(ge.EphemerisError, match="lack the column 'sqrt_a_sqrt_m'"):
        ge.kepler_positions_E({"system": np.array(["G"])}, [0], [0])
    with pytest.raises(ge.EphemerisError, match=r"state0 \(R, 6\)"):
        ge.glonass_integrate(np.zeros((2, 5)), np.zeros((2, 3)), np.zeros((2, 1)))
