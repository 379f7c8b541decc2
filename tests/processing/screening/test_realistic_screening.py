"""Screening on realistic telemetry (processing.simulate.realistic): quantised, jittered, gappy data raise
(almost) no false alarms; late GNSS tags are found as such with their offset; a rate transient that the star
tracker sees too is not a fault, one that it does not see is."""

import numpy as np
import pytest

from processing.attitude import rotations
from processing.orbits.gnss_checks import divided_difference_noise, time_tag_check
from processing.screening.criteria import ScreeningParams, screen
from processing.screening.tools import quantisation_step, time_grid_irregular
from processing.simulate.realistic import simulate_realistic
from processing.spacecraft import Spacecraft
from processing.time.timescales import iso_to_tai_ns
from processing.units import NS_PER_S

T0 = int(iso_to_tai_ns("2023-06-01T00:00:00"))
PARAMS = ScreeningParams(energy_model="two_body")  # the simulator's orbit is two-body


def _screen(sc, params=PARAMS):
    return screen(sc.streams, Spacecraft.from_json(sc.config), params)


def test_false_alarm_rate_below_0p1_percent_per_criterion_on_clean_realistic_data():
    counts: dict[tuple[str, str], list[int]] = {}
    for seed in range(3):
        sc = simulate_realistic(start_tai_ns=T0, duration_s=2400.0, seed=seed, manoeuvre_start_s=800.0,
                                n_late_blocks=0)
        res = _screen(sc)
        for stream, per in res.summary().items():
            for crit, d in per.items():
                c = counts.setdefault((stream, crit), [0, 0])
                c[0] += d["n_rejected"]
                c[1] += d["n_total"]
    rates = {k: r / n for k, (r, n) in counts.items()}
    assert all(rate < 1e-3 for rate in rates.values()), {k: r for k, r in rates.items() if r >= 1e-3}
    assert counts[("gyro", "any")][1] > 6000


def test_naive_tolerances_would_raise_false_alarms():
    """The same data with the nominal grid tolerance: jittered tags fail the time grid (the test can fail)."""
    sc = simulate_realistic(start_tai_ns=T0, duration_s=1200.0, seed=1, n_late_blocks=0)
    t = sc.streams["gyro"]["time_tai_ns"]
    f, _, _, tol = time_grid_irregular(t, 0.25, k=0.0)
    assert tol == 0.25 and f.mean() > 0.01
    f, _, _, tol = time_grid_irregular(t, 0.25)
    assert tol == 0.5 and not f.any()


def test_lsb_and_noise_estimated_from_the_data():
    sc = simulate_realistic(start_tai_ns=T0, duration_s=1200.0, seed=2)
    g = sc.streams["gyro"]
    lsb = quantisation_step(np.stack([g[c] for c in ("wx", "wy", "wz")], axis=1))
    np.testing.assert_allclose(lsb, sc.truth.lsb["gyro_rad_s"], rtol=1e-9)
    assert quantisation_step(np.random.default_rng(0).standard_normal(500))[0] == 0.0
    n = sc.streams["gnss"]
    t_s = n["time_tai_ns"] / NS_PER_S
    sigma = divided_difference_noise(t_s - t_s[0], np.stack([n[c] for c in ("x", "y", "z")], axis=1))
    np.testing.assert_allclose(sigma, np.sqrt(1.0 + 1.0 / 12.0), rtol=0.1)  # 1 m noise + 1 m LSB


@pytest.mark.parametrize("late_tag_s", [3.4, 0.5])
def test_late_gnss_tags_found_with_their_offset_and_no_neighbour_rejected(late_tag_s):
    sc = simulate_realistic(start_tai_ns=T0, duration_s=2400.0, seed=4, late_tag_s=late_tag_s, n_late_blocks=3,
                            late_block_s=40.0)
    res = _screen(sc)
    late = sc.truth.gnss_late
    crit = {c.name: c for c in res.criteria if c.stream == "gnss"}
    np.testing.assert_array_equal(crit["time_tag"].flagged, late)
    rejected = res.rejected("gnss")
    np.testing.assert_array_equal(rejected, late)  # no kinematic or velocity rejection of good neighbours
    found = res.findings["gnss_time_tags"][0]
    assert found["n_states"] == late.sum()
    assert abs(found["offset_s_median"] - late_tag_s) < 0.01


