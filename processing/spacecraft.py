"""The spacecraft configuration as the algorithms see it (README "Spacecraft configuration").

One frozen, validated object instead of the JSON dict: mountings q_B<sensor> (sensor -> body, scalar
first, Hamilton) as read-only (4,) float arrays, unit and canonical (q0 >= 0); solar panels; the GNSS
antenna axis; the inertia. Algorithms ask for a mounting with the method of its sensor
(``star_tracker_mounting(name)``, ``magnetometer_mounting()``, ...), which raises
:class:`MissingMountingError` naming the sensor and the configured ones when it is absent. The one
default is the documented one, "gyro frame (body unless configured)": :meth:`Spacecraft.gyro_mounting` is
the identity when no gyro is configured. Magnetometer, sun-sensor and star-tracker mountings and the
antenna axis have no default. The report specifications stay app-side (app/reports/specs.py).

The service builds this object from its validated schema (app/config_schema.py, app/jobs/inputs.py);
:meth:`Spacecraft.from_json` reads the same JSON shape directly (simulators, tests).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude.rotations import quat_canonical
from processing.errors import TaskError

IDENTITY_QUATERNION = (1.0, 0.0, 0.0, 0.0)
UNIT_TOLERANCE = 1e-6
"""Largest | |q| - 1 | accepted for a mounting quaternion (the schema's rule)."""


class SpacecraftConfigError(TaskError):
    """A configuration value is malformed (wrong shape, not finite, not unit)."""


class MissingMountingError(SpacecraftConfigError):
    """A sensor the computation needs is not in the spacecraft configuration."""


def _frozen(x: NDArray[np.float64]) -> NDArray[np.float64]:
    x.setflags(write=False)
    return x


def mounting(q: ArrayLike, what: str) -> NDArray[np.float64]:
    """A mounting quaternion as a read-only (4,) float array, normalised and canonical (q0 >= 0).

    Raises SpacecraftConfigError (naming ``what``, e.g. "star_trackers.st1.q_BS") unless q has 4
    finite components of unit norm within UNIT_TOLERANCE."""
    try:
        a = np.array(q, dtype=np.float64)
    except (TypeError, ValueError):
        raise SpacecraftConfigError(f"{what} must be 4 numbers (scalar first), got {q!r}") from None
    if a.shape != (4,) or not np.all(np.isfinite(a)):
        raise SpacecraftConfigError(f"{what} must be 4 finite numbers (scalar first), got {q!r}")
    n = float(np.linalg.norm(a))
    if abs(n - 1.0) > UNIT_TOLERANCE:
        raise SpacecraftConfigError(f"{what} must have unit norm within {UNIT_TOLERANCE:g}, got |q| = {n:.9g}")
    return _frozen(np.asarray(quat_canonical(a / n), dtype=np.float64))


def _vector(v: ArrayLike, what: str, shape: tuple[int, ...] = (3,)) -> NDArray[np.float64]:
    try:
        a = np.array(v, dtype=np.float64)
    except (TypeError, ValueError):
        raise SpacecraftConfigError(f"{what} must be numbers of shape {shape}, got {v!r}") from None
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise SpacecraftConfigError(f"{what} must be finite numbers of shape {shape}, got {v!r}")
    return _frozen(a)


def _unit_vector(v: ArrayLike, what: str) -> NDArray[np.float64]:
    a = _vector(v, what)
    n = float(np.linalg.norm(a))
    if n < 1e-9:
        raise SpacecraftConfigError(f"{what} must be non-zero")
    return _frozen(a / n)


@dataclass(frozen=True, eq=False)
class SolarPanel:
    """One panel: outward normal in the body frame (unit, (3,)) and its current in full sun, A."""

    normal_B: NDArray[np.float64]
    max_current_a: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "normal_B", _unit_vector(self.normal_B, "solar_panels[].normal_B"))
        if not (np.isfinite(self.max_current_a) and self.max_current_a > 0):
            raise SpacecraftConfigError(f"solar_panels[].max_current_a must be > 0, got {self.max_current_a!r}")
        object.__setattr__(self, "max_current_a", float(self.max_current_a))


