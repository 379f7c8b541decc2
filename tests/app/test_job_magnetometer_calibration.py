"""Job ``magnetometer_calibration`` on seed-004 output with injected magnetometer errors: summary, warnings,
figure and report section through the job function; a short arc (not observable, nulls, no calibration); the
calibration version through the API and its application by the runner to a later gyroless_ekf job."""

from __future__ import annotations

import json

import numpy as np
import pytest
from matplotlib.figure import Figure

from app.jobs.runner import apply_magnetometer_calibration
from app.jobs.types.magnetometer_calibration import JOB, Params, report_sections
from app.reports.sections import ReportContext
from processing.simulate.seed004 import orbit_period_s, simulate_seed004
from processing.spacecraft import Spacecraft
from processing.tasks import TaskError, TaskInputs, no_progress
from processing.time.timescales import iso_to_tai_ns
from tests.app.test_jobs_api import upload_columns, wait

T0 = int(iso_to_tai_ns(["2025-03-20T12:00:00"])[0])
DURATION_S = 3 * orbit_period_s()
SHORT_S = 2 * orbit_period_s()  # enough for the 9 parameters with this mounting
COUPLING = [[40.0, 0.0, 5.0], [0.0, -25.0, 0.0], [6.0, 0.0, 30.0]]


@pytest.fixture(scope="module")
def scenario():  # noqa: ANN201
    """Three orbits under the averaged LQR (its transient and desaturation give the dipole variation), the
    magnetometer mounted off the body axes, with bias, scale, non-orthogonality and magnetorquer coupling."""
    return simulate_seed004(start_tai_ns=T0, duration_s=DURATION_S, seed=2, controller="lqr", estimator="truth",
                            q_BM=(0.9238795, 0.3826834, 0.0, 0.0), magnetometer_bias_nT=(350.0, -250.0, 200.0),
                            magnetometer_scale_factor_errors=(0.02, -0.01, 0.015),
                            magnetometer_non_orthogonality_rad=(0.004, -0.002, 0.003),
                            magnetometer_coupling_nT_per_A_m2=COUPLING)


def _inputs(sc, streams=None, end_s: float = DURATION_S) -> TaskInputs:  # noqa: ANN001
    return TaskInputs(streams=sc.streams if streams is None else streams, spacecraft=Spacecraft.from_json(sc.config),
                      start_tai_ns=T0, end_tai_ns=T0 + int(end_s * 1e9))


@pytest.fixture(scope="module")
def result(scenario):  # noqa: ANN001, ANN201
    return JOB.run(_inputs(scenario), Params(estimate_coupling=True, magnetometer_noise_nT=100.0), no_progress)


def test_simulator_records_and_applies_the_injected_errors(scenario) -> None:  # noqa: ANN001
    e = scenario.truth.magnetometer_errors
    assert e is not None and np.allclose(e.coupling_nT_per_A_m2, COUPLING)
    m = scenario.streams["magnetometer"]
    b = np.column_stack([m["bx"], m["by"], m["bz"]])
    # B_meas - n = (I + D)(b_M - n) + b + C mu: the correction returns the ideal stream up to (I + D)^-1 n - n
    back = e.correct(b, scenario.truth.mu_B_A_m2)
    assert np.max(np.abs(back - scenario.truth.b_M_ideal_nT)) < 0.05 * 6 * 100.0
    clean = simulate_seed004(start_tai_ns=T0, duration_s=60.0, seed=2)
    assert clean.truth.magnetometer_errors is None
    assert np.array_equal(clean.streams["magnetometer"]["bx"], clean.truth.b_M_ideal_nT[:, 0])


