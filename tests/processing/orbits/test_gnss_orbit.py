"""GNSS state smoothing, coverage and ascending nodes (processing/orbits/gnss_orbit.py) on seed-003 truth."""

import numpy as np
import pytest

from processing.frames.earth_orientation import gcrs_to_itrs_state
from processing.orbits.gnss_orbit import (
    GnssFitError,
    ascending_nodes,
    fit_gnss,
    gnss_to_gcrs,
    split_arcs,
    time_since_ascending_node_s,
    time_since_node_kepler_s,
)
from processing.simulate.seed003 import simulate_seed003
from processing.time.timescales import iso_to_tai_ns

START = int(iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])
NS = 1_000_000_000


def _gnss(scenario):
    g = scenario.streams["gnss"]
    r = np.stack([g[c] for c in ("x", "y", "z")], axis=-1)
    v = np.stack([g[c] for c in ("vx", "vy", "vz")], axis=-1)
    return g["time_tai_ns"], r, v


def _truth_itrs(scenario, t_ns):
    r_I, v_I = scenario.truth.model.orbit((t_ns - START) / 1e9)
    return gcrs_to_itrs_state(r_I, v_I, t_ns)


@pytest.fixture(scope="module")
def scenario():
    return simulate_seed003(start_tai_ns=START, seed=1, duration_s=1200.0, gyro_period_s=10.0,
                            u0_rad=np.radians(-10.0))


def test_chebyshev_fit_beats_the_noise_and_keeps_r_v_consistent(scenario):
    t, r, v = _gnss(scenario)
    fit = fit_gnss(t, r, v)
    assert fit.method == "chebyshev" and len(fit.arcs) == 1 and 6 <= fit.arcs[0].degree <= 14
    # Residual rms = the simulated noise (1 m, 1 mm/s per axis): 003 §1.6's "< 1 m, < 1 mm/s" figures.
    np.testing.assert_allclose(fit.position_rms_m, 1.0, rtol=0.1)
    np.testing.assert_allclose(fit.velocity_rms_m_s, 1e-3, rtol=0.1)
    tq = t[:-1] + NS // 2  # between the samples, where the star tracker needs it
    r_fit, v_fit, ok = fit.evaluate(tq)
    r_true, v_true = _truth_itrs(scenario, tq)
    assert ok.all()
    assert np.sqrt(np.mean((r_fit - r_true) ** 2)) < 0.1  # m (measured ~0.03)
    assert np.sqrt(np.mean((v_fit - v_true) ** 2)) < 3e-4  # m/s (measured ~1e-4)
    assert np.max(np.abs(r_fit - r_true)) < 0.5


def test_sine_series_option_follows_003(scenario):
    t, r, v = _gnss(scenario)
    fit = fit_gnss(t, r, v, method="sine")
    assert fit.arcs[0].harmonics[0] > 50  # an orbit arc needs many harmonics (module docstring)
    tq = t[:-1] + NS // 2
    r_fit, v_fit, _ = fit.evaluate(tq)
    r_true, v_true = _truth_itrs(scenario, tq)
    assert np.sqrt(np.mean((r_fit - r_true) ** 2)) < 1.0  # 003: < 1 m
    assert np.sqrt(np.mean((v_fit - v_true) ** 2)) < 1e-3  # 003: < 1 mm/s
    assert np.all(fit.consistency_rms_m_s > 1e-3)  # its position derivative is not the velocity


def test_arcs_gaps_and_coverage(scenario):
    t, r, v = _gnss(scenario)
    keep = (t < START + 400 * NS) | (t > START + 700 * NS)
    fit = fit_gnss(t[keep], r[keep], v[keep], arc_max_s=300.0)
    spans = [((a.first_tai_ns - START) / NS, (a.last_tai_ns - START) / NS) for a in fit.arcs]
    assert spans[0][0] == 0.0 and spans[-1][1] == 1200.0
    assert all(b - a <= 300.0 for a, b in spans)
    assert not any(a < 550.0 < b for a, b in spans)
    _, _, ok = fit.evaluate(np.array([START + 1 * NS, START + 550 * NS, START + 1201 * NS, START + 1300 * NS]))
    assert ok.tolist() == [True, False, True, False]  # 1.5 steps of margin beyond the last sample
    sizes = [s.stop - s.start for s in split_arcs(np.arange(100) * NS, 30.0, 100.0)]
    assert sum(sizes) == 100 and len(sizes) == 4 and max(sizes) <= 31
    assert [s.stop - s.start for s in split_arcs(np.arange(10) * NS, 3.0, 100.0)] == [10]  # >= 6 samples each


def test_bad_inputs():
    t = START + np.arange(10) * NS
    with pytest.raises(GnssFitError, match=r"positions \(N, 3\)"):
        fit_gnss(t, np.zeros((10, 2)), np.zeros((10, 3)))
    with pytest.raises(GnssFitError, match="strictly increasing"):
        fit_gnss(t[::-1], np.ones((10, 3)), np.ones((10, 3)))
    with pytest.raises(GnssFitError, match="finite"):
        fit_gnss(t, np.full((10, 3), np.nan), np.ones((10, 3)))
    with pytest.raises(GnssFitError, match="at least 6"):
        fit_gnss(t[:3], np.ones((3, 3)), np.ones((3, 3)))
    with pytest.raises(GnssFitError, match="method"):
        fit_gnss(t, np.ones((10, 3)), np.ones((10, 3)), method="spline")


def test_ascending_node_and_time_since_node_match_the_truth(scenario):
    """u0 = -10 deg: the node is crossed 10/360 of a period after the start (two-body truth)."""
    t, r, v = _gnss(scenario)
    fit = fit_gnss(t, r, v)
    nodes = ascending_nodes(fit)
    n = scenario.truth.mean_motion_rad_s
    t_node_true = np.radians(10.0) / n
    assert nodes.size == 1
    assert abs((nodes[0] - START) / NS - t_node_true) < 0.01  # s (fit ~3 cm / 7.4 km/s)
    r_I, v_I, ok = gnss_to_gcrs(fit, t)
    since = time_since_ascending_node_s(t, r_I, v_I, nodes)
    t_s = (t - START) / NS
    expected = np.where(t_s >= t_node_true, t_s - t_node_true, t_s + 2 * np.pi / n - t_node_true)
    np.testing.assert_allclose(since, expected, atol=0.05)


def test_kepler_time_since_node_on_an_exact_circular_orbit(scenario):
    t_s = np.array([0.0, 100.0, 1000.0])
    r_I, v_I = scenario.truth.model.orbit(t_s)
    n = scenario.truth.mean_motion_rad_s
    np.testing.assert_allclose(time_since_node_kepler_s(r_I, v_I), (t_s + np.radians(-10.0) / n) % (2 * np.pi / n),
                               atol=1e-6)
