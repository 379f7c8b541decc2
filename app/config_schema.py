"""Spacecraft configuration: the public JSON shape of DESIGN.md, validated.

Mounting quaternions are q_B<sensor> (sensor -> body), scalar first; they must be unit to 1e-6 and are
stored canonical (q0 >= 0). Unknown keys are rejected so that a typo does not silently drop a sensor.
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, field_validator

from app.names import valid_name
from app.reports.specs import Specifications
from processing.attitude.rotations import quat_canonical

UNIT_TOLERANCE = 1e-6


def _unit_quaternion(q: list[float]) -> list[float]:
    if len(q) != 4:
        raise ValueError(f"expected 4 components (q0 scalar first), got {len(q)}")
    if not all(math.isfinite(x) for x in q):
        raise ValueError("components must be finite")
    n = math.sqrt(sum(x * x for x in q))
    if abs(n - 1.0) > UNIT_TOLERANCE:
        raise ValueError(f"quaternion norm must be 1 within {UNIT_TOLERANCE:g}, got {n:.9g}")
    return [float(x) for x in quat_canonical(np.asarray(q, dtype=float) / n)]


def _unit_vector(v: list[float]) -> list[float]:
    if len(v) != 3:
        raise ValueError(f"expected 3 components, got {len(v)}")
    n = math.sqrt(sum(x * x for x in v))
    if not math.isfinite(n) or n < 1e-9:
        raise ValueError("vector must be finite and non-zero")
    return [x / n for x in v]


Quaternion = Annotated[list[float], AfterValidator(_unit_quaternion)]
UnitVector = Annotated[list[float], AfterValidator(_unit_vector)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class StarTracker(_Strict):
    q_BS: Quaternion = Field(description="mounting, star-tracker frame -> body frame, scalar first")


class Gyro(_Strict):
    q_BG: Quaternion = Field(default_factory=lambda: [1.0, 0.0, 0.0, 0.0])


class Magnetometer(_Strict):
    q_BM: Quaternion = Field(default_factory=lambda: [1.0, 0.0, 0.0, 0.0])


class SunSensor(_Strict):
    q_BS: Quaternion = Field(default_factory=lambda: [1.0, 0.0, 0.0, 0.0])


class SolarPanel(_Strict):
    normal_B: UnitVector
    max_current_a: float = Field(gt=0)


class SpacecraftConfig(_Strict):
    star_trackers: dict[str, StarTracker] = Field(default_factory=dict)
    gyro: Gyro | None = None
    magnetometer: Magnetometer | None = None
    sun_sensor: SunSensor | None = None
    solar_panels: list[SolarPanel] = Field(default_factory=list)
    gnss_antenna_axis_B: UnitVector | None = None
    inertia_kg_m2: list[list[float]] | None = None
    specifications: Specifications | None = None  # limits reports judge against (app/reports/specs.py)

    @field_validator("star_trackers")
    @classmethod
    def _names(cls, v: dict[str, StarTracker]) -> dict[str, StarTracker]:
        for name in v:
            if not valid_name(name):
                raise ValueError(f"star tracker name {name!r} must be 1-64 letters, digits, _ . - (not only dots)")
        return v

    @field_validator("inertia_kg_m2")
    @classmethod
    def _inertia(cls, v: list[list[float]] | None) -> list[list[float]] | None:
        if v is None:
            return v
        j = np.asarray(v, dtype=float)
        if j.shape != (3, 3) or not np.all(np.isfinite(j)):
            raise ValueError(f"inertia must be a finite 3x3 matrix, got shape {j.shape}")
        if not np.allclose(j, j.T, rtol=0, atol=1e-9 * max(1.0, float(np.abs(j).max()))):
            raise ValueError("inertia must be symmetric")
        eig = np.linalg.eigvalsh(j)
        if eig.min() <= 0:
            raise ValueError(f"inertia must be positive definite (eigenvalues {eig.tolist()})")
        if eig[0] + eig[1] < eig[2] * (1 - 1e-9):
            raise ValueError("principal moments violate the triangle inequality")
        return v
