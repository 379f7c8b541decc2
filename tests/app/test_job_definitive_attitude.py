"""Jobs ``definitive_attitude`` and ``gyro_noise`` on simulator output: summaries (DESIGN.md keys, null for
undetermined states), warnings, tables, the AEM, figures and report sections, the registry."""

from __future__ import annotations

import json

import numpy as np
import pytest
from matplotlib.figure import Figure

from app.jobs.registry import registry
from app.jobs.types.definitive_attitude import AEM_FILE
from app.jobs.types.definitive_attitude import JOB as DEFINITIVE
from app.jobs.types.definitive_attitude import Params as DParams
from app.jobs.types.gyro_noise import JOB as NOISE
from app.jobs.types.gyro_noise import Params as NParams
from app.reports.sections import ReportContext, ReportSection
from processing.formats.ccsds_adm import parse_aem
from processing.simulate.definitive import default_heads, gyro_noise_rates, simulate_definitive
from processing.simulate.seed003 import simulate_seed003
from processing.spacecraft import Spacecraft
from processing.tasks import TaskError, TaskInputs, no_progress
from processing.units import RAD_PER_DEG

T0 = 1_700_000_000 * 10**9


def _inputs(sc) -> TaskInputs:  # noqa: ANN001
    t = [c["time_tai_ns"] for c in sc.streams.values()]
    return TaskInputs(streams=sc.streams, spacecraft=Spacecraft.from_json(sc.config),
                      start_tai_ns=int(min(x[0] for x in t)), end_tai_ns=int(max(x[-1] for x in t)))


@pytest.fixture(scope="module")
def two_heads():  # noqa: ANN201
    sc = simulate_definitive(start_tai_ns=T0, duration_s=600.0, seed=4, heads=default_heads(2),
                             scale_factor=(2e-4, -1e-4, 1e-4), time_offset_s=0.01)
    res = DEFINITIVE.run(_inputs(sc), DParams(estimate_scale_factors=True, estimate_head_mounting=True,
                                              estimate_time_offset=True), no_progress)
    return sc, res


def test_registered() -> None:
    jobs = registry()
    assert "definitive_attitude" in jobs and "gyro_noise" in jobs


def test_summary_keys_and_values(two_heads) -> None:  # noqa: ANN001
    sc, res = two_heads
    s = res.summary
    json.dumps(s, allow_nan=False)
    for key in ("attitude_sigma_arcsec", "gyro_bias_rad_s", "gyro_bias_sigma_rad_s", "gyro_bias_observable",
                "calibration", "observability", "nis", "nees", "whiteness", "sensors", "artifacts"):
        assert key in s
    cal = s["calibration"]
    assert cal["scale_factor_observable"] == [True, True, True]
    z = (np.array(cal["scale_factor"]) - [2e-4, -1e-4, 1e-4]) / np.array(cal["scale_factor_sigma"])
    assert np.all(np.abs(z) < 4)
    assert abs(cal["time_offset_s"] - 0.01) < 4 * cal["time_offset_sigma_s"]
    mount = cal["head_mountings"]["st2"]
    err = np.array(sc.truth.heads["st2"].mounting_error_rad)
    assert np.all(np.abs(np.array(mount["correction_rad"]) - err) < 4 * np.array(mount["sigma_rad"]))
    assert set(s["sensors"]) == {"st1", "st2"}
    assert s["nis"]["dof"] == 6.0
    codes = {w.code for w in res.warnings}
    assert "time_offset" in codes and "filter_inconsistent" not in codes and "not_observable" not in codes


def test_heads_checked_against_the_gyro(two_heads) -> None:  # noqa: ANN001
    _, res = two_heads
    p = res.summary["plausibility"]
    assert set(p) == {"st1", "st2"}
    assert all(p[h]["checked"] and p[h]["convention"] == "as_given" for h in p)
    assert not {"quaternion_convention", "implausible_input"} & {w.code for w in res.warnings}
    # the filter estimates the time offset itself: the check's own time_offset warning is not repeated
    assert [w.code for w in res.warnings].count("time_offset") == 1


def test_a_conjugated_head_is_named() -> None:
    sc = simulate_definitive(start_tai_ns=T0, duration_s=600.0, seed=5, heads=default_heads(2))
    st = sc.streams["star_tracker"]
    bad = st["sensor"] == "st2"
    for c in ("q1", "q2", "q3"):
        st[c] = np.where(bad, -st[c], st[c])
    res = DEFINITIVE.run(_inputs(sc), DParams(), no_progress)
    p = res.summary["plausibility"]
    assert p["st1"]["convention"] == "as_given" and p["st2"]["convention"] != "as_given"
    conv = [w for w in res.warnings if w.code == "quaternion_convention"]
    assert len(conv) == 1 and "st2" in conv[0].message


