"""Job ``gyro_bias_fit`` (003 §2) on seed-003 simulator output: keys, types, frames, figures, errors."""

from __future__ import annotations

import io
import json
from typing import Any

import numpy as np
import pytest
from matplotlib.figure import Figure
from pydantic import ValidationError

from app.jobs.types.gyro_bias_fit import JOB
from processing.attitude import rotations as rot
from processing.simulate.seed003 import Scenario003, simulate_seed003
from processing.spacecraft import Spacecraft
from processing.tasks import TaskError, TaskInputs, TaskResult, no_progress
from processing.units import RAD_PER_ARCSEC
from tests.app.helpers import assert_json_plain

T0_NS = 1_900_000_000 * 1_000_000_000


def scenario(seed: int = 2, **kwargs: Any) -> Scenario003:
    return simulate_seed003(start_tai_ns=T0_NS, seed=seed, gnss_period_s=1200.0, **kwargs)


def inputs(sc: Scenario003, streams: dict[str, Any] | None = None, config: dict[str, Any] | None = None) -> TaskInputs:
    return TaskInputs(
        streams=sc.streams if streams is None else streams,
        spacecraft=Spacecraft.from_json(sc.config if config is None else config),
        start_tai_ns=T0_NS,
        end_tai_ns=T0_NS + 1200 * 1_000_000_000,
    )


def run(sc: Scenario003, **params: Any) -> TaskResult:
    return JOB.run(inputs(sc), JOB.params(**params), no_progress)


@pytest.fixture(scope="module")
def default_result() -> tuple[Scenario003, TaskResult]:
    sc = scenario()
    return sc, run(sc)


def test_summary_keys_types_and_truth(default_result: tuple[Scenario003, TaskResult]) -> None:
    sc, result = default_result
    s = result.summary
    assert_json_plain(s)
    json.dumps(s, allow_nan=False)
    for key in ("gyro_bias_rad_s", "gyro_bias_sigma_rad_s", "gyro_bias_sigma_paper_rad_s", "delta_sensor_arcsec_s",
                "delta_sensor_sigma_arcsec_s", "delta_sensor_sigma_paper_arcsec_s", "delta_body_arcsec_s",
                "initial_mrp", "initial_mrp_sigma", "initial_mrp_sigma_paper", "residual_rms_arcsec",
                "residual_rms_gyro_arcsec", "star_tracker_sigma_arcsec", "gyro_arw_rad_sqrt_s"):
        assert isinstance(s[key], list) and len(s[key]) == 3, key
    assert isinstance(s["sigma_unit_weight"], float)
    assert isinstance(s["iterations"], int) and s["converged"] is True
    assert s["reference_sensor"] == "st1" and s["mounting"] is None
    # body frame, w_meas = w_true + b (q_BG = 1 here)
    b, sig = np.array(s["gyro_bias_rad_s"]), np.array(s["gyro_bias_sigma_rad_s"])
    assert np.all(np.abs(b - sc.truth.gyro_bias0_rad_s) <= 4 * sig)
    assert np.all(np.array(s["gyro_bias_sigma_paper_rad_s"]) < 0.2 * sig)  # the paper's figure is optimistic
    # the paper's Delta in the sensor frame is -(bias in S)
    delta = -rot.quat_rotate(rot.quat_conjugate(sc.truth.q_BS), b) / RAD_PER_ARCSEC
    np.testing.assert_allclose(s["delta_sensor_arcsec_s"], delta, atol=1e-9)
    np.testing.assert_allclose(s["delta_body_arcsec_s"], -b / RAD_PER_ARCSEC, atol=1e-9)
    assert s["initial_time"].endswith("Z") and s["initial_time_tai_ns"] == T0_NS
    q_IB0 = np.array(s["initial_q_IB"])
    # a small rotation theta has MRP theta / 4
    assert rot.angle_between(q_IB0, sc.truth.q_IB_gyro[0]) < 4 * 4 * np.linalg.norm(s["initial_mrp_sigma"])
    np.testing.assert_allclose(rot.quat_to_mrp(s["initial_q_IS"]), s["initial_mrp"], atol=1e-12)
    assert len(s["covariance"]) == 6 and len(s["covariance"][0]) == 6
    assert set(s["sensors"]) == {"st1"}
    # clean data: no warning; the time offset is determined (and ~0), the offsets pass the constancy test
    assert result.warnings == [] and s["quaternion_convention"] == "as_given"
    assert s["time_offset_observable"] is True and s["time_offset_corrected_s"] is None
    assert abs(s["time_offset_s"]) < 3 * s["time_offset_sigma_s"] < 0.1
    c = s["offset_constancy"]
    assert c["constant"] is True and c["parts"] == 4 and c["dof"] == 9 and c["inflation"] == [1.0, 1.0, 1.0]
    assert s["gyro_bias_sigma_rad_s"] == s["gyro_bias_sigma_constant_rad_s"]
    assert max(s["residual_consistency"]) < 2.0 and s["status"] == "converged"
    assert s["sensors"]["st1"]["plausibility"]["convention"] == "as_given"


