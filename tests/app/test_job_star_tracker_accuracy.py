"""Job ``star_tracker_accuracy`` (003 §1.3-1.5) on seed-003 simulator output: keys, types, figures, errors."""

from __future__ import annotations

import io
import json
from typing import Any

import numpy as np
import pytest
from matplotlib.figure import Figure
from pydantic import ValidationError

from app.jobs.types.star_tracker_accuracy import JOB
from processing.simulate.seed003 import Scenario003, simulate_seed003
from processing.spacecraft import Spacecraft
from processing.tasks import TaskError, TaskInputs, TaskResult, no_progress
from tests.app.helpers import assert_json_plain

T0_NS = 1_900_000_000 * 1_000_000_000
NS = 1_000_000_000


def scenario(seed: int = 4, **kwargs: Any) -> Scenario003:
    return simulate_seed003(start_tai_ns=T0_NS, seed=seed, gnss_period_s=1200.0, **kwargs)


def inputs(sc: Scenario003, streams: dict[str, Any] | None = None, config: dict[str, Any] | None = None) -> TaskInputs:
    return TaskInputs(
        streams=sc.streams if streams is None else streams,
        spacecraft=Spacecraft.from_json(sc.config if config is None else config),
        start_tai_ns=T0_NS,
        end_tai_ns=T0_NS + 1200 * NS,
    )


@pytest.fixture(scope="module")
def default_result() -> tuple[Scenario003, TaskResult]:
    sc = scenario()
    return sc, JOB.run(inputs(sc), JOB.params(), no_progress)


def test_job_declaration():
    assert JOB.name == "star_tracker_accuracy" and JOB.paper == "003 §1"
    assert JOB.streams == ("star_tracker",) and JOB.optional_streams == ("gyro",)
    p = JOB.params()
    assert (p.sensor, p.harmonics, p.use_gyro) == (None, "auto", True)
    assert JOB.params(harmonics=40).harmonics == 40
    for bad in ({"harmonics": -1}, {"harmonics": "many"}, {"colour": "red"}, {"use_gyro": "perhaps"}):
        with pytest.raises(ValidationError):
            JOB.params(**bad)


def test_summary_keys_types_and_values(default_result):
    sc, result = default_result
    s = result.summary
    assert_json_plain(s)
    json.dumps(s, allow_nan=False)
    for key in ("sigma_arcsec", "sigma_smoothing_arcsec", "sigma_robust_arcsec", "sigma_smoothing_robust_arcsec",
                "sigma_eq2_arcsec", "motion_rms_arcsec", "gyro_rate_rms_diff_arcsec_s",
                "gyro_rate_rms_diff_expected_arcsec_s", "gyro_offset_arcsec_s", "gyro_noise_sigma_arcsec_s",
                "gyro_smoothing_sigma_arcsec_s"):
        assert isinstance(s[key], list) and len(s[key]) == 3 and all(isinstance(v, float) for v in s[key]), key
    assert s["sensor"] == "st1" and s["gyro_used"] is True and s["harmonics_mode"] == "auto"
    assert isinstance(s["harmonics"], int) and s["harmonics_per_segment"] == [s["harmonics"]]
    assert s["n_samples"] == sc.streams["star_tracker"]["time_tai_ns"].size and s["n_segments"] == 1
    np.testing.assert_allclose(s["sigma_arcsec"], [2.5, 5.0, 15.0], rtol=0.12)
    assert all(a < b for a, b in zip(s["sigma_arcsec"][:2], s["sigma_smoothing_arcsec"][:2], strict=True))
    lines = s["spectral_lines"]
    assert {k for line in lines for k in line} == {"source", "axis", "freq_hz", "amplitude_arcsec_s",
                                                 "attitude_amplitude_arcsec", "attitude_rms_arcsec",
                                                 "aliased_freq_hz", "removed"}
    gyro = [line for line in lines if line["source"] == "gyro"]
    assert [line["axis"] for line in gyro] == ["y1", "y2", "y3"]
    for line in gyro:
        assert line["freq_hz"] == pytest.approx(0.4, abs=1e-4)
        assert line["aliased_freq_hz"] == pytest.approx(1 / 15, abs=1e-4)
        assert line["amplitude_arcsec_s"] == pytest.approx(3.0 * 2 * np.pi * 0.4, rel=0.1)  # 3" at 0.4 Hz
    assert all(line["amplitude_arcsec_s"] is None for line in lines if line["source"] == "star_tracker")


