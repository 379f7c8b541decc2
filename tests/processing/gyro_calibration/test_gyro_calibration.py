"""End-to-end calibration against the truth of the seed-000 scenario (issue 7, "Done when").

Five seeds of one hour each (460,800 increments at 128 Hz, 3,601 star-tracker samples): drift within
0.01 "/s of the truth after convergence and convergence within 60 s; misalignment within 1" per axis;
scale-factor error within 0.005 %; through every slew (the first one 60 s at up to 5 deg/s) the
attitude error of the drift-predicted estimate stays below the bound of
processing.gyro_calibration.drift_observer.slew_error_bound.
"""

from dataclasses import dataclass

import numpy as np
import pytest

from processing.attitude import rotations
from processing.gyro_calibration.calibration import (
    CalibrationError,
    CalibrationSettings,
    apply_gyro_calibration,
    calibrate_gyro,
    correction_flags,
)
from processing.gyro_calibration.drift_observer import (
    MODE_CORRECTED,
    MODE_PREDICTED,
    MODE_RESUMED,
    run_drift_observer,
    slew_error_bound,
)
from processing.simulate.seed000 import GYRO_NOISE_000_RAD, Truth000, simulate_seed000

ARCSEC_RAD = np.pi / 648000.0
DEG_RAD = np.pi / 180.0
SEEDS = (0, 1, 2, 3, 4)
DURATION_S = 3600.0


@dataclass
class Run:
    truth: Truth000
    t_st: np.ndarray
    result: object


def _inputs(s):
    tr = s.truth
    g = s.streams["gyro_increments"]
    st = s.streams["star_tracker"]
    incr = np.stack([g["dax"], g["day"], g["daz"]], axis=-1)
    q = np.stack([st[f"q{i}"] for i in range(4)], axis=-1)
    return tr.seconds(g["time_tai_ns"]), incr, g["interval_s"], tr.seconds(st["time_tai_ns"]), q


def _inputs_from_truth(run):
    """The star-tracker quaternions of a run, rebuilt from the truth and its recorded noise."""
    tr = run.truth
    q = rotations.quat_multiply(tr.q_IS_st, rotations.rotvec_to_quat(tr.st_noise_rotvec_S))
    return None, None, None, run.t_st, rotations.quat_canonical(q)


@pytest.fixture(scope="module")
def runs() -> dict[int, Run]:
    out = {}
    for seed in SEEDS:
        s = simulate_seed000(start_tai_ns=0, duration_s=DURATION_S, seed=seed)
        t_g, incr, dt, t_st, q = _inputs(s)
        out[seed] = Run(truth=s.truth, t_st=t_st, result=calibrate_gyro(t_g, incr, dt, t_st, q))
    return out


@pytest.mark.parametrize("seed", SEEDS)
def test_drift_converges_within_60_s_to_0_01_arcsec_s(runs, seed):
    run = runs[seed]
    obs = run.result.observer
    truth_b = run.truth.drift_G_rad_s(run.t_st)
    err = np.abs(obs.drift_rad_s - truth_b) / ARCSEC_RAD
    outside = np.flatnonzero(np.any(err > 0.01, axis=1))
    converged_at = run.t_st[outside[-1] + 1] if outside.size else 0.0
    assert converged_at <= 60.0, converged_at  # and it stays within 0.01 "/s to the end, slews included
    assert np.all(err[run.t_st > 60.0] < 0.01)
    # the reported drift (trend of the last window, at the end) and the estimate of the convergence time
    np.testing.assert_allclose(run.result.drift_rad_s / ARCSEC_RAD, truth_b[-1] / ARCSEC_RAD, atol=0.01)
    assert run.result.drift_convergence_s <= 60.0


@pytest.mark.parametrize("seed", SEEDS)
def test_misalignment_within_1_arcsec(runs, seed):
    run = runs[seed]
    est = run.result.alignment
    err = (est.misalignment_rad - run.truth.misalignment_rad) / ARCSEC_RAD
    sigma = est.misalignment_sigma_rad / ARCSEC_RAD
    assert np.all(np.abs(err) < 1.0), err
    assert np.all(np.abs(err) < 4.0 * sigma), (err, sigma)  # the jackknife sigma is honest
    assert np.all(sigma < 0.5) and np.all(est.observable_axes)
    assert est.n_windows >= 90 and est.solver_disagreement_rad < 1e-12
    assert run.result.converged and len(run.result.iterations) <= 4