def test_subintervals_halves_and_quarters(default_result: tuple[Scenario003, TaskResult]) -> None:
    _, result = default_result
    subs = result.summary["subintervals"]
    assert [(r["parts"], r["index"]) for r in subs] == [(2, 0), (2, 1), (4, 0), (4, 1), (4, 2), (4, 3)]
    for r in subs:
        assert {"start", "end", "gyro_bias_rad_s", "gyro_bias_sigma_rad_s"} <= set(r)
        assert r["start"] < r["end"] and r["start_tai_ns"] < r["end_tai_ns"]
        assert len(r["gyro_bias_rad_s"]) == 3 and r["n_samples"] > 50
    table = result.tables["subintervals"]
    assert table["delta1_sensor_arcsec_s"].shape == (6,)
    np.testing.assert_allclose(table["gyro_bias2_rad_s"], [r["gyro_bias_rad_s"][1] for r in subs])


def test_tables(default_result: tuple[Scenario003, TaskResult]) -> None:
    sc, result = default_result
    res = result.tables["residuals"]
    n = sc.streams["star_tracker"]["time_tai_ns"].size
    assert set(res) == {"time_tai_ns", "sensor", "e1_arcsec", "e2_arcsec", "e3_arcsec"}
    assert all(len(v) == n for v in res.values()) and res["time_tai_ns"].dtype == np.int64
    rms = [float(np.sqrt(np.mean(res[f"e{i}_arcsec"] ** 2))) for i in (1, 2, 3)]
    np.testing.assert_allclose(rms, result.summary["residual_rms_arcsec"], rtol=1e-12)
    rates = result.tables["rates"]
    assert rates["time_tai_ns"].size == sc.streams["gyro"]["time_tai_ns"].size  # 12,001 < 20,000 rows
    # rates corrected by the estimated bias are close to the truth (noise 1.5"/s)
    err = rates["w2_B_deg_s"] * 3600 - sc.truth.w_B_gyro[:, 1] / RAD_PER_ARCSEC
    assert abs(np.mean(err)) < 0.1 and 1.3 < np.std(err) < 1.7


def test_figures(default_result: tuple[Scenario003, TaskResult]) -> None:
    _, result = default_result
    figs = JOB.figures(result, JOB.params())
    assert set(figs) == {"rates", "residuals", "subintervals"}
    for fig in figs.values():
        assert isinstance(fig, Figure)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=40)
        assert buf.getvalue()[:4] == b"\x89PNG"


def test_body_frame_with_a_rotated_gyro() -> None:
    q_BG = tuple(rot.quat_from_axis_angle([0.3, 1.0, -0.2], 0.9).tolist())
    sc = scenario(6, q_BG=q_BG)
    s = run(sc, scheme=1, subintervals=[]).summary
    b_B = rot.quat_rotate(np.array(q_BG), sc.truth.gyro_bias0_rad_s)  # the gyro-frame bias turned into B
    assert np.all(np.abs(np.array(s["gyro_bias_rad_s"]) - b_B) <= 4 * np.array(s["gyro_bias_sigma_rad_s"]))
    assert s["subintervals"] == [] and s["scheme"] == 1


def test_smoothed_rates_variant() -> None:
    sc = scenario(3)
    result = run(sc, use_smoothed_rates=True, subintervals=[2])
    s = result.summary
    assert s["use_smoothed_rates"] is True and isinstance(s["smoothing_harmonics"], int)
    assert np.all(np.abs(np.array(s["gyro_bias_rad_s"]) - sc.truth.gyro_bias0_rad_s)
                  <= 4 * np.array(s["gyro_bias_sigma_rad_s"]))
    assert any("omega_ap" in n for n in result.notes)
    assert "w1_B_ap_deg_s" in result.tables["rates"]
    fixed = run(sc, use_smoothed_rates=True, smoothing_harmonics=30, subintervals=[]).summary
    assert fixed["smoothing_harmonics"] == 30


