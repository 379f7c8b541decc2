"""Job ``gyroless_ekf`` (paper 004) on simulator output: summary, tables, figures, errors."""

import json

import numpy as np
import pytest
from matplotlib.figure import Figure
from pydantic import ValidationError

from app.jobs.types.gyroless_ekf import JOB, Params
from processing.attitude.rotations import quat_to_dcm
from processing.gyroless.filtering import attitude_errors_rad
from processing.simulate.seed004 import simulate_seed004
from processing.spacecraft import Spacecraft
from processing.tasks import TaskError, TaskInputs, no_progress
from processing.time.timescales import iso_to_tai_ns

T0 = int(iso_to_tai_ns(["2025-03-20T12:00:00"])[0])
DURATION_S = 1800.0


@pytest.fixture(scope="module")
def scenario():  # noqa: ANN201
    return simulate_seed004(start_tai_ns=T0, duration_s=DURATION_S, seed=1, controller="energy", estimator="mekf",
                            initial_angles_deg=(5.0, -3.0, 10.0), sun_outage_s=600.0, sun_outage_center_u_deg=45.0)


def _inputs(sc, config=None, streams=None) -> TaskInputs:  # noqa: ANN001
    return TaskInputs(streams=streams if streams is not None else sc.streams,
                      spacecraft=Spacecraft.from_json(sc.config if config is None else config),
                      start_tai_ns=T0, end_tai_ns=T0 + int(DURATION_S * 1e9))


@pytest.fixture(scope="module")
def result(scenario):  # noqa: ANN001, ANN201
    return JOB.run(_inputs(scenario), Params(filter="ekf"), no_progress)


def test_summary_is_json_and_has_the_design_keys(result) -> None:  # noqa: ANN001
    s = result.summary
    json.dumps(s, allow_nan=False)
    for key in ("filter", "smoother", "converged", "time_to_converge_s", "nis_mean", "nis_mean_bounds_95",
                "whiteness", "innovation_rms_deg", "roll_deg", "pitch_deg", "yaw_deg", "attitude_sigma_deg",
                "sun_outages", "artifacts"):
        assert key in s
    assert s["filter"] == "ekf" and s["smoother"] is True and s["converged"] is True
    assert s["n_steps"] == int(DURATION_S) + 1
    assert s["nis_mean_bounds_95"][0] < s["nis_mean"] < 1.1 * s["nis_mean_bounds_95"][1]
    assert 0.05 < s["innovation_rms_deg"]["magnetometer"] < 1.0 and 0.3 < s["innovation_rms_deg"]["sun_sensor"] < 1.5
    assert len(s["sun_outages"]) == 1 and 580 < s["sun_outages"][0]["duration_s"] < 620
    assert s["whiteness"]["fraction_outside"] < 0.3
    assert set(s["roll_deg"]) == {"mean", "std", "min", "max"}


def test_attitude_table_against_truth(scenario, result) -> None:  # noqa: ANN001
    att = result.tables["attitude"]
    tr = scenario.truth
    i = np.searchsorted(tr.time_tai_ns, att["time_tai_ns"])
    assert np.array_equal(tr.time_tai_ns[i], att["time_tai_ns"])
    q = np.column_stack([att[f"q{k}"] for k in range(4)])
    assert np.all(q[:, 0] >= 0)
    err = np.degrees(attitude_errors_rad(q, tr.q_OB[i]))
    assert np.all(np.sqrt(np.mean(err**2, axis=0)) < 0.5)
    np.testing.assert_allclose(att["roll_deg"], np.degrees(tr.roll_rad[i]), atol=1.0)
    for col in ("sigma_x_deg", "w_bo_z_rad_s", "w_sigma_y_rad_s", "tau_d_x_N_m", "q_ib_0", "roll_filtered_deg"):
        assert att[col].shape == q[:, 0].shape and np.all(np.isfinite(att[col]))
    # q_IB = q_IO o q_OB: the body z axis (nadir in O for small angles) points roughly at the Earth
    q_ib = np.column_stack([att[f"q_ib_{k}"] for k in range(4)])
    z_I = quat_to_dcm(q_ib)[:, :, 2]
    nadir = -tr.r_I[i] / np.linalg.norm(tr.r_I[i], axis=1, keepdims=True)
    assert np.median(np.degrees(np.arccos(np.sum(z_I * nadir, axis=1)))) < 20
    inn = result.tables["innovations"]
    assert set(inn) == {"time_tai_ns", "nis", "nis_dof", "magnetometer_residual_deg", "sun_residual_deg"}
    assert np.isnan(inn["sun_residual_deg"]).sum() == int(round(600))


def test_figures(result) -> None:  # noqa: ANN001
    figs = JOB.figures(result, Params(filter="ekf"))
    assert set(figs) == {"attitude", "attitude_sigma", "rates", "consistency", "disturbance"}
    assert all(isinstance(f, Figure) for f in figs.values())