@dataclass(frozen=True, eq=False)
class Spacecraft:
    """The configuration of one spacecraft version (all parts optional, as in the JSON).

    star_trackers: name -> q_BS (configured order); gyro_q_BG, magnetometer_q_BM, sun_sensor_q_BS:
    None when the sensor is not configured; solar_panels in panel-index order (the ``panel`` column of
    panel_currents); gnss_antenna_axis_B: unit (3,); inertia_kg_m2: (3, 3). Arrays are read-only.
    """

    star_trackers: Mapping[str, NDArray[np.float64]] = field(default_factory=dict)
    gyro_q_BG: NDArray[np.float64] | None = None
    magnetometer_q_BM: NDArray[np.float64] | None = None
    sun_sensor_q_BS: NDArray[np.float64] | None = None
    solar_panels: tuple[SolarPanel, ...] = ()
    gnss_antenna_axis_B: NDArray[np.float64] | None = None
    inertia_kg_m2: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        trackers = {str(k): mounting(q, f"star_trackers.{k}.q_BS") for k, q in self.star_trackers.items()}
        object.__setattr__(self, "star_trackers", MappingProxyType(trackers))
        for name, what in (("gyro_q_BG", "gyro.q_BG"), ("magnetometer_q_BM", "magnetometer.q_BM"),
                           ("sun_sensor_q_BS", "sun_sensor.q_BS")):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, mounting(value, what))
        object.__setattr__(self, "solar_panels", tuple(self.solar_panels))
        if self.gnss_antenna_axis_B is not None:
            object.__setattr__(self, "gnss_antenna_axis_B",
                               _unit_vector(self.gnss_antenna_axis_B, "gnss_antenna_axis_B"))
        if self.inertia_kg_m2 is not None:
            object.__setattr__(self, "inertia_kg_m2", _vector(self.inertia_kg_m2, "inertia_kg_m2", (3, 3)))

    @classmethod
    def from_json(cls, config: Mapping[str, Any]) -> Spacecraft:
        """From the JSON shape (``{"star_trackers": {"st1": {"q_BS": [...]}}, "gyro": {"q_BG": [...]}, ...}``)
        with the schema's rules: a gyro, magnetometer or sun-sensor entry without its quaternion is
        mounted as the body; ``specifications`` (app-side) is ignored."""
        def entry(key: str, q: str) -> Any:
            value = config.get(key)
            return None if value is None else value.get(q, IDENTITY_QUATERNION)

        trackers = {}
        for name, st in (config.get("star_trackers") or {}).items():
            if not isinstance(st, Mapping) or "q_BS" not in st:
                raise SpacecraftConfigError(f"star_trackers.{name} has no q_BS mounting")
            trackers[name] = st["q_BS"]
        panels = tuple(SolarPanel(p["normal_B"], p["max_current_a"]) for p in config.get("solar_panels") or ())
        return cls(star_trackers=trackers, gyro_q_BG=entry("gyro", "q_BG"),
                   magnetometer_q_BM=entry("magnetometer", "q_BM"), sun_sensor_q_BS=entry("sun_sensor", "q_BS"),
                   solar_panels=panels, gnss_antenna_axis_B=config.get("gnss_antenna_axis_B"),
                   inertia_kg_m2=config.get("inertia_kg_m2"))

    # -- what is configured ---------------------------------------------------------------------

    @property
    def star_tracker_names(self) -> tuple[str, ...]:
        return tuple(self.star_trackers)

    @property
    def has_gyro(self) -> bool:
        return self.gyro_q_BG is not None

    def configured(self) -> str:
        """The configured sensors, for messages: "star_trackers st1, st2; gyro" (or "none")."""
        parts = [f"star_trackers {', '.join(self.star_trackers)}"] if self.star_trackers else []
        parts += [name for name, value in (("gyro", self.gyro_q_BG), ("magnetometer", self.magnetometer_q_BM),
                                           ("sun_sensor", self.sun_sensor_q_BS),
                                           ("gnss_antenna_axis_B", self.gnss_antenna_axis_B)) if value is not None]
        if self.solar_panels:
            parts.append(f"{len(self.solar_panels)} solar_panels")
        return "; ".join(parts) or "none"

    # -- mountings --------------------------------------------------------------------------------

    def star_tracker_mounting(self, name: str) -> NDArray[np.float64]:
        """Mounting q_BS of star tracker ``name``; MissingMountingError when it is not configured."""
        q = self.star_trackers.get(name)
        if q is None:
            raise MissingMountingError(
                f"star tracker {name!r} is not in the spacecraft configuration "
                f"(configured: {', '.join(self.star_trackers) or 'none'}); add star_trackers.{name}.q_BS")
        return q

    def gyro_mounting(self) -> NDArray[np.float64]:
        """Gyro mounting q_BG; the body frame (identity) when no gyro is configured (DESIGN.md)."""
        return self.gyro_q_BG if self.gyro_q_BG is not None else _frozen(np.array(IDENTITY_QUATERNION))

    def magnetometer_mounting(self) -> NDArray[np.float64]:
        """Magnetometer mounting q_BM; MissingMountingError when no magnetometer is configured."""
        return self._required(self.magnetometer_q_BM, "the magnetometer", "magnetometer.q_BM")

    def sun_sensor_mounting(self) -> NDArray[np.float64]:
        """Sun-sensor mounting q_BS; MissingMountingError when no sun sensor is configured."""
        return self._required(self.sun_sensor_q_BS, "the sun sensor", "sun_sensor.q_BS")

    def antenna_axis_B(self) -> NDArray[np.float64]:
        """GNSS antenna axis a_B (unit); MissingMountingError when it is not configured."""
        return self._required(self.gnss_antenna_axis_B, "the GNSS antenna axis", "gnss_antenna_axis_B")

    def _required(self, value: NDArray[np.float64] | None, sensor: str, key: str) -> NDArray[np.float64]:
        if value is None:
            raise MissingMountingError(f"{sensor} is not in the spacecraft configuration "
                                       f"(configured: {self.configured()}); add {key}")
        return value

    # -- panels -----------------------------------------------------------------------------------

    def panel_normals_B(self) -> NDArray[np.float64]:
        """(P, 3) unit normals of the solar panels, (0, 3) when none are configured."""
        return np.array([p.normal_B for p in self.solar_panels], dtype=np.float64).reshape(-1, 3)

    def panel_max_current_a(self) -> NDArray[np.float64]:
        """(P,) full-sun currents of the solar panels, A."""
        return np.array([p.max_current_a for p in self.solar_panels], dtype=np.float64)

    def with_gyro_mounting(self, q_BG: ArrayLike) -> Spacecraft:
        """A copy with another gyro mounting (e.g. identity for calibrated, body-frame gyro data)."""
        return replace(self, gyro_q_BG=np.asarray(q_BG, dtype=np.float64))