def test_mounting_not_determinable_is_reported(default_result: tuple[Scenario003, TaskResult]) -> None:
    sc, base = default_result
    s = run(sc, estimate_mounting=True, subintervals=[]).summary
    m = s["mounting"]
    assert m["determinable"] is False and m["misalignment_sensor_rad"] is None and m["q_BS"] is None
    assert "not determinable" in m["reason"] and len(m["correlation"]) == 9
    np.testing.assert_allclose(s["gyro_bias_rad_s"], base.summary["gyro_bias_rad_s"], rtol=1e-9)


def test_two_star_trackers_jointly() -> None:
    sc = scenario(4)
    st = sc.streams["star_tracker"]
    q_BS2 = rot.quat_multiply(sc.truth.q_BS, rot.quat_from_axis_angle([1.0, 0.0, 0.0], -np.pi / 2))
    noise = np.random.default_rng(0).normal(size=(st["time_tai_ns"].size, 3)) * [2.5, 5, 15] * RAD_PER_ARCSEC
    q2 = rot.quat_canonical(rot.quat_multiply(rot.quat_multiply(sc.truth.q_IB_st, q_BS2), rot.rotvec_to_quat(noise)))
    both = {k: np.concatenate([st[k], st[k]]) for k in ("time_tai_ns", "q0", "q1", "q2", "q3")}
    for i in range(4):
        both[f"q{i}"][st["time_tai_ns"].size:] = q2[:, i]
    both["sensor"] = np.array(["st1"] * st["time_tai_ns"].size + ["st2"] * st["time_tai_ns"].size, dtype=object)
    config = {**sc.config, "star_trackers": {**sc.config["star_trackers"], "st2": {"q_BS": q_BS2.tolist()}}}
    streams = {**sc.streams, "star_tracker": both}
    s = JOB.run(inputs(sc, streams, config), JOB.params(subintervals=[]), no_progress).summary
    assert set(s["sensors"]) == {"st1", "st2"} and s["reference_sensor"] == "st1"
    assert s["n_star_tracker_samples"] == 2 * st["time_tai_ns"].size
    only2 = JOB.run(inputs(sc, streams, config), JOB.params(sensor="st2", subintervals=[]), no_progress).summary
    assert only2["reference_sensor"] == "st2" and set(only2["sensors"]) == {"st2"}
    for r in (s, only2):
        assert np.all(np.abs(np.array(r["gyro_bias_rad_s"]) - sc.truth.gyro_bias0_rad_s)
                      <= 4 * np.array(r["gyro_bias_sigma_rad_s"]))


def test_params_are_validated() -> None:
    with pytest.raises(ValidationError):
        JOB.params(unknown=1)
    with pytest.raises(ValidationError):
        JOB.params(scheme=3)
    with pytest.raises(ValidationError):
        JOB.params(weights=(1.0, 0.0, 1.0))
    with pytest.raises(ValidationError):
        JOB.params(subintervals=[2, 0])
    assert JOB.params().weights == (1.0, 1.0, 0.2)
    assert JOB.name == "gyro_bias_fit" and JOB.streams == ("star_tracker", "gyro")


def test_bad_inputs_are_task_errors() -> None:
    sc = scenario(5)
    with pytest.raises(TaskError, match=r"star tracker 'st9' is not in the spacecraft configuration"):
        run(sc, sensor="st9")
    with pytest.raises(TaskError, match="no gyro samples in the job window"):
        JOB.run(inputs(sc, {"star_tracker": sc.streams["star_tracker"]}), JOB.params(), no_progress)
    g = {k: np.delete(v, np.s_[3000:3100]) for k, v in sc.streams["gyro"].items()}  # a 10 s gap
    with pytest.raises(TaskError, match=r"gyro gap of 10.1 s exceeds max_gyro_gap_s = 5.0 s"):
        JOB.run(inputs(sc, {**sc.streams, "gyro": g}), JOB.params(split_at_gyro_gaps=False), no_progress)
    result = JOB.run(inputs(sc, {**sc.streams, "gyro": g}), JOB.params(max_gyro_gap_s=20.0, subintervals=[]),
                     no_progress)
    assert any("gyro gaps" in n for n in result.notes)
    with pytest.raises(TaskError, match="no configured star tracker has data"):
        JOB.run(inputs(sc, config={"star_trackers": {"stX": {"q_BS": [1, 0, 0, 0]}}}), JOB.params(), no_progress)


def test_progress_is_reported() -> None:
    sc = scenario(5)
    seen: list[tuple[float, str]] = []
    JOB.run(inputs(sc), JOB.params(subintervals=[2]), lambda f, s: seen.append((f, s)))
    fractions = [f for f, _ in seen]
    assert fractions[0] == 0.0 and fractions[-1] == 1.0 and fractions == sorted(fractions)


