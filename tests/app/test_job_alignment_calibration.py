"""Job ``alignment_calibration`` (paper 000) on simulator output: summary, tables, figures, input handling."""

import json

import numpy as np
import pytest
from matplotlib.figure import Figure
from pydantic import ValidationError

from app.jobs.types.alignment_calibration import JOB, Params
from processing.attitude import rotations
from processing.simulate.seed000 import simulate_seed000
from processing.spacecraft import Spacecraft
from processing.tasks import TaskError, TaskInputs, TaskResult, no_progress
from processing.time.timescales import iso_to_tai_ns
from processing.units import RAD_PER_ARCSEC

START = int(iso_to_tai_ns("2024-03-01T12:00:00"))
DURATION_S = 900.0
NS = 1_000_000_000


@pytest.fixture(scope="module")
def scenario():
    return simulate_seed000(start_tai_ns=START, duration_s=DURATION_S, seed=11)


def _inputs(streams, config):
    return TaskInputs(streams=streams, spacecraft=Spacecraft.from_json(config), start_tai_ns=START,
                      end_tai_ns=START + int(DURATION_S) * NS)


@pytest.fixture(scope="module")
def result(scenario) -> TaskResult:
    return JOB.run(_inputs(scenario.streams, scenario.config), JOB.params(), no_progress)


def test_job_declaration():
    assert JOB.name == "alignment_calibration" and JOB.paper == "000"
    assert JOB.streams == ("star_tracker",) and JOB.optional_streams == ("gyro_increments", "gyro")
    with pytest.raises(ValidationError):
        JOB.params(unknown=1)
    with pytest.raises(ValidationError, match="window_max_samples"):
        Params(window_min_samples=18, window_max_samples=12)
    assert Params().t_r_s == 200.0 and Params().rate_threshold_deg_s == 1.0


def test_summary_keys_units_and_json(result, scenario):
    s = result.summary
    json.dumps(s, allow_nan=False)  # plain JSON: floats, lists, None only
    for key in ("misalignment_rad", "misalignment_sigma_rad", "drift_rad_s", "misalignment_arcsec"):
        assert isinstance(s[key], list) and len(s[key]) == 3 and all(isinstance(v, float) for v in s[key])
    assert len(s["misalignment_quaternion"]) == 4 and isinstance(s["scale_factor_error"], float)
    assert isinstance(s["drift_convergence_s"], float) and isinstance(s["calibration_windows"], int)
    tr = scenario.truth
    # 15 minutes: the accuracy is ~2x that of an hour (the hour is tested in tests/processing)
    np.testing.assert_allclose(s["misalignment_rad"], tr.misalignment_rad, atol=2.0 * RAD_PER_ARCSEC)
    np.testing.assert_allclose(np.array(s["misalignment_sigma_rad"]) / RAD_PER_ARCSEC, 0.5, atol=0.4)
    assert s["scale_factor_error"] == pytest.approx(tr.scale_factor_error, abs=1e-5)
    np.testing.assert_allclose(s["drift_rad_s"], tr.drift_G_rad_s(DURATION_S), atol=0.01 * RAD_PER_ARCSEC)
    assert s["drift_convergence_s"] <= 60.0
    # DESIGN.md: misalignment_rad is the rotation vector of q_GS (the gyro is nominally aligned here)
    q_GS = np.array(s["q_GS"])
    np.testing.assert_allclose(s["misalignment_rad"], rotations.quat_to_rotvec(q_GS), atol=1e-15)
    np.testing.assert_allclose(s["misalignment_quaternion"], q_GS, atol=1e-15)
    assert s["misalignment_observable"] == [True, True, True] and s["calibration_complete"]
    assert s["sensor"] == "st1" and s["gyro_stream"] == "gyro_increments"
    assert s["n_gyro_samples"] == 115_200 and s["n_star_tracker_samples"] == 901
    assert s["converged"] and s["iterations"] >= 1 and s["solver_disagreement_rad"] < 1e-12
    assert s["slew_bound_exceeded"] == 0 and s["n_slews"] >= 4
    cal = s["calibration"]
    q_BG = np.array(cal["q_BG"])
    # the calibrated gyro mounting: q_BG = q_BS o q_GS^-1
    q_BS = np.array(scenario.config["star_trackers"]["st1"]["q_BS"])
    assert rotations.angle_between(q_BG, rotations.quat_multiply(q_BS, rotations.quat_conjugate(q_GS))) < 1e-15
    assert cal["drift_rad_s"] == s["drift_rad_s"] and cal["star_tracker"] == "st1"


