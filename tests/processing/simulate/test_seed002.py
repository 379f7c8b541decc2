"""Seed-002 truth simulator: structure, determinism, and consistency of the telemetry with the truth."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from processing.attitude import rotations
from processing.environment import igrf_field_E_nT
from processing.formats.rinex_nav import parse_rinex_nav
from processing.orbits.gnss_ephemeris import satellite_positions_E
from processing.screening.criteria import energy_h
from processing.simulate.seed002 import Seed002ParameterError, simulate_seed002
from processing.streams import STREAMS
from processing.vector_attitude.antenna_axis import dcm_EO_002, earth_occulted, line_of_sight_O
from tests.real_data import GNSS_NAV

NAV = GNSS_NAV / "brdc2800.15n"


@cache
def nav():
    return parse_rinex_nav(NAV.read_bytes()).columns


@cache
def scenario(seed: int = 0, duration_s: float = 2400.0):
    return simulate_seed002(nav=nav(), seed=seed, duration_s=duration_s)


def test_streams_follow_the_canonical_schemas() -> None:
    sc = scenario()
    assert set(sc.streams) == {"gnss", "magnetometer", "panel_currents", "gnss_visibility"}
    for name, cols in sc.streams.items():
        assert set(cols) == {"time_tai_ns", "sensor", *STREAMS[name].column_names}, name
        n = len(cols["time_tai_ns"])
        assert all(len(v) == n for v in cols.values())
        assert cols["time_tai_ns"].dtype == np.int64
    assert len(sc.streams["panel_currents"]["time_tai_ns"]) == 6 * len(sc.streams["gnss"]["time_tai_ns"])
    assert sc.config["gnss_antenna_axis_B"] == [1.0, 0.0, 0.0] and len(sc.config["solar_panels"]) == 6
    assert sc.parameters["seed"] == 0


def test_deterministic_by_seed() -> None:
    a = simulate_seed002(nav=nav(), seed=3, duration_s=300.0)
    b = simulate_seed002(nav=nav(), seed=3, duration_s=300.0)
    c = simulate_seed002(nav=nav(), seed=4, duration_s=300.0)
    for s in a.streams:
        for k in a.streams[s]:
            np.testing.assert_array_equal(a.streams[s][k], b.streams[s][k])
    assert not np.array_equal(a.streams["magnetometer"]["bx"], c.streams["magnetometer"]["bx"])


def test_telemetry_consistent_with_truth() -> None:
    sc = scenario()
    tr = sc.truth
    clean = ~tr.faults["magnetometer"]
    # magnetometer = dcm_MB dcm_BO B_O + noise of 100 nT
    dcm_BO = rotations.quat_to_dcm(rotations.quat_conjugate(tr.q_OB))
    dcm_MB = rotations.quat_to_dcm(np.asarray(sc.config["magnetometer"]["q_BM"])).T
    b_M = np.einsum("ij,njk,nk->ni", dcm_MB, dcm_BO, tr.field_O_nT)
    m = sc.streams["magnetometer"]
    resid = np.stack([m["bx"], m["by"], m["bz"]], axis=1)[clean] - b_M[clean]
    assert np.std(resid) == pytest.approx(100.0, rel=0.05)
    np.testing.assert_allclose(tr.field_E_nT, igrf_field_E_nT(tr.r_E, tr.time_tai_ns))
    # 002 angles of the truth rebuild q_OB (matrix (3) = dcm_BO)
    np.testing.assert_allclose(rotations.dcm_from_angles_002(tr.pitch_rad, tr.yaw_rad, tr.roll_rad), dcm_BO,
                               atol=1e-12)
    # panel currents: I_max nu max(0, n . s_B) + 0.01 A
    s_B = np.einsum("nij,nj->ni", dcm_BO, tr.sun_O)
    normals = np.array([p["normal_B"] for p in sc.config["solar_panels"]])
    model = 1.2 * tr.sunlit_fraction[:, None] * np.maximum(0.0, s_B @ normals.T)
    cur = sc.streams["panel_currents"]["current_a"].reshape(-1, 6)
    ok = ~tr.faults["panel_currents"].reshape(-1, 6)
    assert np.std((cur - model)[ok]) == pytest.approx(0.01, rel=0.05)
    shadow = tr.sunlit_fraction == 0.0
    assert 0.2 < shadow.mean() < 0.6 and np.all(np.abs(cur[shadow & ok.all(axis=1)]) < 0.06)
    # GNSS noise 5 m, 0.05 m/s
    g = sc.streams["gnss"]
    ok_g = ~tr.faults["gnss"]
    dr = np.stack([g["x"], g["y"], g["z"]], axis=1)[ok_g] - tr.r_E[ok_g]
    dv = np.stack([g["vx"], g["vy"], g["vz"]], axis=1)[ok_g] - tr.v_E[ok_g]
    assert np.std(dr) == pytest.approx(5.0, rel=0.05) and np.std(dv) == pytest.approx(0.05, rel=0.05)


def test_orbit_has_j2_energy_oscillation() -> None:
    """The truth orbit is integrated with J2: the two-body h of eq. 15 oscillates by ~1e5 m^2/s^2 while
    the J2-aware h stays constant to well below the GNSS noise."""
    tr = scenario().truth
    h2 = energy_h(tr.r_E, tr.v_E, "two_body")
    hj = energy_h(tr.r_E, tr.v_E, "j2")
    assert np.ptp(h2) > 5e4
    assert np.ptp(hj) < 50.0


def test_visibility_geometry() -> None:
    """Reported satellites are within the antenna cone and above the Earth's limb (+50 km)."""
    sc = scenario()
    tr = sc.truth
    vis = sc.streams["gnss_visibility"]
    t = vis["time_tai_ns"]
    k = np.searchsorted(tr.time_tai_ns, t)
    sats = [f"G{p:02d}" for p in vis["prn"]]
    names = sorted(set(sats))
    pos = satellite_positions_E(nav(), tr.time_tai_ns, names)
    j = np.searchsorted(names, sats)
    los = line_of_sight_O(pos.r_E, tr.r_E, dcm_EO_002(tr.r_E, tr.v_E))
    g = los[k, j]
    assert np.all(np.einsum("ni,ni->n", g, tr.antenna_O[k]) >= np.cos(np.deg2rad(80.0)) - 1e-12)
    occ = earth_occulted(los, np.linalg.norm(tr.r_E, axis=1), 50e3)
    assert not np.any(occ[k, j])
    per_epoch = np.bincount(k, minlength=tr.time_tai_ns.size)
    assert 6 < per_epoch.mean() < 14