def test_tables(default_result):
    sc, result = default_result
    n = sc.streams["star_tracker"]["time_tai_ns"].size
    t = result.tables
    assert {"residuals", "rates", "gyro_comparison", "segments", "spectrum_gyro", "spectrum_star_tracker_rate",
            "spectrum_star_tracker_residuals"} <= set(t)
    for name, cols in t.items():
        lengths = {np.asarray(v).shape for v in cols.values()}
        assert len(lengths) == 1 and len(next(iter(lengths))) == 1, name
    res = t["residuals"]
    assert res["time_tai_ns"].dtype == np.int64 and res["time_tai_ns"].size == n
    for i in (1, 2, 3):
        std = np.sqrt(np.mean(res[f"e{i}_corrected_arcsec"] ** 2))
        assert std < result.summary["sigma_arcsec"][i - 1]  # dof-corrected sigma is above the plain rms
    assert set(t["rates"]) == {"time_tai_ns", *(f"w{i}_{f}_arcsec_s" for f in "BS" for i in (1, 2, 3))}
    assert 4.99 < t["spectrum_gyro"]["freq_hz"][-1] <= 5.0  # up to the gyro Nyquist frequency


def test_figures_draw(default_result):
    _, result = default_result
    figs = JOB.figures(result, JOB.params())
    assert set(figs) == {"rodrigues_fit", "residuals", "rates", "spectra", "residual_spectra"}
    for fig in figs.values():
        assert isinstance(fig, Figure) and fig.get_label()
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=40)
        assert buf.getvalue()[:4] == b"\x89PNG"


def test_without_gyro_and_with_manual_harmonics():
    sc = scenario(seed=5, duration_s=600.0)
    streams = {"star_tracker": sc.streams["star_tracker"]}
    result = JOB.run(inputs(sc, streams=streams), JOB.params(harmonics=30), no_progress)
    s = result.summary
    assert s["harmonics"] == 30 and s["harmonics_mode"] == "manual" and s["gyro_used"] is False
    assert "gyro_rate_rms_diff_arcsec_s" not in s and "gyro_comparison" not in result.tables
    assert s["sigma_arcsec"] == s["sigma_smoothing_arcsec"]
    assert any("no gyro" in note for note in result.notes)
    assert set(JOB.figures(result, JOB.params(harmonics=30))) >= {"rates", "spectra"}
    off = JOB.run(inputs(sc), JOB.params(harmonics=30, use_gyro=False), no_progress)
    assert off.summary["gyro_used"] is False and any("use_gyro" in note for note in off.notes)


def test_sensor_choice_and_errors():
    sc = scenario(seed=6, duration_s=300.0)
    st = sc.streams["star_tracker"]
    two = {k: np.concatenate([v, v]) for k, v in st.items()}
    two["sensor"] = np.array(["st1"] * st["sensor"].size + ["st2"] * st["sensor"].size, dtype=object)
    config = {**sc.config, "star_trackers": {"st1": sc.config["star_trackers"]["st1"],
                                             "st2": {"q_BS": [1.0, 0.0, 0.0, 0.0]}}}
    with pytest.raises(TaskError, match="ambiguous"):
        JOB.run(inputs(sc, streams={"star_tracker": two}, config=config), JOB.params(), no_progress)
    chosen = JOB.run(inputs(sc, streams={"star_tracker": two}, config=config), JOB.params(sensor="st2"),
                     no_progress)
    assert chosen.summary["sensor"] == "st2"
    with pytest.raises(TaskError,
                       match=r"star tracker 'st9' is not in the spacecraft configuration \(configured: st1\)"):
        JOB.run(inputs(sc), JOB.params(sensor="st9"), no_progress)
    with pytest.raises(TaskError, match="no star_tracker samples of sensor 'st1'"):
        JOB.run(inputs(sc, streams={"star_tracker": {**two, "sensor": np.full(two["sensor"].size, "st2", object)}},
                       config={**sc.config}), JOB.params(), no_progress)
    short = {k: v[:8] for k, v in st.items()}
    with pytest.raises(TaskError, match="at least 12"):
        JOB.run(inputs(sc, streams={"star_tracker": short}), JOB.params(), no_progress)
    with pytest.raises(TaskError, match="harmonics must be <= N - 2"):
        JOB.run(inputs(sc, streams={"star_tracker": st}), JOB.params(harmonics=500), no_progress)