@pytest.mark.parametrize("seed", SEEDS)
def test_scale_factor_within_0_005_percent(runs, seed):
    run = runs[seed]
    est = run.result.alignment
    err = est.scale_factor_error - run.truth.scale_factor_error
    assert abs(err) < 0.005e-2, err
    assert abs(err) < 4.0 * est.scale_factor_sigma


@pytest.mark.parametrize("seed", SEEDS)
def test_attitude_error_through_slews_below_the_bound(runs, seed):
    """Every slew of the scenario (correction off while |w| > 1 deg/s): the attitude error of the
    drift-predicted estimate when the correction resumes is below slew_error_bound, evaluated with the
    errors actually made (a posteriori) and with the job's own 3-sigma terms (the reported bound)."""
    run = runs[seed]
    res, tr = run.result, run.truth
    obs = res.observer
    q_true = tr.q_IS(run.t_st)
    att_err = rotations.angle_between(obs.q_prior, q_true)
    post_err = rotations.angle_between(obs.q_post, q_true)
    resumed = np.flatnonzero(obs.mode == MODE_RESUMED)
    assert resumed.size == res.slews.start_s.size >= 15
    dm = abs(res.alignment.scale_factor_error - tr.scale_factor_error)
    dtheta = np.linalg.norm(res.alignment.misalignment_rad - tr.misalignment_rad)
    for k, start, end, angle, bound_reported in zip(resumed, res.slews.start_s, res.slews.end_s,
                                                    res.slews.rotation_angle_rad, res.slews.bound_rad, strict=True):
        j = int(np.searchsorted(run.t_st, start))
        assert obs.mode[j] == MODE_CORRECTED and np.all(obs.mode[j + 1 : k] == MODE_PREDICTED)
        db = np.max(np.linalg.norm(obs.drift_rad_s[j:k] - tr.drift_G_rad_s(run.t_st[j:k]), axis=-1))
        posterior = slew_error_bound(end - start, angle, initial_error_rad=post_err[j], drift_error_rad_s=db,
                                     scale_factor_error=dm, misalignment_error_rad=dtheta,
                                     gyro_noise_rad=GYRO_NOISE_000_RAD * np.sqrt(3))
        assert att_err[k] <= posterior, (k, att_err[k] / ARCSEC_RAD, posterior / ARCSEC_RAD)
        assert att_err[k] <= bound_reported