def test_tables(result):
    t = result.tables
    assert set(t) == {"drift", "attitude_residuals", "rate_coverage", "rate_residuals", "slews"}
    n = len(t["drift"]["time_tai_ns"])
    assert n == 901 and all(len(v) == n for v in t["drift"].values())
    assert t["drift"]["time_tai_ns"][0] == START and t["drift"]["time_tai_ns"].dtype == np.int64
    assert set(t["drift"]["mode"]) == {"init", "corrected", "predicted", "resumed"}
    corrected = t["attitude_residuals"]["mode"] == "corrected"
    assert np.std(t["attitude_residuals"]["prior_x_arcsec"][corrected]) == pytest.approx(0.3, rel=0.3)
    cov = t["rate_coverage"]
    unit = np.stack([cov[f"direction_{a}"] for a in "xyz"], axis=-1)
    np.testing.assert_allclose(np.linalg.norm(unit, axis=-1), 1.0, atol=1e-12)
    assert np.all(cov["mean_rate_deg_s"] < 1.0) and cov["used"].sum() == result.summary["calibration_windows"]
    res = t["rate_residuals"]
    assert np.sqrt(np.mean(res["residual_x_arcsec_s"] ** 2)) < 0.5
    assert np.all(t["slews"]["end_error_arcsec"] <= t["slews"]["bound_arcsec"])


def test_figures(result):
    figs = JOB.figures(result, JOB.params())
    assert set(figs) == {"drift", "attitude_residuals", "rate_residuals", "rate_coverage"}
    assert all(isinstance(f, Figure) for f in figs.values())


def test_gyro_rates_are_integrated_to_increments(scenario):
    """Only a `gyro` stream (rates, here 32 Hz from the spline of the truth increments): the job integrates
    them by the trapezoid and still calibrates (less precisely: 32 Hz rates lose the increments' exactness)."""
    g = scenario.streams["gyro_increments"]
    t_ns = g["time_tai_ns"][3::4]
    incr = np.stack([g["dax"], g["day"], g["daz"]], axis=-1)
    rates = incr.reshape(-1, 4, 3).sum(axis=1) / (4.0 / 128.0)  # mean rate over each 1/32 s
    streams = {
        "star_tracker": scenario.streams["star_tracker"],
        "gyro": {"time_tai_ns": t_ns - NS // 64, "wx": rates[:, 0], "wy": rates[:, 1], "wz": rates[:, 2],
                 "sensor": np.full(t_ns.size, "gyro", dtype=object)},
    }
    out = JOB.run(_inputs(streams, scenario.config), JOB.params(), no_progress)
    s = out.summary
    assert s["gyro_stream"] == "gyro" and any("trapezoidal" in n for n in out.notes)
    np.testing.assert_allclose(s["misalignment_rad"], scenario.truth.misalignment_rad, atol=5.0 * RAD_PER_ARCSEC)
    assert s["scale_factor_error"] == pytest.approx(scenario.truth.scale_factor_error, abs=5e-5)
    np.testing.assert_allclose(s["drift_rad_s"], scenario.truth.drift_G_rad_s(DURATION_S), atol=0.05 * RAD_PER_ARCSEC)


def test_input_errors(scenario):
    only_st = {"star_tracker": scenario.streams["star_tracker"]}
    with pytest.raises(TaskError, match="no gyro_increments or gyro samples"):
        JOB.run(_inputs(only_st, scenario.config), JOB.params(), no_progress)
    with pytest.raises(TaskError, match="not in the spacecraft configuration"):
        JOB.run(_inputs(scenario.streams, scenario.config), JOB.params(sensor="st9"), no_progress)
    bad_config = {"star_trackers": {"st1": {"q_BS": [0, 0, 0, 0]}}, "gyro": {"q_BG": [1, 0, 0, 0]}}
    with pytest.raises(TaskError, match="q_BS"):
        JOB.run(_inputs(scenario.streams, bad_config), JOB.params(), no_progress)
    short = {k: {c: v[: len(v) // 30] for c, v in cols.items()} for k, cols in scenario.streams.items()}
    with pytest.raises(TaskError, match="star-tracker samples"):
        JOB.run(_inputs(short, scenario.config), JOB.params(), no_progress)
    with pytest.raises(TaskError, match="gyro_increments samples"):
        JOB.run(_inputs(only_st, scenario.config), JOB.params(gyro_source="gyro_increments"), no_progress)
