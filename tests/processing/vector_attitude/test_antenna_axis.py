"""Antenna axis from visibility (002 eqs. 5-7) and the cone refinement."""

from __future__ import annotations

import numpy as np
import pytest

from processing.frames.orbital import dcm_IO_003
from processing.units import R_EARTH_M
from processing.vector_attitude import antenna_axis as aa


def _sky(n_epochs: int, n_sats: int, seed: int) -> np.ndarray:
    g = np.random.default_rng(seed).normal(size=(n_epochs, n_sats, 3))
    return g / np.linalg.norm(g, axis=-1, keepdims=True)


def test_normal_equations_are_the_papers_system() -> None:
    """The solution solves the 3x3 system printed below eq. 7 with the paper's sums."""
    g = _sky(1, 20, 1)
    vis = g[..., 2] > 0.2
    radius = np.array([R_EARTH_M + 600e3])
    res = aa.antenna_axis_O(g, vis, np.ones_like(vis), radius, grazing_altitude_m=0.0)
    occ = aa.earth_occulted(g, radius, 0.0)[0]
    use = vis[0] | ~occ
    x, y, z = g[0, use].T
    sign = np.where(vis[0, use], 1.0, -1.0)
    m = np.array([[x @ x, x @ y, x @ z], [x @ y, y @ y, y @ z], [x @ z, y @ z, z @ z]])
    rhs = np.array([sign @ x, sign @ y, sign @ z])
    sol = np.linalg.solve(m, rhs)
    np.testing.assert_allclose(res.a_O[0], sol / np.linalg.norm(sol), atol=1e-12)
    assert res.n_visible[0] == vis.sum() and res.n_invisible[0] + res.n_visible[0] == use.sum()
    assert res.n_occulted[0] == (~vis[0] & occ).sum()


def test_earth_occultation_eq6() -> None:
    """Hidden when z < 0 and |z| > cos(asin(R / r)): at r = R + 500 km the limb is 22 deg below the horizontal."""
    radius = np.array([R_EARTH_M + 500e3])
    limb = np.cos(np.arcsin(R_EARTH_M / radius[0]))
    z = np.array([-0.99, -limb - 1e-6, -limb + 1e-6, -0.1, 0.5])
    g = np.stack([np.sqrt(1 - z**2), np.zeros_like(z), z], axis=-1)[None]
    assert aa.earth_occulted(g, radius, 0.0)[0].tolist() == [True, True, False, False, False]
    # 50 km of atmosphere raises the blocked disc
    assert aa.earth_occulted(g, radius, 50e3)[0, 2]


def test_axis_recovered_from_a_full_sky() -> None:
    """Many satellites all round: eq. 7 points close to the true axis, the cone fit closer."""
    rng = np.random.default_rng(4)
    a_true = rng.normal(size=(200, 3))
    a_true /= np.linalg.norm(a_true, axis=1, keepdims=True)
    g = _sky(200, 40, 2)
    vis = np.einsum("tsi,ti->ts", g, a_true) >= np.cos(np.deg2rad(80))
    radius = np.full(200, 5 * R_EARTH_M)  # far away: no satellite hidden
    res = aa.antenna_axis_O(g, vis, np.ones_like(vis), radius)
    err7 = np.degrees(np.arccos(np.clip(np.sum(res.a_O * a_true, axis=1), -1, 1)))
    refined = aa.refine_antenna_axis_O(g, vis, np.ones_like(vis), res.a_O, np.deg2rad(80))
    err_ml = np.degrees(np.arccos(np.clip(np.sum(refined * a_true, axis=1), -1, 1)))
    assert np.median(err7) < 12.0
    assert np.median(err_ml) < 0.6 * np.median(err7)
    # the refined axis satisfies eq. 5 for (almost) every satellite
    dots = np.einsum("tsi,ti->ts", g, refined)
    wrong = (vis & (dots < np.cos(np.deg2rad(80)))) | (~vis & (dots >= np.cos(np.deg2rad(80))))
    assert wrong.mean() < 0.01


def test_not_determined_with_few_satellites() -> None:
    g = _sky(2, 3, 3)
    res = aa.antenna_axis_O(g, np.ones((2, 3), bool), np.ones((2, 3), bool), np.full(2, 7e6))
    assert not res.ok.any() and np.isnan(res.a_O).all()
    with pytest.raises(aa.AntennaAxisError, match=r"g_O \(T, S, 3\)"):
        aa.antenna_axis_O(g[0], np.ones(3, bool), np.ones(3, bool), [7e6])


def test_orbital_frame_from_an_earth_fixed_state() -> None:
    """dcm_EO_002 is the inertial 003/002 orbital frame expressed in ITRF axes (inertial velocity used)."""
    r_E = np.array([[7.0e6, 1.0e5, 2.0e5]])
    v_E = np.array([[10.0, 6.5e3, 3.0e3]])
    m = aa.dcm_EO_002(r_E, v_E)
    v_in = v_E + np.cross([0, 0, 7.292115e-5], r_E)
    np.testing.assert_allclose(m, dcm_IO_003(r_E, v_in), atol=1e-15)
    np.testing.assert_allclose(m[0, :, 2], r_E[0] / np.linalg.norm(r_E[0]))  # Z2 radial
    g = aa.line_of_sight_O(np.array([[[2.0e7, 0.0, 0.0]]]), r_E, m)
    assert np.linalg.norm(g) == pytest.approx(1.0)