def test_summary_recovers_the_injected_errors(scenario, result) -> None:  # noqa: ANN001
    s = result.summary
    json.dumps(s, allow_nan=False)
    e = scenario.truth.magnetometer_errors
    assert s["bias_observable"] == [True] * 3 and s["scale_factor_observable"] == [True] * 3
    assert s["non_orthogonality_observable"] == [True] * 3
    for key, sig, truth in (("bias_nT", "bias_sigma_nT", e.bias_nT),
                            ("scale_factor_errors", "scale_factor_sigma", e.scale_factor_errors),
                            ("non_orthogonality_rad", "non_orthogonality_sigma_rad", e.non_orthogonality_rad)):
        assert np.all(np.abs(np.array(s[key]) - truth) < 3 * np.array(s[sig])), key
    assert np.allclose(s["scale_factors"], 1 + np.array(s["scale_factor_errors"]))
    # coupling: every observable element within 3 sigma; the undetermined ones null
    C, Cs, Co = (np.array(s[k], dtype=float) for k in ("coupling_nT_per_A_m2", "coupling_sigma_nT_per_A_m2",
                                                         "coupling_observable"))
    Co = Co.astype(bool)
    assert np.all(np.abs(C[Co] - np.array(COUPLING)[Co]) < 3 * Cs[Co])
    assert np.all(np.isnan(C[~Co]))
    assert s["residual_field_rms_before_nT"] > 300 and 90 < s["residual_field_rms_after_nT"] < 110
    assert s["calibration"]["kind"] == "magnetometer" and s["calibration_complete"] == bool(Co.all())
    if not Co.all():
        assert [w.code for w in result.warnings] == ["not_observable"]
        assert "coupling" in result.warnings[0].message


def test_without_coupling_clean_result_and_calibration(scenario) -> None:  # noqa: ANN001
    """The 9 parameters on data without coupling: complete, no warning, a calibration that inverts the model."""
    sc = simulate_seed004(start_tai_ns=T0, duration_s=SHORT_S, seed=3, controller="lqr", estimator="truth",
                          q_BM=(0.9238795, 0.3826834, 0.0, 0.0), magnetometer_bias_nT=(350.0, -250.0, 200.0),
                          magnetometer_scale_factor_errors=(0.02, -0.01, 0.015))
    r = JOB.run(_inputs(sc, end_s=SHORT_S), Params(magnetometer_noise_nT=100.0), no_progress)
    s = r.summary
    assert r.warnings == [] and s["calibration_complete"] is True
    assert np.all(np.abs(np.array(s["non_orthogonality_rad"])) < 3 * np.array(s["non_orthogonality_sigma_rad"]))
    cal = s["calibration"]
    assert cal["coupling_nT_per_A_m2"] is None and np.allclose(cal["bias_nT"], s["bias_nT"])
    figs = JOB.figures(r, Params())
    assert isinstance(figs["field_residuals"], Figure)
    ctx = ReportContext(job_type=JOB.name, summary=s, params=Params(), config=sc.config, specifications=None)
    (section,) = report_sections(ctx)
    assert len(section.tables[0].rows) == 9 and "field_residuals" in section.figure_names
    # the runner's correction with this calibration brings |B| to the field model
    streams, notes = apply_magnetometer_calibration(dict(sc.streams), cal, None)
    m = streams["magnetometer"]
    assert "calibration version" in notes[0]
    b = np.column_stack([m["bx"], m["by"], m["bz"]])
    assert np.sqrt(np.mean((b - sc.truth.b_M_ideal_nT) ** 2)) < 10.0


def test_short_arc_is_not_observable(scenario) -> None:  # noqa: ANN001
    end_s = 600.0
    streams = {k: {c: v[:601] for c, v in cols.items()} for k, cols in scenario.streams.items()}
    r = JOB.run(_inputs(scenario, streams, end_s), Params(), no_progress)
    s = r.summary
    assert s["calibration_complete"] is False
    assert "not_observable" in [w.code for w in r.warnings]
    assert None in s["bias_nT"] + s["scale_factors"] + s["non_orthogonality_rad"]
    assert False in s["bias_observable"] + s["scale_factor_observable"] + s["non_orthogonality_observable"]
    assert "orbit" in next(w.message for w in r.warnings if w.code == "not_observable")


def test_input_errors(scenario) -> None:  # noqa: ANN001
    no_torquer = {k: v for k, v in scenario.streams.items() if k != "magnetorquer"}
    with pytest.raises(TaskError, match="magnetorquer"):
        JOB.run(_inputs(scenario, no_torquer), Params(estimate_coupling=True), no_progress)
    few = {k: {c: v[:20] for c, v in cols.items()} for k, cols in scenario.streams.items()}
    with pytest.raises(TaskError, match="at least 50"):
        JOB.run(_inputs(scenario, few), Params(), no_progress)