def test_robustness_keys_and_no_warning_on_clean_data(default_result):
    _, result = default_result
    s = result.summary
    assert result.warnings == []
    assert s["n_outliers"] == 0 and s["outliers"] == [] and result.tables["outliers"]["time_tai_ns"].size == 0
    assert s["residuals_white"] is True and all(0.0 < p <= 1.0 for p in s["whiteness_p_value"])
    for key in ("sigma_above_cutoff_arcsec", "sigma_lower_bound_arcsec", "sigma_dof", "whiteness_power_ratio",
                "outlier_scale_arcsec"):
        assert isinstance(s[key], list) and len(s[key]) == 3 and all(isinstance(v, float) for v in s[key]), key
    for (lo, hi), sig in zip(s["sigma_ci95_arcsec"], s["sigma_arcsec"], strict=True):
        assert lo < sig < hi
    assert [(line["removed"], line["gyro_only"]) for line in s["gyro_lines"]] == [(True, False)]
    assert s["plausibility"]["st1"]["checked"] is True


def test_outliers_and_a_gyro_only_line_are_reported():
    sc = scenario(seed=2, st_outlier_fraction=0.01, gyro_line_amplitude_rad_s=(10 / 206264.806,) * 3)
    result = JOB.run(inputs(sc), JOB.params(), no_progress)
    s = result.summary
    assert_json_plain(s)
    json.dumps(s, allow_nan=False)
    n_true = int(sc.truth.st_outlier_mask.sum())
    assert s["n_outliers"] == n_true and len(s["outliers"]) == min(n_true, 5)
    table = result.tables["outliers"]
    assert set(table) == {"time_tai_ns", "e1_arcsec", "e2_arcsec", "e3_arcsec", "size_arcsec"}
    np.testing.assert_array_equal(table["time_tai_ns"], sc.truth.st_time_tai_ns[sc.truth.st_outlier_mask])
    np.testing.assert_allclose(table["size_arcsec"], 300.0, atol=40.0)
    np.testing.assert_allclose(s["sigma_arcsec"], [2.5, 5.0, 15.0], rtol=0.12)
    codes = [w.code for w in result.warnings]
    assert "outliers_removed" in codes and "implausible_input" in codes
    gyro_only = [w for w in result.warnings if w.code == "implausible_input" and "gyro only" in w.message]
    assert len(gyro_only) == 1 and gyro_only[0].evidence["freq_hz"] == pytest.approx(0.25, abs=1e-3)
    assert {(round(x["freq_hz"], 2), x["removed"]) for x in s["gyro_lines"]} == {(0.25, False), (0.4, True)}


def test_gauss_markov_noise_raises_correlated_residuals():
    sc = scenario(seed=3, duration_s=900.0, st_noise_tau_s=30.0)
    result = JOB.run(inputs(sc, streams={"star_tracker": sc.streams["star_tracker"]}), JOB.params(), no_progress)
    s = result.summary
    assert s["residuals_white"] is False and "plausibility" not in s
    (w,) = [w for w in result.warnings if w.code == "correlated_residuals"]
    assert "lower bound" in w.message
    assert all(lb >= sig for lb, sig in zip(s["sigma_lower_bound_arcsec"], s["sigma_arcsec"], strict=True))
    assert s["sigma_arcsec"][2] < 0.5 * 15.0  # the failure the warning is about: the harmonics absorb the noise