def _with_star_tracker(sc: Scenario003, q: np.ndarray | None = None, shift_ns: int = 0) -> dict[str, Any]:
    st = dict(sc.streams["star_tracker"])
    if q is not None:
        st.update({f"q{i}": q[:, i].copy() for i in range(4)})
    st["time_tai_ns"] = st["time_tai_ns"] + shift_ns
    return {**sc.streams, "star_tracker": st}


def test_scalar_last_quaternions_are_named_and_not_converged() -> None:
    """The reviewer's case: (x, y, z, w) uploaded under q0..q3 headers. Gauss-Newton converges on nonsense (biases
    of tens of deg/h, residuals of hundreds of arcsec); the job says which convention fits and that it did not."""
    sc = scenario(7)
    st = sc.streams["star_tracker"]
    q = rot.quat_canonical(np.column_stack([st[f"q{i}"] for i in (1, 2, 3, 0)]))
    result = JOB.run(inputs(sc, _with_star_tracker(sc, q)), JOB.params(), no_progress)
    s = result.summary
    assert s["converged"] is False and s["quaternion_convention"] == "scalar_last"
    assert "likely cause" in s["status"] and "quaternion_convention" in s["status"]
    (w,) = [w for w in result.warnings if w.code == "quaternion_convention"]
    assert "qx, qy, qz, qw" in w.message and w.evidence["convention"] == "scalar_last"
    assert max(s["residual_rms_arcsec"]) > 100
    assert "implausible_input" not in {w.code for w in result.warnings}  # the cause is named


def test_time_offset_reported_and_corrected() -> None:
    sc = scenario(8)
    shifted = _with_star_tracker(sc, shift_ns=-400_000_000)  # tags 0.4 s early: true time = tag + 0.4 s
    plain = JOB.run(inputs(sc, shifted), JOB.params(subintervals=[]), no_progress)
    s = plain.summary
    assert abs(s["time_offset_s"] - 0.4) <= 3 * s["time_offset_sigma_s"] and s["time_offset_corrected_s"] is None
    (w,) = [w for w in plain.warnings if w.code == "time_offset"]
    assert "fit_time_offset" in w.message and w.evidence["time_offset_s"] == s["time_offset_s"]
    fixed = JOB.run(inputs(sc, shifted), JOB.params(subintervals=[], fit_time_offset=True), no_progress)
    f = fixed.summary
    assert f["time_offset_corrected_s"] == s["time_offset_s"]
    (wf,) = [w for w in fixed.warnings if w.code == "time_offset"]
    assert wf.evidence["corrected"] is True and "were corrected" in wf.message
    # the correction removes the offset's share of the residuals (the 0.4 Hz vibration seen 0.4 s late)
    assert np.all(np.array(f["residual_rms_arcsec"]) < np.array(s["residual_rms_arcsec"]))
    b, sig = np.array(f["gyro_bias_rad_s"]), np.array(f["gyro_bias_sigma_rad_s"])
    assert np.all(np.abs(b - sc.truth.gyro_bias0_rad_s) <= 4 * sig)


def test_drifting_offsets_inflate_the_sigma_and_warn() -> None:
    drift_G = tuple(np.array([1.0, -1.0, 0.5]) * 0.5 * RAD_PER_ARCSEC / 1200.0)  # 0.5"/s over the window
    sc = scenario(9, gyro_bias_drift_rad_s2=drift_G)
    result = run(sc)
    s = result.summary
    (w,) = [w for w in result.warnings if w.code == "bias_not_constant"]
    assert w.evidence["p_value"] < 1e-6 and w.evidence["dof"] == 9
    assert s["offset_constancy"]["constant"] is False
    sig, sig_c = np.array(s["gyro_bias_sigma_rad_s"]), np.array(s["gyro_bias_sigma_constant_rad_s"])
    assert np.all(sig >= sig_c) and np.max(sig / sig_c) > 3
    mean_bias = sc.truth.gyro_bias0_rad_s + np.array(drift_G) * 600.0  # the offset averaged over the window
    assert np.all(np.abs(np.array(s["gyro_bias_rad_s"]) - mean_bias) <= 3 * sig)
    np.testing.assert_allclose(np.sqrt(np.diag(s["covariance"])[3:6]) / RAD_PER_ARCSEC,
                               s["delta_sensor_sigma_arcsec_s"], rtol=1e-9)