@pytest.mark.slow
def test_calibration_version_is_stored_and_applied_by_the_runner(client) -> None:  # noqa: ANN001
    sc = simulate_seed004(start_tai_ns=T0, duration_s=SHORT_S, seed=4, controller="lqr", estimator="truth",
                          q_BM=(0.9238795, 0.3826834, 0.0, 0.0), magnetometer_bias_nT=(350.0, -250.0, 200.0),
                          magnetometer_scale_factor_errors=(0.02, -0.01, 0.015))
    client.post("/api/v1/spacecraft", json={"name": "micro", "config": sc.config})
    for stream, columns in sc.streams.items():
        upload_columns(client, "micro", stream, columns)
    r = client.post("/api/v1/jobs", json={"type": "magnetometer_calibration", "spacecraft": "micro",
                                          "params": {"magnetometer_noise_nT": 100.0}})
    job = wait(client, r.json()["id"], timeout_s=120)
    assert job["status"] == "succeeded", job["error"]
    assert job["result"]["calibration_complete"] is True
    cals = client.get("/api/v1/spacecraft/micro/calibrations").json()
    assert [(c["kind"], c["version"], c["job_id"]) for c in cals] == [("magnetometer", 1, job["id"])]
    # a gyroless_ekf job over the last 10 minutes pins the version; the runner corrects its magnetometer data
    end = T0 + int(SHORT_S * 1e9)
    later = client.post("/api/v1/jobs", json={"type": "gyroless_ekf", "spacecraft": "micro", "time_scale": "tai",
                                              "start": (end - 600e9) / 1e9, "end": end / 1e9,
                                              "params": {"smoother": False}}).json()
    assert client.get(f"/api/v1/jobs/{later['id']}").json()["reference"] == {"calibration:magnetometer": cals[0]["id"]}
    done = wait(client, later["id"], timeout_s=240)
    assert done["status"] == "succeeded", done["error"]
    assert any("magnetometer data corrected with calibration version 1" in n for n in done["notes"]), done["notes"]


def test_runner_correction_with_coupling_uses_the_latest_dipole() -> None:
    """apply_magnetometer_calibration: the dipole of the latest magnetorquer sample at or before each sample;
    only the calibrated sensor is corrected; without a recent dipole the samples are dropped and it says so."""
    from processing.magnetometer.model import MagnetometerErrors

    e = MagnetometerErrors.from_components([100.0, -50.0, 20.0], [0.01, 0.0, -0.01], [0.002, 0.0, 0.0], COUPLING)
    rng = np.random.default_rng(1)
    t = np.arange(40, dtype=np.int64) * 1_000_000_000
    B_true = rng.normal(size=(40, 3)) * 3e4
    t_tq = t[::4] - 500_000_000  # a dipole every 4 s, half a second before a magnetometer sample
    mu = rng.normal(size=(t_tq.size, 3))
    held = mu[np.searchsorted(t_tq, t, side="right") - 1]
    H = e.measure(B_true, held)
    sensor = np.array(["mag1"] * 20 + ["mag2"] * 20, dtype=object)
    streams = {"magnetometer": {"time_tai_ns": t, "sensor": sensor, "bx": H[:, 0], "by": H[:, 1], "bz": H[:, 2]}}
    torquer = {"time_tai_ns": t_tq, "sensor": np.full(t_tq.size, "mtq", dtype=object), "mx": mu[:, 0], "my": mu[:, 1],
               "mz": mu[:, 2]}
    values = {"sensor": "mag1", "bias_nT": e.bias_nT.tolist(), "D": e.D.tolist(), "coupling_nT_per_A_m2": COUPLING}
    out, notes = apply_magnetometer_calibration(streams, values, torquer)
    m = out["magnetometer"]
    b = np.column_stack([m["bx"], m["by"], m["bz"]])
    assert np.allclose(b[:20], B_true[:20], rtol=0, atol=1e-6)  # mag1 corrected
    assert np.array_equal(b[20:], H[20:])  # mag2 untouched
    assert "coupling" in notes[0] and len(notes) == 1
    out, notes = apply_magnetometer_calibration(streams, values, None)
    assert len(out["magnetometer"]["time_tai_ns"]) == 20 and "dropped" in notes[1]
