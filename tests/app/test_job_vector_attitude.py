"""Job vector_attitude: JOB.run on the seed-002 simulator output, attitude table against the truth."""

from __future__ import annotations

import json
from functools import cache

import numpy as np
import pytest
from pydantic import ValidationError

from app.config_schema import SpacecraftConfig
from app.jobs.outputs import jsonable
from app.jobs.types.vector_attitude import JOB, Params
from processing.attitude import rotations
from processing.formats.rinex_nav import parse_rinex_nav_reference
from processing.simulate.seed002 import simulate_seed002
from processing.spacecraft import Spacecraft
from processing.tasks import ReferenceData, TaskError, TaskInputs, no_progress
from tests.real_data import GNSS_NAV

NAV = GNSS_NAV / "brdc2800.15n"


@cache
def nav_reference() -> ReferenceData:
    parsed = parse_rinex_nav_reference(NAV.read_bytes())
    return ReferenceData("nav1", "brdc2800.15n", parsed.columns, parsed.details)


@cache
def scenario():
    return simulate_seed002(nav=nav_reference().columns, seed=11, duration_s=1800.0)


def _inputs(streams=None, with_nav: bool = True) -> TaskInputs:
    sc = scenario()
    t = sc.truth.time_tai_ns
    return TaskInputs(streams=sc.streams if streams is None else streams, spacecraft=Spacecraft.from_json(sc.config),
                      start_tai_ns=int(t[0]), end_tai_ns=int(t[-1]),
                      reference={"rinex_nav": nav_reference()} if with_nav else {})


def test_run_on_the_scenario() -> None:
    sc = scenario()
    params = Params(field_model_error_nT=0.0, current_noise_a=0.01, current_model_error_a=0.0)
    result = JOB.run(_inputs(), params, no_progress)
    s = result.summary
    json.dumps(jsonable(s), allow_nan=False)
    assert set(s["methods_used"]) <= {"q_method", "loosely_coupled", "none"}
    assert s["methods_used"]["q_method"] > 500 and s["methods_used"]["loosely_coupled"] > 300
    assert s["availability"] > 0.98 and s["n_epochs"] == sc.truth.time_tai_ns.size
    assert s["residuals"]["magnetometer"]["rms_deg"] < 0.1 and s["residuals"]["sun"]["rms_deg"] < 1.5
    n_faults = int(sc.truth.faults["magnetometer"].sum())
    assert n_faults <= s["rejected_samples"]["magnetometer"] <= n_faults + 0.01 * s["n_epochs"]
    tab = result.tables["attitude"]
    q = np.stack([tab[f"q{i}"] for i in range(4)], axis=1)
    three = tab["method"] == "q_method"
    err = np.degrees(rotations.angle_between(q[three], sc.truth.q_OB[three]))
    assert np.median(err) < 1.0
    assert np.mean(err <= tab["bound99_deg"][three]) > 0.97
    # the angles are 002's (matrix (3) of q_OB's conjugate)
    dcm_BO = rotations.quat_to_dcm(rotations.quat_conjugate(q[three]))
    np.testing.assert_allclose(rotations.dcm_from_angles_002(*(np.deg2rad(tab[k][three]) for k in (
        "pitch_deg", "yaw_deg", "roll_deg"))), dcm_BO, atol=1e-9)
    assert set(JOB.figures(result, params)) == {"attitude", "residuals"}
    SpacecraftConfig.model_validate(sc.config)  # the simulator's configuration is a valid upload


def test_methods_and_missing_data() -> None:
    sc = scenario()
    r = JOB.run(_inputs(), Params(method="esoq2", screen=False), no_progress)
    assert set(r.summary["methods_used"]) <= {"esoq2", "none"} and r.summary["rejected_samples"] == {}
    r = JOB.run(_inputs(with_nav=False), Params(), no_progress)
    assert "no rinex_nav reference data" in r.notes[0] and r.summary["vectors_available"]["antenna"] == 0
    no_mag = {k: v for k, v in sc.streams.items() if k != "magnetometer"}
    r = JOB.run(_inputs(streams=no_mag), Params(method="loosely_coupled"), no_progress)
    assert r.summary["methods_used"] == {"none": sc.truth.time_tai_ns.size}
    assert r.summary["n_attitude"] == 0 and "magnetometer: no magnetometer stream" in r.tables["attitude"]["reason"][0]
    with pytest.raises(TaskError, match="needs the GNSS stream"):
        JOB.run(_inputs(streams={k: v for k, v in sc.streams.items() if k != "gnss"}), Params(), no_progress)
    weights = Params(weights={"antenna": 1.0, "magnetometer": 100.0, "sun": 10.0})
    r = JOB.run(_inputs(), weights, no_progress)
    assert r.summary["n_attitude"] > 0
    with pytest.raises(ValidationError):
        Params(method="triad")
    with pytest.raises(ValidationError):
        Params(weights={"gyro": 1.0})
