"""What the screening criteria share (processing.screening.criteria): the thresholds
(:class:`ScreeningParams`), the injectable models (:class:`Environment`), the per-row results
(:class:`Criterion`, :class:`ScreeningResult`), the collector that accumulates them per stream, and the
generic checks every stream gets (time grid, stuck values, spikes).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.environment import igrf_field_E_nT, sun_position_I_m, sunlit_fraction
from processing.samples import sensor_index
from processing.screening.tools import hampel, quantisation_step, stuck, time_grid_irregular

Columns = Mapping[str, NDArray[Any]]
VECTOR_COLUMNS = {
    "gnss": ("x", "y", "z", "vx", "vy", "vz"),
    "magnetometer": ("bx", "by", "bz"),
    "gyro": ("wx", "wy", "wz"),
    "gyro_increments": ("dax", "day", "daz"),
    "sun_sensor": ("sx", "sy", "sz"),
    "star_tracker": ("q0", "q1", "q2", "q3"),
    "magnetorquer": ("mx", "my", "mz"),
    "panel_currents": ("current_a",),
}
KEY_COLUMNS = {"panel_currents": ("panel",), "gnss_visibility": ("system", "prn")}
"""Columns besides (sensor, time) that identify a sample (processing.streams)."""



@dataclass(frozen=True)
class Environment:
    """Models used by the criteria (injectable for tests and other missions).

    field_E_nT(r_E (N, 3) m, tai_ns (N,)) -> (N, 3) nT ITRF; sun_position_I_m(tai_ns (N,)) -> (N, 3) m
    GCRS; sunlit_fraction(r_I (N, 3), r_sun_I (N, 3)) -> (N,) visible fraction of the solar disc.
    """

    field_E_nT: Callable[[NDArray[Any], NDArray[Any]], NDArray[Any]] = igrf_field_E_nT
    sun_position_I_m: Callable[[NDArray[Any]], NDArray[Any]] = sun_position_I_m
    sunlit_fraction: Callable[[NDArray[Any], NDArray[Any]], NDArray[Any]] = sunlit_fraction


@dataclass(frozen=True)
class ScreeningParams:
    """Thresholds. Each tolerance is k x (instrument error + model error) as in 002 eqs. 15-17.

    Defaults: a small-satellite GNSS receiver (10 m, 0.1 m/s, 1 sigma per axis), a magnetometer of
    100 nT noise and IGRF-14's ~150 nT omission/commission error in LEO (crustal and external fields
    in quiet conditions), panel currents read to 0.02 A with 0.03 A of model error (albedo,
    temperature); k = 3 to 6 so that Gaussian noise alone is flagged at a rate below 1e-4 (the
    paper only asks k > 1).
    """

    gnss_position_error_m: float = 10.0
    gnss_velocity_error_m_s: float = 0.1
    k_energy: float = 4.0
    energy_model: Literal["j2", "two_body"] = "j2"
    energy_model_error_m2_s2: float | None = None
    """Model error of h added to dh; None: 300 m^2/s^2 for "j2", 2.5e5 for "two_body" (J2_EARTH oscillation)."""
    k_plane: float = 5.0
    plane_window_s: float = 10.0
    """Half-width of the orbit-normal running median (at least 2 samples)."""
    k_kinematic: float = 6.0
    k_velocity: float = 6.0
    velocity_half_window: int = 8
    magnetometer_error_nT: float = 100.0
    field_model_error_nT: float = 150.0
    k_field: float = 3.0
    current_error_a: float = 0.02
    current_model_error_a: float = 0.03
    k_current: float = 3.0
    sun_norm: bool = True
    spike_half_window: int = 5
    k_spike: float = 6.0
    stuck_min_run: int = 10
    time_grid_tolerance: float = 0.25
    max_rate_rad_s: float = 0.1
    star_tracker_error_rad: float = 5e-5
    gyro_rate_error_rad_s: float = 1e-5
    k_quaternion: float = 6.0
    quaternion_norm_tolerance: float = 1e-3
    grazing_altitude_m: float = 50e3
    max_interpolation_gap_s: float = 30.0
    k_time_tag: float = 6.0
    """GNSS ``time_tag``: a state is tagged off when its residuals are a time shift beyond k dr / |v| (0: off)."""
    k_time_jitter: float = 6.0
    """``time_grid`` tolerance at least k x the robust scatter of the intervals (irregular sampling)."""
    stuck_false_alarm: float = 1e-5
    """Quantised values repeat by chance: ``stuck`` needs runs that chance makes rarer than this per row."""
    transient_consistency: bool = True
    """A gyro spike whose angle the star tracker sees too is a real transient, not rejected."""


@dataclass(frozen=True)
class Criterion:
    """One criterion applied to one stream: row masks aligned with the stream's rows.

    flagged: (n,) rejected by this criterion; applied: (n,) rows the criterion could judge;
    statistic: (n,) the tested quantity (NaN where not applied); threshold: its bound (same unit);
    unit: of statistic and threshold; source: the paper's equation or "generic".
    """

    stream: str
    name: str
    flagged: NDArray[np.bool_]
    applied: NDArray[np.bool_]
    statistic: NDArray[np.float64]
    threshold: float
    unit: str
    source: str


@dataclass(frozen=True)
class ScreeningResult:
    """All criteria applied; ``n_rows[stream]`` rows per screened stream; ``notes`` say what was skipped."""

    criteria: list[Criterion]
    n_rows: dict[str, int]
    notes: list[str] = field(default_factory=list)
    findings: dict[str, Any] = field(default_factory=dict)
    """What the screening found besides flags (JSON-able): ``gnss_time_tags`` (estimated offsets of late
    tags), ``transients`` (gyro spikes confirmed by the star tracker), ``quantisation`` (LSB per stream),
    ``irregular_sampling`` (streams whose grid could not be judged)."""

    def rejected(self, stream: str) -> NDArray[np.bool_]:
        out = np.zeros(self.n_rows[stream], dtype=bool)
        for c in self.criteria:
            if c.stream == stream:
                out |= c.flagged
        return out

    def reasons(self, stream: str) -> NDArray[np.object_]:
        """(n,) ';'-joined names of the criteria that flagged each row ("" when accepted)."""
        out = np.full(self.n_rows[stream], "", dtype=object)
        rows = np.flatnonzero(self.rejected(stream))  # the names are built for the rejected rows only
        sub = np.full(rows.size, "", dtype=object)
        for c in self.criteria:
            if c.stream == stream:
                hit = c.flagged[rows]
                sub[hit] = np.where(sub[hit] == "", c.name, sub[hit] + (";" + c.name))
        out[rows] = sub
        return out

    def summary(self) -> dict[str, dict[str, dict[str, Any]]]:
        """{stream: {criterion: {n_total, n_applied, n_rejected, threshold, unit, source}}} (JSON-able)."""
        out: dict[str, dict[str, dict[str, Any]]] = {}
        for c in self.criteria:
            out.setdefault(c.stream, {})[c.name] = {
                "n_total": int(c.flagged.size), "n_applied": int(c.applied.sum()), "n_rejected": int(c.flagged.sum()),
                "threshold": float(c.threshold), "unit": c.unit, "source": c.source}
        for stream, n in self.n_rows.items():
            rej = self.rejected(stream)
            out.setdefault(stream, {})["any"] = {"n_total": int(n), "n_applied": int(n),
                                                  "n_rejected": int(rej.sum()), "threshold": float("nan"),
                                                  "unit": "", "source": "union"}
        return out


def sensor_groups(cols: Columns) -> list[tuple[str, NDArray[np.int64]]]:
    """(sensor, row indices in time order) per sensor of a stream, sensors sorted."""
    sensors, index = sensor_index(cols["sensor"])
    t = np.asarray(cols["time_tai_ns"], dtype=np.int64)
    out = []
    for i, s in enumerate(sensors):
        idx = np.flatnonzero(index == i)
        out.append((s, idx[np.argsort(t[idx], kind="stable")]))
    return out


class Collector:
    """Accumulates per-row criterion masks of a stream across its sensor groups."""

    def __init__(self, stream: str, n: int) -> None:
        self.stream = stream
        self.n = n
        self.items: dict[str, dict[str, Any]] = {}

    def add(self, name: str, rows: NDArray[np.int64], flagged: ArrayLike, statistic: ArrayLike, threshold: float,
            unit: str, source: str, applied: ArrayLike | None = None) -> None:
        it = self.items.setdefault(name, {
            "flagged": np.zeros(self.n, bool), "applied": np.zeros(self.n, bool), "statistic": np.full(self.n, np.nan),
            "thresholds": [], "unit": unit, "source": source})
        f = np.asarray(flagged, dtype=bool)
        app = np.ones(rows.size, bool) if applied is None else np.asarray(applied, dtype=bool)
        stat = np.asarray(statistic, dtype=np.float64)
        it["flagged"][rows] |= f & app
        it["applied"][rows] |= app
        it["statistic"][rows] = np.where(app, stat, np.nan)
        it["thresholds"].append(float(threshold))

    def criteria(self) -> list[Criterion]:
        out = []
        for name, it in self.items.items():
            th = [x for x in it["thresholds"] if np.isfinite(x)]
            out.append(Criterion(self.stream, name, it["flagged"], it["applied"], it["statistic"],
                                 float(np.max(th)) if th else float("nan"), it["unit"], it["source"]))
        return out


UNITS = {"magnetometer": "nT", "gyro": "rad/s", "gyro_increments": "rad", "sun_sensor": "", "magnetorquer": "A m^2",
         "gnss": "m, m/s", "panel_currents": "A", "star_tracker": ""}
"""Unit of each stream's values (of the spike statistic)."""


