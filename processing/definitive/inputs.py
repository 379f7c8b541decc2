"""The estimator's inputs from a job's telemetry (processing.tasks.TaskInputs): the gyro as steps and every
star-tracker head with its configured mounting. Shared by the definitive_attitude and gyro_noise jobs
and by the tests (which build TaskInputs from the simulators' streams)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np

from processing.definitive.estimate import StarTrackerHead
from processing.definitive.gyro import GyroSteps, from_increments, from_rates
from processing.definitive.model import DefinitiveError, FloatArray
from processing.tasks import TaskError, TaskInputs

GyroSource = Literal["auto", "gyro", "gyro_increments"]


def gyro_steps(inputs: TaskInputs, source: GyroSource = "auto", max_gap_s: float = 5.0) -> GyroSteps:
    """The window's gyro (rates or increments; ``auto`` prefers increments) as :class:`GyroSteps`."""
    have = [name for name in ("gyro_increments", "gyro") if inputs.sensors(name)]
    if source == "auto":
        if not have:
            raise TaskError("no gyro or gyro_increments samples in the job window")
        source = "gyro_increments" if "gyro_increments" in have else "gyro"
    if len(inputs.sensors(source)) > 1:
        raise TaskError(f"the window holds several {source} sensors ({list(inputs.sensors(source))}); one gyro "
                        "triad is expected")
    try:
        if source == "gyro_increments":
            inc = inputs.gyro_increments()
            return from_increments(inc.time_tai_ns, inc.da_G_rad, inc.interval_s, max_gap_s)
        g = inputs.gyro()
        return from_rates(g.time_tai_ns, g.w_G_rad_s, max_gap_s)
    except DefinitiveError as exc:
        raise TaskError(str(exc)) from exc


def star_tracker_heads(inputs: TaskInputs, sensors: Sequence[str] | None = None) -> list[StarTrackerHead]:
    """Every configured head with data (configured order; ``sensors`` picks and orders them, the first is the
    reference); MissingMountingError for a named head that is not configured."""
    present = inputs.sensors("star_tracker")
    if not present:
        raise TaskError("no star_tracker samples in the job window")
    sc = inputs.spacecraft
    if sensors:
        names = list(sensors)
        if len(set(names)) != len(names):
            raise TaskError(f"sensors must be distinct, got {names}")
        for name in names:
            sc.star_tracker_mounting(name)
            if name not in present:
                raise TaskError(f"no star_tracker samples of sensor {name!r} in the window (present: {list(present)})")
    else:
        names = [n for n in sc.star_tracker_names if n in present]
        if not names:
            raise TaskError(f"no configured star tracker has data in the window (configured: "
                            f"{list(sc.star_tracker_names)}, present: {list(present)})")
    heads = []
    for name in names:
        v = inputs.star_tracker(name)
        heads.append(StarTrackerHead(name=name, time_tai_ns=v.time_tai_ns, q_IS=v.q_IS,
                                     q_BS=np.asarray(sc.star_tracker_mounting(name), dtype=np.float64)))
    return heads


def gyro_mounting(inputs: TaskInputs) -> FloatArray:
    return np.asarray(inputs.spacecraft.gyro_mounting(), dtype=np.float64)
