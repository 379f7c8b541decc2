"""Job ``alignment_calibration`` (paper 000) on simulator output: summary, tables, figures, input handling."""

import json
import types

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
    for key in ("misalignment_rad", "misalignment_sigma_rad", "drift_rad_s", "drift_sigma_rad_s",
                "misalignment_arcsec"):
        assert isinstance(s[key], list) and len(s[key]) == 3 and all(isinstance(v, float) for v in s[key])
    assert len(s["misalignment_quaternion"]) == 4 and isinstance(s["scale_factor_error"], float)
    assert isinstance(s["drift_convergence_s"], float) and isinstance(s["calibration_windows"], int)
    tr = scenario.truth
    # 15 minutes: the accuracy is ~2x that of an hour (the hour is tested in tests/processing)
    np.testing.assert_allclose(s["misalignment_rad"], tr.misalignment_rad, atol=2.0 * RAD_PER_ARCSEC)
    # sigmas from the information matrix with the window noise model (bench/alignment_observability.py:
    # 3-sigma coverage over 30 seeds), here ~0.8"; every value within 3 of its sigmas of the truth
    sig = np.array(s["misalignment_sigma_rad"])
    assert np.all((sig > 0.2 * RAD_PER_ARCSEC) & (sig < 1.5 * RAD_PER_ARCSEC)), sig / RAD_PER_ARCSEC
    assert np.all(np.abs(np.array(s["misalignment_rad"]) - tr.misalignment_rad) < 3 * sig)
    assert s["scale_factor_error"] == pytest.approx(tr.scale_factor_error, abs=1e-5)
    assert abs(s["scale_factor_error"] - tr.scale_factor_error) < 3 * s["scale_factor_error_sigma"] < 3e-5
    np.testing.assert_allclose(s["drift_rad_s"], tr.drift_G_rad_s(DURATION_S), atol=0.01 * RAD_PER_ARCSEC)
    d_sig = np.array(s["drift_sigma_rad_s"])
    assert np.all(np.abs(np.array(s["drift_rad_s"]) - tr.drift_G_rad_s(DURATION_S)) < 3 * d_sig)
    assert np.all(d_sig < 0.02 * RAD_PER_ARCSEC)
    # everything determined: no warning, observability flags true, the information matrix of full rank
    assert result.warnings == []
    assert s["scale_factor_observable"] is True and s["drift_observable"] == [True, True, True]
    obs = s["observability"]
    assert obs["rank"] == 7 and all(obs["determinable"]) and min(obs["relative_eigenvalues"]) > 0.05
    assert obs["parameters"][:4] == ["scale_factor", "misalignment_x", "misalignment_y", "misalignment_z"]
    # the plausibility check of the head against the gyro (app.jobs.plausibility), its time offset on top
    assert s["plausibility"]["st1"]["checked"] and s["plausibility"]["st1"]["convention"] == "as_given"
    assert abs(s["time_offset_s"]) < 3 * s["time_offset_sigma_s"] < 0.01
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


@pytest.fixture(scope="module")
def nadir():
    """The orbital orientation held for the whole arc: a constant rate (the orbital pitch rate) only."""
    sc = simulate_seed000(start_tai_ns=START, duration_s=DURATION_S, seed=12, initial_hold_s=1e6)
    return sc, JOB.run(_inputs(sc.streams, sc.config), JOB.params(), no_progress)