def test_time_tag_check_tells_a_position_fault_from_a_time_shift():
    sc = simulate_realistic(start_tai_ns=T0, duration_s=1200.0, seed=5, n_late_blocks=0)
    n = sc.streams["gnss"]
    t = n["time_tai_ns"]
    r = np.stack([n[c] for c in ("x", "y", "z")], axis=1)
    v = np.stack([n[c] for c in ("vx", "vy", "vz")], axis=1)
    r[600:620] += 5000.0 * v[600:620] / np.linalg.norm(v[600:620], axis=1, keepdims=True)  # along-track only
    chk = time_tag_check(t, r, v, position_sigma_m=1.0, velocity_sigma_m_s=1e-3)
    assert np.all(np.abs(chk.offset_s[600:620]) > 0.5)
    assert not chk.shift_consistent[600:620].any()  # the velocities do not move with the positions
    assert chk.shift_consistent[100:500].all()


def _with_rate_pulse(sc, k, amplitude_rad_s, star_tracker_sees_it):
    """Add a one-sample rate pulse about gyro x at gyro row k; optionally turn the star tracker by the same
    (trapezoid-integrated) angle, as a real transient would."""
    streams = {s: dict(c) for s, c in sc.streams.items()}
    g = streams["gyro"]
    g["wx"] = g["wx"].copy()
    g["wx"][k] += amplitude_rad_s
    if star_tracker_sees_it:
        tg = g["time_tai_ns"]
        pulse = np.zeros(tg.size)
        pulse[k] = amplitude_rad_s
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (pulse[1:] + pulse[:-1]) * np.diff(tg) / NS_PER_S)])
        st = streams["star_tracker"]
        ang = np.interp(st["time_tai_ns"], tg, cum)
        q_SB = rotations.quat_conjugate(sc.truth.q_BS)
        axis_S = rotations.quat_rotate(q_SB, np.array([1.0, 0.0, 0.0]))  # gyro x = body x (q_BG = 1)
        q = np.stack([st[f"q{i}"] for i in range(4)], axis=1)
        q = rotations.quat_canonical(rotations.quat_multiply(q, rotations.rotvec_to_quat(ang[:, None] * axis_S)))
        for i in range(4):
            st[f"q{i}"] = q[:, i]
    return type(sc)(streams=streams, config=sc.config, truth=sc.truth, parameters=sc.parameters)


def test_a_transient_seen_by_gyro_and_star_tracker_is_not_a_fault():
    sc = simulate_realistic(start_tai_ns=T0, duration_s=1200.0, seed=6, n_late_blocks=0, dropout_probability=0.0,
                            n_long_gaps=0)
    k = 500
    real = _screen(_with_rate_pulse(sc, k, 3e-3, True))
    fault = _screen(_with_rate_pulse(sc, k, 3e-3, False))
    spike = {r: next(c for c in res.criteria if c.stream == "gyro" and c.name == "spike")
             for r, res in (("real", real), ("fault", fault))}
    assert not spike["real"].flagged[k] and real.findings["transients"]["gyro_spikes_confirmed_by_star_tracker"] == 1
    assert not real.rejected("star_tracker").any()
    assert spike["fault"].flagged[k] and "transients" not in fault.findings
    assert fault.rejected("star_tracker").any()  # the star tracker disagrees with the faulty gyro there


def _gracefo_gnv(sat):
    from processing.formats import gracefo_l1b as l1b
    from tests.real_data import GRACEFO

    t, r, v, _frame = l1b.gnv_states(l1b.parse_l1b((GRACEFO / f"GNV1B_2023-06-01_{sat}_04.txt").read_bytes()))
    return t, r, v


@pytest.mark.parametrize("sat", ["C", "D"])
def test_gracefo_gnv1b_precise_orbit_is_consistent_and_a_late_block_in_it_is_found(sat):
    from processing.orbits.gnss_checks import check_gnss_fit
    from processing.orbits.gnss_orbit import fit_gnss

    t, r, v = _gracefo_gnv(sat)  # 100 s of POD orbit at 1 Hz (sub-mm noise)
    c = check_gnss_fit(fit_gnss(t, r, v), t, r, v)
    assert c.consistent and c.cause is None  # sub-mm model residuals above the noise are not a fault
    chk = time_tag_check(t, r, v, position_sigma_m=0.01, velocity_sigma_m_s=1e-5)
    assert chk.applied.all() and chk.shift_consistent.all() and np.nanmax(np.abs(chk.offset_s)) < 1e-4
    # the states of rows 40..59 replaced by those 3 rows earlier (tags 3 s late), as a receiver would report
    r2, v2 = r.copy(), v.copy()
    r2[40:60], v2[40:60] = r[37:57], v[37:57]
    c2 = check_gnss_fit(fit_gnss(t, r2, v2), t, r2, v2, position_sigma_m=0.01, velocity_sigma_m_s=1e-5)
    assert not c2.consistent and abs(c2.late_offset_s - 3.0) < 1e-3
    np.testing.assert_array_equal(np.flatnonzero(c2.late_tags), np.arange(40, 60))