def test_fault_labels() -> None:
    sc = scenario()
    tr = sc.truth
    n = tr.time_tai_ns.size
    assert 0.003 < tr.faults["gnss"].mean() < 0.012
    assert tr.faults["magnetometer"].sum() == pytest.approx(0.005 * n, abs=3)
    assert tr.faults["panel_currents"].sum() == pytest.approx(0.003 * 6 * n, abs=4)
    assert set(tr.fault_kind["gnss"][tr.faults["gnss"]]) <= {"position", "velocity", "position+velocity"}
    assert np.all((tr.fault_kind["magnetometer"] == "spike") == tr.faults["magnetometer"])
    cur = sc.streams["panel_currents"]["current_a"]
    clean = tr.clean["panel_currents"]["current_a"]
    f = tr.faults["panel_currents"]
    assert np.all(np.abs(cur[f] - clean[f]) >= 0.3 * 1.2) and np.array_equal(cur[~f], clean[~f])
    spikes = np.stack([sc.streams["magnetometer"][c] for c in ("bx", "by", "bz")], axis=1) - tr.clean["magnetometer"][
        "b_M"]
    mags = np.linalg.norm(spikes[tr.faults["magnetometer"]], axis=1)
    assert np.all((mags >= 1500) & (mags <= 10000))


def test_parameter_errors() -> None:
    with pytest.raises(Seed002ParameterError, match="duration_s"):
        simulate_seed002(nav=nav(), duration_s=5.0)
    with pytest.raises(Seed002ParameterError, match="gnss_fault_fraction"):
        simulate_seed002(nav=nav(), duration_s=100.0, gnss_fault_fraction=0.5)