def test_tables_aem_figures_and_sections(two_heads) -> None:  # noqa: ANN001
    sc, res = two_heads
    att = res.tables["attitude"]
    assert att["time_tai_ns"].size == res.summary["n_epochs"]
    aem = parse_aem(res.files[AEM_FILE][0].decode())
    seg = aem.segments[0]
    assert seg.ref_frame_b == "SC_BODY_1"
    np.testing.assert_array_equal(seg.time_tai_ns, att["time_tai_ns"])
    q = np.stack([att[f"q{i}"] for i in range(4)], axis=1)
    assert np.max(np.abs(np.abs(np.sum(seg.q_AB * q, axis=1)) - 1)) < 1e-12
    figs = DEFINITIVE.figures(res, DParams())
    assert set(figs) == {"attitude_sigma", "gyro_bias", "residuals", "consistency"}
    assert all(isinstance(f, Figure) for f in figs.values())
    ctx = ReportContext(job_type="definitive_attitude", summary=res.summary, params=DParams(), config=sc.config,
                        specifications=None)
    sections = DEFINITIVE.report_sections(ctx)
    assert sections and all(isinstance(x, ReportSection) for x in sections)


def test_undetermined_states_are_null_with_a_warning() -> None:
    sc = simulate_definitive(start_tai_ns=T0, duration_s=600.0, seed=6, motion="earth", heads=default_heads(1))
    res = DEFINITIVE.run(_inputs(sc), DParams(estimate_scale_factors=True), no_progress)
    cal = res.summary["calibration"]
    assert False in cal["scale_factor_observable"]
    for v, ok in zip(cal["scale_factor"], cal["scale_factor_observable"], strict=True):
        assert (v is None) == (not ok)
    assert "not_observable" in {w.code for w in res.warnings}


def test_003_comparison_in_the_report() -> None:
    sc = simulate_seed003(start_tai_ns=T0, duration_s=600.0, seed=0)
    res = DEFINITIVE.run(_inputs(sc), DParams(compare_with=["gyro_bias_fit", "alignment_calibration"]), no_progress)
    cmp = res.summary["comparison"]
    assert cmp["gyro_bias_fit"]["available"] is True
    for row in cmp["gyro_bias_fit"]["rows"]:
        assert abs(row["difference_over_combined_sigma"]) < 3
    ctx = ReportContext(job_type="definitive_attitude", summary=res.summary, params=DParams(), config=sc.config,
                        specifications=None)
    titles = [x.title for x in DEFINITIVE.report_sections(ctx)]
    assert any("gyro_bias_fit" in t for t in titles) and any("alignment_calibration" in t for t in titles)


def test_gyro_noise_rates_quiet_arc() -> None:
    n, period = 72_000, 0.1
    arw = 0.05 * RAD_PER_DEG / 60
    w = gyro_noise_rates(n, period, arw_rad_sqrt_s=arw, seed=2) + np.array([1e-4, -2e-4, 5e-5])
    t = T0 + np.arange(n, dtype=np.int64) * 100_000_000
    sc = type("S", (), {"streams": {"gyro": {"time_tai_ns": t, "wx": w[:, 0], "wy": w[:, 1], "wz": w[:, 2],
                                             "sensor": np.full(n, "gyro", dtype=object)}},
                        "config": {"gyro": {"q_BG": [1, 0, 0, 0]}}})()
    res = NOISE.run(_inputs(sc), NParams(), no_progress)
    s = res.summary
    json.dumps(s, allow_nan=False)
    for lo_hi in s["angle_random_walk_ci95_rad_sqrt_s"]:
        assert lo_hi[0] <= arw <= lo_hi[1]
    assert s["rate_random_walk_observable"] == [False, False, False]
    assert s["rate_random_walk_rad_s_sqrt_s"] == [None] * 3
    assert "not_observable" in {w.code for w in res.warnings}
    assert set(NOISE.figures(res, NParams())) == {"allan_deviation"}


def test_gyro_noise_residual_against_star_tracker() -> None:
    sc = simulate_definitive(start_tai_ns=T0, duration_s=3600.0, seed=9, heads=default_heads(1), motion="earth",
                             arw_rad_sqrt_s=2e-5, bias_random_walk_rad_s_sqrt_s=0.0)
    res = NOISE.run(_inputs(sc), NParams(source="residual"), no_progress)
    s = res.summary
    assert s["data"] == "angles" and s["reference_sensor"] == "st1"
    for lo_hi in s["angle_random_walk_ci95_rad_sqrt_s"]:
        assert lo_hi[0] <= 2e-5 <= lo_hi[1]


def test_errors() -> None:
    sc = simulate_definitive(start_tai_ns=T0, duration_s=60.0, seed=1, heads=default_heads(1))
    with pytest.raises(TaskError):
        DEFINITIVE.run(_inputs(sc), DParams(sensors=["nope"]), no_progress)
    with pytest.raises(ValueError):
        DParams(unknown=1)  # type: ignore[call-arg]
