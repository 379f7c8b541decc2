"""gyro_bias_fit gives the same summary numbers as recorded before its speed-ups (issue 24), to 1e-12 relative.

tests/data/gyro_bias_fit_golden.json holds the summaries of the job on a gap-free and a gapped 1200-s seed-003
arc (10 Hz gyro, 3-s star tracker; the gapped one has a 2-s gyro hole, bridged, and a 30-s one, which splits
the arc into two segments fitted on their own), written by the code of commit 251b003 (branch ``pipeline``,
before the speed-ups) with ``.venv/bin/python -m tests.app.test_job_gyro_bias_fit_golden --write``. Strings,
booleans and integers must be equal; floats equal to 1e-12 relative.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from app.jobs.types.gyro_bias_fit import JOB
from processing.simulate.seed003 import simulate_seed003
from processing.spacecraft import Spacecraft
from processing.tasks import TaskInputs, no_progress

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "gyro_bias_fit_golden.json"
T0_NS = 1_900_000_000 * 1_000_000_000
DURATION_S = 1200.0
RTOL = 1e-12


def _gapped(streams: dict[str, Any]) -> dict[str, Any]:
    g = streams["gyro"]
    t_s = (np.asarray(g["time_tai_ns"]) - T0_NS) / 1e9
    hole = ((t_s > 300.0) & (t_s < 302.0)) | ((t_s > 700.0) & (t_s < 730.0))
    return {**streams, "gyro": {k: np.asarray(v)[~hole] for k, v in g.items()}}


def summaries() -> dict[str, Any]:
    """{"gap_free": summary, "gapped": summary} of a default gyro_bias_fit, as JSON values."""
    sc = simulate_seed003(start_tai_ns=T0_NS, duration_s=DURATION_S, seed=2, gnss_period_s=1200.0)
    out = {}
    for name, streams in (("gap_free", sc.streams), ("gapped", _gapped(sc.streams))):
        inputs = TaskInputs(streams=streams, spacecraft=Spacecraft.from_json(sc.config), start_tai_ns=T0_NS,
                            end_tai_ns=T0_NS + int(DURATION_S * 1e9))
        out[name] = json.loads(json.dumps(JOB.run(inputs, JOB.params(), no_progress).summary))
    return out


def _differences(got: Any, want: Any, where: str) -> list[str]:
    if isinstance(want, dict):
        if not isinstance(got, dict) or set(got) != set(want):
            return [f"{where}: keys {sorted(got) if isinstance(got, dict) else got!r} != {sorted(want)}"]
        return [d for k in want for d in _differences(got[k], want[k], f"{where}.{k}")]
    if isinstance(want, list):
        if not isinstance(got, list) or len(got) != len(want):
            return [f"{where}: {got!r} != {want!r}"]
        return [d for i, (g, w) in enumerate(zip(got, want, strict=True)) for d in _differences(g, w, f"{where}[{i}]")]
    if isinstance(want, float) and isinstance(got, float) and not (want == got or math.isnan(want) and math.isnan(got)):
        if abs(got - want) > RTOL * max(abs(got), abs(want)):
            return [f"{where}: {got!r} != {want!r} (relative {abs(got - want) / max(abs(got), abs(want)):.2g})"]
        return []
    if type(got) is not type(want) or (got != want and not isinstance(want, float)):
        return [f"{where}: {got!r} != {want!r}"]
    return []


@pytest.fixture(scope="module")
def current() -> dict[str, Any]:
    return summaries()


@pytest.mark.parametrize("arc", ["gap_free", "gapped"])
def test_summary_numbers_match_the_recorded_ones(current: dict[str, Any], arc: str) -> None:
    want = json.loads(GOLDEN.read_text())[arc]
    if arc == "gapped":  # the arc really was split, and both segments fitted
        assert len(want["segments"]) == 2, want.get("segments")
    diffs = _differences(current[arc], want, arc)
    assert not diffs, f"{len(diffs)} differences, first: " + "; ".join(diffs[:5])


def test_the_comparison_can_fail(current: dict[str, Any]) -> None:
    want = json.loads(GOLDEN.read_text())["gap_free"]
    bias = list(want["gyro_bias_rad_s"])
    bias[0] *= 1.0 + 1e-11
    assert _differences(current["gap_free"], {**want, "gyro_bias_rad_s": bias}, "s")
    assert _differences(current["gap_free"], {**want, "converged": not want["converged"]}, "s")


if __name__ == "__main__" and sys.argv[1:] == ["--write"]:
    GOLDEN.write_text(json.dumps(summaries(), indent=1, sort_keys=True) + "\n")