def test_figures_draw_with_outliers():
    sc = scenario(seed=5, duration_s=600.0, st_outlier_fraction=0.02)
    result = JOB.run(inputs(sc, streams={"star_tracker": sc.streams["star_tracker"]}), JOB.params(), no_progress)
    assert result.summary["n_outliers"] > 0
    fig = JOB.figures(result, JOB.params())["residuals"]
    top = fig.axes[0]
    assert max(abs(v) for v in top.get_ylim()) < 100.0  # the 300" outliers do not set the scale
    assert any("outliers" in (line.get_label() or "") for line in top.get_lines())


def test_scalar_last_upload_is_named_by_the_plausibility_check():
    sc = scenario(seed=7, duration_s=600.0)
    st = dict(sc.streams["star_tracker"])
    st["q0"], st["q1"], st["q2"], st["q3"] = st["q1"], st["q2"], st["q3"], st["q0"]  # (x, y, z, w) under q0..q3
    result = JOB.run(inputs(sc, streams={**sc.streams, "star_tracker": st}), JOB.params(), no_progress)
    assert result.summary["plausibility"]["st1"]["convention"] == "scalar_last"
    assert "quaternion_convention" in [w.code for w in result.warnings]


def test_multi_head_mode_on_two_heads():
    from processing.simulate.definitive import default_heads, simulate_definitive

    sc = simulate_definitive(start_tai_ns=1_700_000_000 * 10**9, duration_s=1800.0, seed=3, heads=default_heads(2),
                             motion="earth")
    t = sc.streams["star_tracker"]["time_tai_ns"]
    inputs = TaskInputs(streams=sc.streams, spacecraft=Spacecraft.from_json(sc.config), start_tai_ns=int(t.min()),
                        end_tai_ns=int(t.max()))
    res = JOB.run(inputs, JOB.params(heads=["all"], identical_heads=True), no_progress)
    assert_json_plain(res.summary)
    mh = res.summary["multi_head"]
    truth = np.array(sc.truth.heads["st1"].sigma_rad) * 206264.806
    for h in ("st1", "st2"):
        got = mh["heads"][h]
        assert got["observable"] == [True] * 3
        assert np.all(np.abs(np.array(got["sigma_arcsec"]) - truth) < 3 * np.array(got["sigma_sigma_arcsec"]))
    err = np.linalg.norm(np.array(sc.truth.heads["st2"].mounting_error_rad)) * 206264.806
    assert abs(np.linalg.norm(mh["pairs"][0]["relative_mounting_error_arcsec"]) - err) < 3.0
    assert "inter_head" in res.tables and "inter_boresight_angle" in JOB.figures(res, JOB.params())
    assert not {"not_observable", "implausible_input"} & {w.code for w in res.warnings}
    alone = JOB.run(inputs, JOB.params(heads=["all"]), no_progress)  # two heads, no assumption: ranges, no values
    assert alone.summary["multi_head"]["heads"]["st1"]["sigma_arcsec"] == [None] * 3
    assert "not_observable" in {w.code for w in alone.warnings}
    with pytest.raises(TaskError, match="at least two heads"):
        JOB.run(inputs, JOB.params(heads=["st1"]), no_progress)
    with pytest.raises(TaskError, match="no star_tracker samples"):
        JOB.run(inputs, JOB.params(heads=["st1", "st9"]), no_progress)


def test_the_gyro_is_not_read_with_use_gyro_false():
    from app.jobs.runner import stream_names

    assert stream_names(JOB, JOB.params(use_gyro=False)) == ("star_tracker",)
    assert stream_names(JOB, JOB.params()) == stream_names(JOB) == ("star_tracker", "gyro")
