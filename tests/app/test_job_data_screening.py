"""Job data_screening: JOB.run on the seed-002 simulator output, summary, flags table, figures."""

from __future__ import annotations

import json
from functools import cache

import numpy as np
import pytest
from matplotlib.figure import Figure
from pydantic import ValidationError

from app.jobs.outputs import jsonable
from app.jobs.types.data_screening import JOB, Params, _rejected_by
from processing.formats.rinex_nav import parse_rinex_nav_reference
from processing.screening.flags import filter_streams
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
    return simulate_seed002(nav=nav_reference().columns, seed=7, duration_s=2400.0)


def _inputs(streams=None, reference=None) -> TaskInputs:
    sc = scenario()
    t = sc.truth.time_tai_ns
    return TaskInputs(streams=sc.streams if streams is None else streams, spacecraft=Spacecraft.from_json(sc.config),
                      start_tai_ns=int(t[0]), end_tai_ns=int(t[-1]),
                      reference={"rinex_nav": nav_reference()} if reference is None else reference)


def test_run_on_the_scenario() -> None:
    sc = scenario()
    result = JOB.run(_inputs(), Params(), no_progress)
    s = result.summary
    json.dumps(jsonable(s), allow_nan=False)
    assert set(s["streams"]) == {"gnss", "magnetometer", "panel_currents", "gnss_visibility"}
    e = s["streams"]["gnss"]["energy"]
    assert e["source"] == "002 eq. 15" and e["n_total"] == sc.truth.time_tai_ns.size and e["threshold"] > 0
    assert s["streams"]["magnetometer"]["field_magnitude"]["threshold"] == 750.0
    assert s["streams"]["gnss_visibility"]["visibility_occulted"]["n_rejected"] == 0
    assert s["energy_reference"].startswith("robust") and s["navigation_data"] == "brdc2800.15n"
    flags = result.tables["flags"]
    n_faults = sum(int(f.sum()) for f in sc.truth.faults.values())
    assert s["n_rejected"] == int((~flags["accepted"]).sum()) >= n_faults
    # every injected fault is rejected with its reasons
    for stream, truth in sc.truth.faults.items():
        sel = np.asarray(flags["stream"]) == stream
        assert np.all(~flags["accepted"][sel][truth])
        assert np.all(flags["reasons"][sel][truth] != "")
    # later jobs with screened = true: the runner drops the rejected rows
    kept = filter_streams(sc.streams, flags)
    assert len(kept["magnetometer"]["time_tai_ns"]) == sc.truth.time_tai_ns.size - s["streams"]["magnetometer"][
        "any"]["n_rejected"]
    stats = result.tables["statistics"]
    assert {"energy", "field_magnitude", "panel_eclipse"} <= set(stats["criterion"])
    figs = JOB.figures(result, Params())
    assert set(figs) == {"flags_timeline", "criteria"} and all(isinstance(f, Figure) for f in figs.values())


def test_streams_parameter_reference_orbit_and_errors() -> None:
    sc = scenario()
    tr = sc.truth
    orbit = {"time_tai_ns": tr.time_tai_ns[::20], **{c: tr.r_I[::20, i] for i, c in enumerate("xyz")},
             **{c: tr.v_I[::20, i] for i, c in enumerate(("vx", "vy", "vz"))}}
    ref = {"reference_orbit": ReferenceData("o1", "orbit.oem", orbit, {"frame": "GCRF", "earth_fixed": False})}
    result = JOB.run(_inputs(reference=ref), Params(streams=["gnss", "star_tracker"]), no_progress)
    assert list(result.summary["streams"]) == ["gnss"]
    assert result.summary["energy_reference"] == "reference orbit orbit.oem (GCRF)"
    assert "no samples of star_tracker in the window" in result.notes
    gnss = result.tables["flags"]
    assert np.all(~gnss["accepted"][tr.faults["gnss"]])
    with pytest.raises(TaskError, match="none of the streams to screen"):
        JOB.run(_inputs(streams={"gnss": sc.streams["gnss"]}), Params(streams=["magnetometer"]), no_progress)
    with pytest.raises(ValidationError):
        Params(k_energy=0.5)
    with pytest.raises(ValidationError):
        Params(unknown=1)
    assert JOB.reference == ("rinex_nav", "reference_orbit") and JOB.any_stream


def test_only_the_chosen_streams_and_what_their_criteria_need_are_read() -> None:
    from app.jobs.runner import stream_names

    assert stream_names(JOB, Params()) == stream_names(JOB)
    assert set(stream_names(JOB, Params(streams=["magnetometer"]))) == {"magnetometer", "gnss"}
    assert set(stream_names(JOB, Params(streams=["star_tracker"]))) == {"star_tracker", "gyro", "gnss"}


def test_rejected_by_names_whole_criteria_only():
    """_rejected_by matches whole ';'-joined names (not prefixes), and rows without a reason never match:
    the same rows as searching ';' + reasons + ';' over every row."""
    reasons = np.array(["", "energy", "energy_x;spike", "spike;energy", "velocity", "", "stuck;energy;spike"],
                       dtype=object)
    assert _rejected_by(reasons, "energy").tolist() == [False, True, False, True, False, False, True]
    assert _rejected_by(reasons, "spike").tolist() == [False, False, True, True, False, False, True]
    assert _rejected_by(reasons, "energy_x").tolist() == [False, False, True, False, False, False, False]
    assert not _rejected_by(reasons[:0], "energy").size
    everywhere = np.char.find(np.char.add(np.char.add(";", reasons.astype(str)), ";"), ";velocity;") >= 0
    assert np.array_equal(_rejected_by(reasons, "velocity"), everywhere)
