"""Scenario -> estimator inputs, and truth errors measured with scipy's Rotation (independent of our rotations)."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from processing.definitive.estimate import DefinitiveResult, StarTrackerHead, estimate_definitive_attitude
from processing.definitive.gyro import GyroSteps
from processing.definitive.inputs import gyro_mounting, gyro_steps, star_tracker_heads
from processing.definitive.model import DefinitiveSettings
from processing.simulate.definitive import ScenarioDefinitive
from processing.spacecraft import Spacecraft
from processing.tasks import TaskInputs


def task_inputs(sc: ScenarioDefinitive | Any) -> TaskInputs:
    t = [c["time_tai_ns"] for c in sc.streams.values()]
    return TaskInputs(streams=sc.streams, spacecraft=Spacecraft.from_json(sc.config),
                      start_tai_ns=int(min(x[0] for x in t)), end_tai_ns=int(max(x[-1] for x in t)))


def inputs_of(sc: Any) -> tuple[GyroSteps, list[StarTrackerHead], np.ndarray]:
    ti = task_inputs(sc)
    return gyro_steps(ti), star_tracker_heads(ti), gyro_mounting(ti)


def run(sc: Any, settings: DefinitiveSettings) -> DefinitiveResult:
    steps, heads, q_BG = inputs_of(sc)
    return estimate_definitive_attitude(steps, heads, q_BG, settings)


def attitude_error(q_est: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """Rotation vector (K, 3) of q_est^-1 o q_true in body axes (q_true = q_est o exp(e)), by scipy."""
    r_est = Rotation.from_quat(q_est, scalar_first=True)
    r_true = Rotation.from_quat(q_true, scalar_first=True)
    return (r_est.inv() * r_true).as_rotvec()


def calibration_truth(result: DefinitiveResult, K_true: np.ndarray) -> np.ndarray:
    from processing.definitive.model import K_ENTRIES

    return np.array([K_true[K_ENTRIES[i]] for i in result.layout.calibration])
