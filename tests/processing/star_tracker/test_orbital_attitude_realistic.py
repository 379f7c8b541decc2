"""orbital_attitude on realistic telemetry (processing.simulate.realistic): manoeuvre segmentation, the GNSS
fit judged against the receiver noise (late tags named and dropped), the orbit-frame error in the sigma, and
the 3-2-1 sequence -- all against the simulator's truth."""

from functools import cache

import numpy as np
import pytest

from processing.attitude import rotations
from processing.orbits.gnss_checks import check_gnss_fit
from processing.orbits.gnss_orbit import fit_gnss
from processing.simulate.realistic import simulate_realistic
from processing.star_tracker.orbital_attitude import OrbitalAttitudeError, euler_angles, orbital_attitude
from processing.time.timescales import iso_to_tai_ns
from processing.units import ARCSEC_PER_RAD

T0 = int(iso_to_tai_ns("2023-06-01T00:00:00"))


@cache
def scenario(n_late_blocks=0):
    return simulate_realistic(start_tai_ns=T0, duration_s=1500.0, seed=21, manoeuvre_start_s=600.0,
                              manoeuvre_duration_s=200.0, n_late_blocks=n_late_blocks, late_block_s=60.0)


def _run(sc, **kw):
    st, g = sc.streams["star_tracker"], sc.streams["gnss"]
    return orbital_attitude(st["time_tai_ns"], np.stack([st[f"q{i}"] for i in range(4)], axis=1),
                            g["time_tai_ns"], np.stack([g[c] for c in ("x", "y", "z")], axis=1),
                            np.stack([g[c] for c in ("vx", "vy", "vz")], axis=1), q_BS=sc.truth.q_BS, **kw)


def _angle_errors_arcsec(res, sc, raw=False):
    """(N, 3) errors of the 3-2-1 angles against the truth's, and the mask of samples in the manoeuvre."""
    idx = np.searchsorted(sc.truth.st_time_tai_ns, res.time_tai_ns)
    truth = euler_angles(sc.truth.st_q_OB[idx], "321")
    got = (res.pitch_raw_rad, res.yaw_raw_rad, res.roll_raw_rad) if raw else (res.pitch_rad, res.yaw_rad, res.roll_rad)
    err = np.stack([np.angle(np.exp(1j * (a - b))) for a, b in zip(got, truth, strict=True)], axis=1) * ARCSEC_PER_RAD
    a, b = sc.truth.manoeuvre_tai_ns
    return err, (res.time_tai_ns >= a) & (res.time_tai_ns <= b)


def _rms(x):
    return np.sqrt(np.mean(x ** 2, axis=0))


def test_smoothing_segments_at_the_manoeuvre_and_stays_within_2x_of_the_unsmoothed_error():
    sc = scenario()
    res = _run(sc, euler_sequence="321", harmonics=15)
    (start, end), = res.manoeuvres_tai_ns
    a, b = sc.truth.manoeuvre_tai_ns
    t = res.time_tai_ns
    before, after = t[t <= a][-1], t[t >= b][0]  # last sample before and first after (gaps may hide the edges)
    assert before - 15e9 < start < a + 15e9 and b - 15e9 < end < after + 15e9, ((start - a) / 1e9, (end - b) / 1e9)
    err, m = _angle_errors_arcsec(res, sc)
    err_raw, _ = _angle_errors_arcsec(res, sc, raw=True)
    assert np.all(_rms(err[m]) < 2.0 * _rms(err_raw[m])), (_rms(err[m]), _rms(err_raw[m]))
    assert np.all(_rms(err[~m]) < _rms(err_raw[~m]))  # smoothing helps outside the manoeuvre
    flat = _run(sc, euler_sequence="321", harmonics=15, segment_at_manoeuvres=False)
    err_flat, _ = _angle_errors_arcsec(flat, sc)
    assert flat.manoeuvres_tai_ns == ()
    assert _rms(err_flat[m])[1] > 5.0 * _rms(err_raw[m])[1]  # a smoother across the turn fails the 2x in yaw


