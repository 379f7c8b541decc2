"""The typed input boundary of the jobs: the stored spacecraft configuration -> processing.spacecraft.

The configuration is validated by its schema (app/config_schema.py) when it is uploaded and again
here, then turned once into the frozen :class:`processing.spacecraft.Spacecraft` the tasks receive.
The report specifications stay app-side (app/reports/specs.py) and are not part of it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import ValidationError

from app.config_schema import SpacecraftConfig
from processing.spacecraft import SolarPanel, Spacecraft
from processing.tasks import TaskError


def _array(values: list[float] | list[list[float]] | None) -> NDArray[np.float64] | None:
    return None if values is None else np.asarray(values, dtype=np.float64)


def spacecraft_from_config(config: SpacecraftConfig) -> Spacecraft:
    """The processing view of a validated configuration (mountings, panels, antenna axis, inertia)."""
    return Spacecraft(
        star_trackers={name: np.asarray(st.q_BS, dtype=np.float64) for name, st in config.star_trackers.items()},
        gyro_q_BG=_array(None if config.gyro is None else config.gyro.q_BG),
        magnetometer_q_BM=_array(None if config.magnetometer is None else config.magnetometer.q_BM),
        sun_sensor_q_BS=_array(None if config.sun_sensor is None else config.sun_sensor.q_BS),
        solar_panels=tuple(SolarPanel(np.asarray(p.normal_B, dtype=np.float64), p.max_current_a)
                           for p in config.solar_panels),
        gnss_antenna_axis_B=_array(config.gnss_antenna_axis_B),
        inertia_kg_m2=_array(config.inertia_kg_m2),
    )


def spacecraft_from_stored(raw: Mapping[str, Any] | None, version: int | None = None) -> Spacecraft:
    """A stored configuration (JSON; None: no configuration, an empty spacecraft) validated and converted;
    TaskError when it no longer passes the schema."""
    try:
        config = SpacecraftConfig.model_validate(dict(raw or {}))
    except ValidationError as exc:
        which = "" if version is None else f" version {version}"
        raise TaskError(f"the spacecraft configuration{which} is not valid: {exc}") from None
    return spacecraft_from_config(config)