def stuck_min_run(values: NDArray[np.float64], lsb: NDArray[np.float64], min_run: int, false_alarm: float) -> int:
    """The run length that makes ``stuck`` a fault on quantised data: with a fraction p of rows equal to their
    predecessor (the noise below the LSB), a run of m equal rows arises by chance with probability ~p^(m-1);
    m is raised until that is below ``false_alarm`` (never below ``min_run``; unquantised data: min_run)."""
    if values.shape[0] < 2 or not np.any(lsb > 0):
        return min_run
    p1 = float(np.mean(np.all(values[1:] == values[:-1], axis=1)))
    if p1 <= 0.0 or p1 >= 1.0:
        return min_run
    return max(min_run, 1 + int(np.ceil(np.log(false_alarm) / np.log(p1))))


def generic_checks(col: Collector, cols: Columns, stream: str, rows: NDArray[np.int64], p: ScreeningParams,
                   spike: bool = True, stuck_ignore: NDArray[np.bool_] | None = None,
                   findings: dict[str, Any] | None = None) -> None:
    """time_grid (tolerance widened by the sampling jitter), stuck (run length raised for quantised values)
    and (with ``spike``) the Hampel spike test (threshold at least a few LSB) on the rows of one sensor group."""
    t = np.asarray(cols["time_tai_ns"], dtype=np.int64)[rows]
    flagged, dev, period, tol = time_grid_irregular(t, p.time_grid_tolerance, p.k_time_jitter)
    col.add("time_grid", rows, flagged, dev, tol, "fraction of the sampling period", "generic")
    if findings is not None and tol >= 0.5:
        findings.setdefault("irregular_sampling", []).append(stream)
    names = VECTOR_COLUMNS.get(stream)
    if names is None:
        return
    values = np.stack([np.asarray(cols[c], dtype=np.float64)[rows] for c in names], axis=1)
    lsb = quantisation_step(values)
    if findings is not None and np.any(lsb > 0):
        findings.setdefault("quantisation", {})[stream] = {c: float(q) for c, q in zip(names, lsb, strict=True)}
    run = stuck_min_run(values, lsb, p.stuck_min_run, p.stuck_false_alarm)
    col.add("stuck", rows, stuck(values, run, stuck_ignore), np.full(rows.size, np.nan),
            float(run), "samples", "generic")
    if spike and rows.size > 2 * p.spike_half_window:
        q2 = float(np.sum(lsb ** 2))
        floor = p.k_spike * np.sqrt(q2 / 12.0) + np.sqrt(q2)  # rounding noise, plus one LSB of the median
        dist, th, f = hampel(values, p.spike_half_window, p.k_spike, floor=floor)
        col.add("spike", rows, f, dist, th, UNITS.get(stream, ""), "generic")