def test_mekf_without_smoother_and_without_magnetorquer(scenario) -> None:  # noqa: ANN001
    streams = {k: v for k, v in scenario.streams.items() if k != "magnetorquer"}
    r = JOB.run(_inputs(scenario, streams=streams), Params(smoother=False, torque_noise_N_m=2e-5), no_progress)
    assert r.summary["filter"] == "mekf" and r.summary["smoother"] is False
    assert any("no magnetorquer telemetry" in n for n in r.notes)
    assert "roll_filtered_deg" not in r.tables["attitude"]


def test_errors(scenario) -> None:  # noqa: ANN001
    cfg = {k: v for k, v in scenario.config.items() if k != "inertia_kg_m2"}
    with pytest.raises(TaskError, match="inertia_kg_m2"):
        JOB.run(_inputs(scenario, config=cfg), Params(), no_progress)
    with pytest.raises(ValidationError):
        Params(filter="ukf")
    with pytest.raises(ValidationError):
        Params(unknown=1)
    streams = dict(scenario.streams)
    mag = dict(streams["magnetometer"])
    mag["sensor"] = np.where(np.arange(mag["sensor"].size) % 2 == 0, "mag_a", "mag_b").astype(object)
    streams["magnetometer"] = mag
    with pytest.raises(TaskError, match="several magnetometer sensors"):
        JOB.run(_inputs(scenario, streams=streams), Params(), no_progress)
    streams = {k: v for k, v in scenario.streams.items() if k != "sun_sensor"}
    with pytest.raises(TaskError, match="no sun_sensor samples"):
        JOB.run(_inputs(scenario, streams=streams), Params(), no_progress)
    assert JOB.name == "gyroless_ekf" and JOB.streams == ("magnetometer", "sun_sensor", "gnss")


@pytest.mark.parametrize("sensor, name", [("magnetometer", "the magnetometer"), ("sun_sensor", "the sun sensor")])
def test_a_missing_mounting_is_an_error_naming_the_sensor(scenario, sensor, name) -> None:  # noqa: ANN001
    cfg = {k: v for k, v in scenario.config.items() if k != sensor}  # was: axes taken as body axes
    with pytest.raises(TaskError, match=f"{name} is not in the spacecraft configuration .*add {sensor}.q_B"):
        JOB.run(_inputs(scenario, config=cfg), Params(), no_progress)


def test_clean_data_raise_no_warning(result) -> None:  # noqa: ANN001
    assert result.warnings == [] and result.summary["consistency"]["consistent"] is True
    assert result.summary["magnetometer_bias"] is None and result.summary["field_error_O_nT"] is None
    assert result.summary["process_noise"]["torque_noise_N_m"] == pytest.approx(4e-6)


def _biased(scenario, bias_nT):  # noqa: ANN001, ANN202
    streams = dict(scenario.streams)
    mag = dict(streams["magnetometer"])
    for c, b in zip(("bx", "by", "bz"), bias_nT, strict=True):
        mag[c] = mag[c] * 1.02 + b
    streams["magnetometer"] = mag
    return streams


def test_an_uncalibrated_magnetometer_is_flagged(scenario) -> None:  # noqa: ANN001
    r = JOB.run(_inputs(scenario, streams=_biased(scenario, (300.0, -300.0, 300.0))), Params(), no_progress)
    s = r.summary
    assert s["converged"] is False and s["consistency"]["consistent"] is False
    (w,) = [w for w in r.warnings if w.code == "filter_inconsistent"]
    assert "estimate_magnetometer_bias" in w.message
    for key in ("nis_mean", "nis_bounds_99", "ljung_box_p", "max_abs_rho", "windows_failed"):
        assert key in w.evidence
    json.dumps(r.summary, allow_nan=False)


def test_bias_states_in_the_summary_and_tables(scenario) -> None:  # noqa: ANN001
    bias = (300.0, -200.0, 250.0)
    streams = dict(scenario.streams)
    mag = dict(streams["magnetometer"])
    for c, b in zip(("bx", "by", "bz"), bias, strict=True):
        mag[c] = mag[c] + b
    streams["magnetometer"] = mag
    r = JOB.run(_inputs(scenario, streams=streams), Params(estimate_magnetometer_bias=True), no_progress)
    b = r.summary["magnetometer_bias"]
    assert b["axes"] == ["x_B", "y_B", "z_B"] and len(b["observable"]) == 3
    for v, sig, obs, truth in zip(b["value_B_nT"], b["sigma_B_nT"], b["observable"], bias, strict=True):
        assert (v is None) == (not obs)  # q_BM is the identity here: B = M
        if obs:
            assert abs(v - truth) < 4 * sig
    assert ("not_observable" in {w.code for w in r.warnings}) == (not all(b["observable"]))
    assert r.summary["process_noise"]["torque_noise_N_m"] == pytest.approx(1e-5)  # the default with the states
    assert "mag_bias_x_nT" in r.tables["attitude"] and "mag_bias_z_sigma_nT" in r.tables["attitude"]
    json.dumps(r.summary, allow_nan=False)