def test_constant_rate_arc_determines_nothing(nadir):
    """Issue 17: a constant rate about one axis determines neither misalignment nor scale factor nor drift
    (only their sum, the apparent drift): all null with *_observable false, a not_observable warning that
    says which motion would determine them, no calibration version, trends without points."""
    sc, res = nadir
    s = res.summary
    json.dumps(s, allow_nan=False)
    assert s["misalignment_rad"] == [None] * 3 and s["misalignment_sigma_rad"] == [None] * 3
    assert s["misalignment_observable"] == [False] * 3
    assert s["scale_factor_error"] is None and s["scale_factor_error_sigma"] is None
    assert s["scale_factor_observable"] is False
    assert s["drift_rad_s"] == [None] * 3 and s["drift_sigma_rad_s"] == [None] * 3
    assert s["drift_observable"] == [False] * 3
    assert s["observability"]["rank"] == 3 and not any(s["observability"]["determinable"])
    assert s["calibration_complete"] is False and s["calibration"]["complete"] is False
    assert s["calibration"]["scale_factor_error"] is None and s["calibration"]["drift_rad_s"] == [None] * 3
    # the apparent drift (what compensates the gyro, with the chain's own calibration, under this very motion)
    assert all(isinstance(v, float) for v in s["apparent_drift_rad_s"])
    codes = [w.code for w in res.warnings]
    assert codes == ["not_observable"], codes
    msg = res.warnings[0].message
    assert "misalignment about x" in msg and "the scale factor" in msg and "drift z" in msg
    assert "rotate also about" in msg and "vary the rate magnitude" in msg
    # how fast: about the rate that would give a 1" misalignment sigma with windows like these (000's ~0.3-0.9
    # deg/s scans give ~1" on 15 min, tests above) and the rate spread for a 0.005 % scale-factor sigma
    need = res.warnings[0].evidence["rate_needed_deg_s"]
    assert 0.05 <= need["misalignment_1_arcsec"] < 1.0 and 0.01 <= need["scale_factor_0_005_percent_spread"] < 1.0
    # the missing rotation axes are the body axes perpendicular to the pitch axis (body y)
    axes = np.array(res.warnings[0].evidence["rate_axes_body"])
    assert abs(axes[0][1]) > 0.999 and np.all(np.abs(axes[1:, 1]) < 0.01)
    from app.reports import specs, trends

    job = types.SimpleNamespace(id="n", type="alignment_calibration", start_tai_ns=START, end_tai_ns=START + NS,
                                result={"summary": s}, params={}, created_at=0)
    got = trends.trends([job], trends.KEY_METRICS, specs.Specifications())
    values = [v for t in got for p in t.points for v in p.values]
    assert all(v is None for v in values), values


def test_one_axis_arc_determines_the_perpendicular_misalignment():
    """Every slew and scan about body y (with the orbital rate: all rates about one axis, of varying
    magnitude): the misalignment about the rate axis is undetermined (its S components y and z are null),
    the one about S x, the scale factor and the drift are determined and within 3 sigma of the truth."""
    sc = simulate_seed000(start_tai_ns=START, duration_s=DURATION_S, seed=13, maneuver_axis_B=(0.0, 1.0, 0.0))
    res = JOB.run(_inputs(sc.streams, sc.config), JOB.params(), no_progress)
    s, tr = res.summary, sc.truth
    assert s["misalignment_observable"] == [True, False, False]
    assert s["misalignment_rad"][1:] == [None, None]
    assert abs(s["misalignment_rad"][0] - tr.misalignment_rad[0]) < 3 * s["misalignment_sigma_rad"][0]
    assert abs(s["scale_factor_error"] - tr.scale_factor_error) < 3 * s["scale_factor_error_sigma"]
    err = np.array(s["drift_rad_s"]) - tr.drift_G_rad_s(DURATION_S)
    assert np.all(np.abs(err) < 3 * np.array(s["drift_sigma_rad_s"]))
    assert [w.code for w in res.warnings] == ["not_observable"] and not s["calibration_complete"]
    assert "misalignment about y" in res.warnings[0].message


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


def test_per_axis_scale_factor_option(scenario):
    """per_axis_scale_factor: m per gyro axis with its sigma and flags (here the truth is the same on all axes)."""
    res = JOB.run(_inputs(scenario.streams, scenario.config), JOB.params(per_axis_scale_factor=True), no_progress)
    s = res.summary
    assert s["scale_factor_observable"] == [True, True, True] and res.warnings == []
    assert s["observability"]["parameters"][:3] == ["scale_factor_x", "scale_factor_y", "scale_factor_z"]
    m, sig = np.array(s["scale_factor_error_per_axis"]), np.array(s["scale_factor_error_per_axis_sigma"])
    assert np.all(np.abs(m - scenario.truth.scale_factor_error) < 3 * sig) and np.all(sig < 2e-5)
    assert abs(s["scale_factor_error"] - scenario.truth.scale_factor_error) < 3 * s["scale_factor_error_sigma"]