def test_no_manoeuvre_found_without_one():
    sc = simulate_realistic(start_tai_ns=T0, duration_s=1200.0, seed=22, n_late_blocks=0)
    assert _run(sc, smoothing=False).manoeuvres_tai_ns == ()


def test_321_angles_rebuild_q_OB_and_differ_from_231_through_the_turn():
    sc = scenario()
    res = _run(sc, euler_sequence="321", smoothing=False)
    x, y, z = (np.array(v, dtype=float) for v in np.eye(3))
    q = rotations.quat_multiply(rotations.quat_multiply(rotations.quat_from_axis_angle(z, res.yaw_rad),
                                                        rotations.quat_from_axis_angle(y, res.pitch_rad)),
                                rotations.quat_from_axis_angle(x, res.roll_rad))
    np.testing.assert_allclose(rotations.angle_between(q, res.q_OB), 0.0, atol=1e-7)
    stats = res.angle_statistics_deg()
    assert 170.0 < abs(stats["yaw_deg"]["max"] - stats["yaw_deg"]["min"]) < 190.0
    assert abs(stats["pitch_deg"]["max"]) < 1.0
    other = res.angle_statistics_deg(sequence="231")
    assert abs(other["pitch_deg"]["max"] - other["pitch_deg"]["min"]) > 90.0  # 2-3-1 passes its singularity
    with pytest.raises(OrbitalAttitudeError, match="euler_sequence"):
        _run(sc, euler_sequence="123", smoothing=False)


def test_clean_gnss_fit_is_consistent_with_the_estimated_noise():
    sc = scenario()
    res = _run(sc, smoothing=False)
    c = res.gnss_check
    assert c.consistent and c.cause is None and not c.late_tags.any()
    np.testing.assert_allclose(c.position_sigma_m, np.sqrt(1 + 1 / 12), rtol=0.1)
    assert res.gnss_dropped_late == 0 and res.orbit_frame_sigma_rad.max() * ARCSEC_PER_RAD < 0.1


def test_late_gnss_tags_named_dropped_and_their_error_in_the_sigma():
    sc = scenario(n_late_blocks=2)
    kept = _run(sc, smoothing=False, euler_sequence="321", drop_late_gnss_tags=False)
    c = kept.gnss_check
    assert not c.consistent and max(c.rms_ratio) > 100
    assert "time tags" in c.cause and abs(c.late_offset_s - 3.4) < 0.01
    np.testing.assert_array_equal(c.late_tags, sc.truth.gnss_late)
    err_kept, _ = _angle_errors_arcsec(kept, sc, raw=True)
    clean = _run(scenario(), smoothing=False, euler_sequence="321")
    err_clean, _ = _angle_errors_arcsec(clean, sc, raw=True)
    excess = np.sqrt(np.maximum(_rms(err_kept) ** 2 - _rms(err_clean) ** 2, 0.0))
    assert excess.max() > 10.0  # the late tags do turn the orbital frame
    sigma = kept.orbit_frame_sigma_rad * ARCSEC_PER_RAD
    assert np.all(excess < 2.0 * sigma), (excess, sigma)  # and the reported frame error covers it
    dropped = _run(sc, smoothing=False, euler_sequence="321")
    assert dropped.gnss_dropped_late == sc.truth.gnss_late.sum() and dropped.gnss_recheck.consistent
    err_dropped, _ = _angle_errors_arcsec(dropped, sc, raw=True)
    np.testing.assert_allclose(_rms(err_dropped), _rms(err_clean), rtol=0.05)


def test_inertial_velocities_named_as_a_frame_error():
    sc = scenario()
    g = sc.streams["gnss"]
    t = g["time_tai_ns"]
    r = np.stack([g[c] for c in ("x", "y", "z")], axis=1)
    v = np.stack([g[c] for c in ("vx", "vy", "vz")], axis=1) + np.cross([0.0, 0.0, 7.292115e-5], r)
    c = check_gnss_fit(fit_gnss(t, r, v), t, r, v)
    assert not c.consistent and c.inertial_velocity and "frame" in c.cause