@pytest.mark.parametrize("seed", SEEDS)
def test_drift_prediction_through_a_60_s_slew(runs, seed):
    """The first slew (60 s, 5 deg/s peak, 150 deg) with the correction off for a full 60 s around it: the
    observer re-run on the calibrated rotations predicts the drift from its trend, and the attitude error
    at the end is below the bound with the issue's tolerances as errors (0.01 "/s per axis, 0.005 %,
    1" per axis) and below the bound with the errors actually made."""
    run = runs[seed]
    res, tr = run.result, run.truth
    rot = res.rotations
    on = correction_flags(rot.max_rate_rad_s, rot.valid, DEG_RAD)
    k_end = int(np.flatnonzero(res.observer.mode == MODE_RESUMED)[0])
    k_start = k_end - 60
    on[k_start + 1 : k_end] = False
    _, _, _, _, q = _inputs_from_truth(run)
    obs = run_drift_observer(run.t_st, q, rot.q, rot.rotvec_rad, rot.valid, on, rate_map=res.observer_rate_map,
                             drift_ref_rad_s=res.observer_drift_ref_rad_s, t_r_s=CalibrationSettings().t_r_s)
    assert obs.mode[k_start] == MODE_CORRECTED and obs.mode[k_end] == MODE_RESUMED
    assert np.all(obs.mode[k_start + 1 : k_end] == MODE_PREDICTED)
    duration = run.t_st[k_end] - run.t_st[k_start]
    angle = np.sum(np.linalg.norm(rot.rotvec_rad[k_start:k_end], axis=-1))
    assert duration == 60.0 and angle > 140 * DEG_RAD
    q_true = tr.q_IS(run.t_st[[k_start, k_end]])
    e0 = rotations.angle_between(obs.q_post[k_start], q_true[0])
    error = rotations.angle_between(obs.q_prior[k_end], q_true[1])
    a_priori = slew_error_bound(duration, angle, initial_error_rad=e0, drift_error_rad_s=0.01 * ARCSEC_RAD * np.sqrt(3),
                                scale_factor_error=0.005e-2, misalignment_error_rad=np.sqrt(3) * ARCSEC_RAD,
                                gyro_noise_rad=GYRO_NOISE_000_RAD * np.sqrt(3))
    db = np.max(np.linalg.norm(obs.drift_rad_s[k_start:k_end] - tr.drift_G_rad_s(run.t_st[k_start:k_end]), axis=-1))
    assert db < 0.01 * ARCSEC_RAD  # the predicted drift stays within the tolerance through the slew
    posterior = slew_error_bound(
        duration, angle, initial_error_rad=e0, drift_error_rad_s=db,
        scale_factor_error=abs(res.alignment.scale_factor_error - tr.scale_factor_error),
        misalignment_error_rad=np.linalg.norm(res.alignment.misalignment_rad - tr.misalignment_rad),
        gyro_noise_rad=GYRO_NOISE_000_RAD * np.sqrt(3),
    )
    assert a_priori / ARCSEC_RAD < 40.0  # 2.6 rad turned: the scale-factor tolerance dominates (27")
    assert error <= posterior <= a_priori, (error / ARCSEC_RAD, posterior / ARCSEC_RAD, a_priori / ARCSEC_RAD)
    assert error < 3.0 * ARCSEC_RAD  # what it actually is


def test_too_little_data_is_refused():
    s = simulate_seed000(start_tai_ns=0, duration_s=40.0, seed=0)
    with pytest.raises(CalibrationError, match="star-tracker samples"):
        calibrate_gyro(*_inputs(s))
    s = simulate_seed000(start_tai_ns=0, duration_s=200.0, seed=0, initial_hold_s=5.0,
                         scan_peak_rate_rad_s=(3.0 * DEG_RAD, 4.0 * DEG_RAD))
    with pytest.raises(CalibrationError, match="alignment windows"):
        calibrate_gyro(*_inputs(s), settings=CalibrationSettings(window_min=18))


def test_apply_gyro_calibration_inverts_eq1():
    """Body rates from gyro data with the true calibration: R(q_BG) (w_G - b) / (1 + m) = w_B."""
    s = simulate_seed000(start_tai_ns=0, duration_s=20.0, seed=3, gyro_noise_std_rad=0.0)
    tr = s.truth
    g = s.streams["gyro_increments"]
    incr = np.stack([g["dax"], g["day"], g["daz"]], axis=-1)
    q_BG = rotations.quat_multiply(tr.q_BS, rotations.quat_conjugate(tr.q_GS))
    t_mid = tr.seconds(g["time_tai_ns"]) - 0.5 * g["interval_s"]
    out = apply_gyro_calibration(incr, q_BG=q_BG, scale_factor_error=tr.scale_factor_error,
                                 drift_rad_s=tr.drift_G_rad_s(0.0), interval_s=g["interval_s"])
    np.testing.assert_allclose(out / g["interval_s"][:, None], tr.plan.w_B(t_mid), atol=1e-9)  # mean vs midpoint
    w_G = (1 + tr.scale_factor_error) * rotations.quat_rotate(tr.q_GS, tr.w_S(t_mid)) + tr.drift_G_rad_s(0.0)
    np.testing.assert_allclose(apply_gyro_calibration(w_G, q_BG=q_BG, scale_factor_error=tr.scale_factor_error,
                                                      drift_rad_s=tr.drift_G_rad_s(0.0)), tr.plan.w_B(t_mid),
                               atol=1e-16)
    with pytest.raises(CalibrationError, match="interval_s"):
        apply_gyro_calibration(incr, q_BG=q_BG, scale_factor_error=0.0, drift_rad_s=np.zeros(3), interval_s=[1.0])
