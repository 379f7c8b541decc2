"""Specification limits stored with the spacecraft, and the pass/fail checks of job summaries.

The limits are the optional ``specifications`` object of the spacecraft configuration (validated by
:class:`Specifications`). Named limits cover the quantities of DESIGN.md's job summaries; ``limits``
holds generic ones for any job type and summary key, so new job types need no code here.
Values are compared in the unit the limit is written in (the key's suffix says which).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, model_validator

from processing.units import ARCSEC_PER_RAD, DEG_H_PER_RAD_S

PPM = 1e6
AXES = ("x", "y", "z")


def _per_axis(v: list[float]) -> list[float]:
    if len(v) != 3 or not all(math.isfinite(x) and x > 0 for x in v):
        raise ValueError(f"expected 3 positive finite values (one per axis), got {v}")
    return [float(x) for x in v]


def _range(v: list[float]) -> list[float]:
    if len(v) != 2 or not all(math.isfinite(x) for x in v) or v[0] > v[1]:
        raise ValueError(f"expected [min, max] with min <= max, got {v}")
    return [float(x) for x in v]


PerAxis = Annotated[list[float], AfterValidator(_per_axis)]
Range = Annotated[list[float], AfterValidator(_range)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class OrbitalAttitudeRanges(_Strict):
    """Allowed [min, max] of each angle of the body in the orbital frame (003 §1.6), degrees."""

    pitch: Range | None = None
    yaw: Range | None = None
    roll: Range | None = None
    euler_sequence: Literal["231", "321"] = Field(
        "231", description="sequence the ranges are written in: 231 = 003 §1.6 pitch, yaw, roll; 321 = yaw, pitch, "
                           "roll (LVLH); judged on the job's angles in that sequence whatever its euler_sequence")


class Limit(_Strict):
    """A generic limit on one summary value of one job type (each component of a vector)."""

    job_type: str = Field(min_length=1, max_length=64)
    key: str = Field(min_length=1, max_length=200,
                     description="summary key; a dotted path reaches into objects, e.g. pitch_deg.std")
    min: float | None = None
    max: float | None = None
    abs: bool = Field(False, description="compare |value|")
    scale: float = Field(1.0, description="multiply the summary value by this before comparing "
                                          "(e.g. 206264.806 for rad -> arcsec)")
    unit: str = Field("", max_length=20, description="unit of min/max after scaling, shown in reports")
    label: str = Field("", max_length=100)

    @model_validator(mode="after")
    def _bounded(self) -> Limit:
        if self.min is None and self.max is None:
            raise ValueError("give min, max or both")
        if self.min is not None and self.max is not None and self.min > self.max:
            raise ValueError("min must not exceed max")
        return self


class Specifications(_Strict):
    """Specification limits of one spacecraft (configuration key ``specifications``)."""

    star_tracker_sigma_arcsec: PerAxis | None = Field(
        None, description="largest accepted 1-sigma star-tracker error per sensor axis x1 x2 x3 (003 §1)")
    orbital_attitude_deg: OrbitalAttitudeRanges | None = Field(
        None, description="pointing spec in the orbital frame: allowed [min, max] of pitch, yaw, roll")
    gyro_bias_max_deg_h: PerAxis | None = Field(
        None, description="largest accepted |gyro bias| per body axis (003 §2)")
    misalignment_max_arcsec: float | None = Field(
        None, gt=0, description="largest accepted gyro-to-star-tracker misalignment angle (000)")
    scale_factor_error_max_ppm: float | None = Field(
        None, gt=0, description="largest accepted |gyro scale-factor error| per axis (000)")
    limits: list[Limit] = Field(default_factory=list, max_length=100)


@dataclass(frozen=True)
class Check:
    """One quantity judged against its limit; ``values`` in ``unit``, one per component."""

    label: str
    key: str
    unit: str
    values: tuple[float | None, ...]
    components: tuple[str, ...]
    limit: str
    passed: tuple[bool | None, ...]  # None: value not determined (null in the summary): UNDETERMINED, never PASS

    @property
    def ok(self) -> bool | None:
        judged = [p for p in self.passed if p is not None]
        return None if not judged else all(judged)


def lookup(summary: Mapping[str, Any], key: str) -> Any:
    """The summary value at a dotted path, or None."""
    value: Any = summary
    for part in key.split("."):
        if not isinstance(value, Mapping) or part not in value:
            return None
        value = value[part]
    return value


def _numbers(value: Any) -> list[float | None] | None:
    if isinstance(value, bool) or value is None:
        return None
    if isinstance(value, (int, float)):
        return [float(value)]
    if isinstance(value, list) and value and all(
            v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)) for v in value):
        return [None if v is None else float(v) for v in value]
    return None


def _components(n: int) -> tuple[str, ...]:
    return AXES if n == 3 else ("",) if n == 1 else tuple(str(i + 1) for i in range(n))


def _bound_check(label: str, key: str, raw: Any, *, scale: float, unit: str, lo: float | None, hi: float | None,
                 absolute: bool, per_component: list[float] | None = None) -> Check | None:
    values = _numbers(raw)
    if values is None:
        return None
    scaled = [None if v is None or not math.isfinite(v) else v * scale for v in values]
    passed: list[bool | None] = []
    limits: list[str] = []
    for i, v in enumerate(scaled):
        top = per_component[i] if per_component is not None and i < len(per_component) else hi
        if v is None:
            passed.append(None)
            continue
        x = abs(v) if absolute else v
        passed.append((lo is None or x >= lo) and (top is None or x <= top))
    if per_component is not None:
        limits.append(("|value| ≤ " if absolute else "≤ ") + ", ".join(f"{x:g}" for x in per_component))
    else:
        name = "|value|" if absolute else "value"
        if lo is not None and hi is not None:
            limits.append(f"{lo:g} ≤ {name} ≤ {hi:g}")
        elif lo is not None:
            limits.append(f"{name} ≥ {lo:g}")
        else:
            limits.append(f"{name} ≤ {hi:g}")
    return Check(label=label, key=key, unit=unit, values=tuple(scaled), components=_components(len(scaled)),
                 limit=" ".join(limits) + (f" {unit}" if unit else ""), passed=tuple(passed))


def _norm_check(label: str, key: str, raw: Any, *, scale: float, unit: str, hi: float) -> Check | None:
    values = _numbers(raw)
    if values is None:
        return None
    if any(v is None or not math.isfinite(v) for v in values):  # a component the data did not determine
        return Check(label=label, key=key, unit=unit, values=(None,), components=("angle",),
                     limit=f"≤ {hi:g} {unit}", passed=(None,))
    angle = math.sqrt(sum(v * v for v in values if v is not None)) * scale
    return Check(label=label, key=key, unit=unit, values=(angle,), components=("angle",),
                 limit=f"≤ {hi:g} {unit}", passed=(angle <= hi,))


def evaluate(job_type: str, summary: Mapping[str, Any] | None, specs: Specifications | None) -> list[Check]:
    """Every limit of ``specs`` that applies to a summary of ``job_type`` (empty when none does)."""
    if not summary or specs is None:
        return []
    checks: list[Check | None] = []
    if job_type == "star_tracker_accuracy" and specs.star_tracker_sigma_arcsec:
        check = _bound_check("Star-tracker accuracy (1σ per sensor axis)", "sigma_arcsec",
                             summary.get("sigma_arcsec"), scale=1.0, unit="arcsec", lo=None, hi=None,
                             absolute=False, per_component=specs.star_tracker_sigma_arcsec)
        axes = summary.get("axes")
        if check is not None and isinstance(axes, list) and len(axes) == len(check.values):
            check = replace(check, components=tuple(str(a) for a in axes))
        if check is not None and summary.get("residuals_white") is False:
            # correlated residuals: sigma is a lower bound, so a value under the limit proves nothing
            # (UNDETERMINED) while one above it still fails
            check = replace(check, passed=tuple(None if p else p for p in check.passed),
                            limit=check.limit + " (sigma a lower bound: correlated residuals)")
        checks.append(check)
    if job_type == "orbital_attitude" and specs.orbital_attitude_deg:
        seq = specs.orbital_attitude_deg.euler_sequence
        by_seq = summary.get("angles_by_sequence")
        in_seq = by_seq.get(seq) if isinstance(by_seq, Mapping) else None
        own = summary.get("euler_sequence", "231") == seq
        for angle in ("pitch", "yaw", "roll"):
            bounds = getattr(specs.orbital_attitude_deg, angle)
            stats = in_seq.get(f"{angle}_deg") if isinstance(in_seq, Mapping) else (
                summary.get(f"{angle}_deg") if own else None)
            if bounds is None or not isinstance(stats, Mapping):
                continue
            prefix = f"angles_by_sequence.{seq}." if isinstance(in_seq, Mapping) else ""
            for stat, lo, hi in (("min", bounds[0], None), ("max", None, bounds[1])):
                checks.append(_bound_check(f"Orbital {angle} ({stat} over the window, sequence {seq})",
                                           f"{prefix}{angle}_deg.{stat}", stats.get(stat), scale=1.0, unit="deg",
                                           lo=lo, hi=hi, absolute=False))
    bias_key = {"gyro_bias_fit": "gyro_bias_rad_s", "alignment_calibration": "drift_rad_s"}.get(job_type)
    if bias_key and specs.gyro_bias_max_deg_h:
        checks.append(_bound_check("Gyro bias (per axis)", bias_key, summary.get(bias_key), scale=DEG_H_PER_RAD_S,
                                   unit="deg/h", lo=None, hi=None, absolute=True,
                                   per_component=specs.gyro_bias_max_deg_h))
    if job_type == "alignment_calibration":
        if specs.misalignment_max_arcsec:
            checks.append(_norm_check("Gyro-to-star-tracker misalignment angle", "misalignment_rad",
                                      summary.get("misalignment_rad"), scale=ARCSEC_PER_RAD, unit="arcsec",
                                      hi=specs.misalignment_max_arcsec))
        if specs.scale_factor_error_max_ppm:
            checks.append(_bound_check("Gyro scale-factor error", "scale_factor_error",
                                       summary.get("scale_factor_error"), scale=PPM, unit="ppm", lo=None,
                                       hi=specs.scale_factor_error_max_ppm, absolute=True))
    for lim in specs.limits:
        if lim.job_type == job_type:
            checks.append(_bound_check(lim.label or lim.key, lim.key, lookup(summary, lim.key), scale=lim.scale,
                                       unit=lim.unit, lo=lim.min, hi=lim.max, absolute=lim.abs))
    return [c for c in checks if c is not None]


def parse(config: Mapping[str, Any] | None) -> Specifications | None:
    """The specifications of a stored configuration (None when it has none or they no longer validate)."""
    raw = (config or {}).get("specifications")
    if not raw:
        return None
    try:
        return Specifications.model_validate(raw)
    except ValueError:
        return None


def verdict(checks: list[Check]) -> str:
    """'fail' when any judged value fails; else 'undetermined' when a limited quantity was not determined
    (null: not observable in the window); else 'pass'; 'none' when no limit applied."""
    if not checks:
        return "none"
    judged = [p for c in checks for p in c.passed if p is not None]
    if judged and not all(judged):
        return "fail"
    if any(p is None for c in checks for p in c.passed):
        return "undetermined"
    return "pass"
