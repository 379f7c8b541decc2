"""Trends across jobs: calibration and accuracy results of one spacecraft over time, so drifts show.

Points come from the summaries the catalog stores with each succeeded job (no artifact is read), placed
at the midpoint of the job's window. Key metrics (star-tracker sigma, gyro offsets, misalignment, scale
factor, orbital pointing) are drawn with the spacecraft's specification limits; any other job type can
be trended generically (every number and 3-vector of its summary).
"""

from __future__ import annotations

import base64
import io
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from app.reports.specs import PPM, Specifications, lookup
from app.reports.summary import flatten_numbers, iso
from processing.time import timescales
from processing.units import ARCSEC_PER_RAD, DEG_H_PER_RAD_S
from storage.models import Job

if TYPE_CHECKING:  # matplotlib is imported when a trend is drawn, not at start-up
    from matplotlib.figure import Figure

MAX_JOBS = 1000


@dataclass(frozen=True)
class Metric:
    """One trended quantity: summary ``key`` of ``job_type`` times ``scale`` in ``unit``.

    ``components`` names the entries of a vector (or of a statistics object with ``stats`` keys);
    ``limits`` gives (lower, upper) lines per component from the specifications, when there are any.
    """

    job_type: str
    key: str
    title: str
    unit: str
    scale: float = 1.0
    components: tuple[str, ...] = ("x", "y", "z")
    stats: tuple[str, ...] = ()
    sigma: str | None = None  # summary key of the 1-sigma of each component (error bars), same scale
    limits: Callable[[Specifications], list[tuple[float | None, float | None]] | None] = field(
        default=lambda specs: None, repr=False)


def _per_axis(values: list[float] | None, symmetric: bool) -> list[tuple[float | None, float | None]] | None:
    if values is None:
        return None
    return [(-v if symmetric else None, v) for v in values]


def _orbital(angle: str) -> Callable[[Specifications], list[tuple[float | None, float | None]] | None]:
    def limits(specs: Specifications) -> list[tuple[float | None, float | None]] | None:
        ranges = specs.orbital_attitude_deg
        bounds = getattr(ranges, angle) if ranges is not None else None
        return None if bounds is None else [(bounds[0], bounds[1])] * 3
    return limits


KEY_METRICS: tuple[Metric, ...] = (
    Metric("star_tracker_accuracy", "sigma_arcsec", "Star-tracker accuracy σ per sensor axis", "arcsec",
           limits=lambda s: _per_axis(s.star_tracker_sigma_arcsec, symmetric=False)),
    Metric("gyro_bias_fit", "gyro_bias_rad_s", "Gyro offsets (bias, body axes)", "deg/h", DEG_H_PER_RAD_S,
           sigma="gyro_bias_sigma_rad_s", limits=lambda s: _per_axis(s.gyro_bias_max_deg_h, symmetric=True)),
    Metric("alignment_calibration", "misalignment_rad", "Gyro-to-star-tracker misalignment (rotation vector)",
           "arcsec", ARCSEC_PER_RAD, sigma="misalignment_sigma_rad"),
    Metric("alignment_calibration", "scale_factor_error", "Gyro scale-factor error", "ppm", PPM,
           sigma="scale_factor_error_sigma",
           limits=lambda s: None if s.scale_factor_error_max_ppm is None else
           [(-s.scale_factor_error_max_ppm, s.scale_factor_error_max_ppm)] * 3),
    Metric("alignment_calibration", "drift_rad_s", "Gyro drift (alignment calibration)", "deg/h", DEG_H_PER_RAD_S,
           limits=lambda s: _per_axis(s.gyro_bias_max_deg_h, symmetric=True)),
    *(Metric("orbital_attitude", f"{a}_deg", f"Orbital {a} (min, mean, max over each window)", "deg",
             components=("min", "mean", "max"), stats=("min", "mean", "max"), limits=_orbital(a))
      for a in ("pitch", "yaw", "roll")),
)


@dataclass(frozen=True)
class Point:
    job_id: str
    job_type: str
    series: str  # the sensor the job was about, or "" when it names none
    window_start_tai_ns: int
    window_end_tai_ns: int
    values: tuple[float | None, ...]
    sigmas: tuple[float | None, ...] | None = None  # 1-sigma per component, when the job reports one

    @property
    def mid_tai_ns(self) -> int:
        return (self.window_start_tai_ns + self.window_end_tai_ns) // 2


@dataclass(frozen=True)
class Trend:
    metric: Metric
    points: tuple[Point, ...]
    limits: list[tuple[float | None, float | None]] | None


def _series(job: Job) -> str:
    summary = (job.result or {}).get("summary") or {}
    for source, key in ((summary, "sensor"), (job.params or {}, "sensor")):
        value = source.get(key)
        if isinstance(value, str) and value:
            return value
    return ""


def _values(metric: Metric, summary: dict[str, Any]) -> tuple[float | None, ...] | None:
    raw = lookup(summary, metric.key)
    if metric.stats:
        if not isinstance(raw, dict):
            return None
        raw = [raw.get(s) for s in metric.stats]
    if isinstance(raw, (int, float)) and not isinstance(raw, bool):
        raw = [raw]
    if not isinstance(raw, list) or not raw:
        return None
    out: list[float | None] = []
    for v in raw:
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        out.append(float(v) * metric.scale if ok else None)
    return tuple(out)


def succeeded_jobs(session: Session, spacecraft_id: int, job_types: Iterable[str], *,
                   start_tai_ns: int | None = None, end_tai_ns: int | None = None) -> list[Job]:
    """Succeeded jobs of these types whose window ends after ``start`` and begins before ``end``, oldest first."""
    q = select(Job).where(Job.spacecraft_id == spacecraft_id, Job.status == "succeeded",
                          Job.type.in_(list(job_types)))
    if start_tai_ns is not None:
        q = q.where(Job.end_tai_ns >= start_tai_ns)
    if end_tai_ns is not None:
        q = q.where(Job.start_tai_ns <= end_tai_ns)
    jobs = list(session.scalars(q.order_by(Job.created_at.desc()).limit(MAX_JOBS)))
    return sorted(jobs, key=lambda j: (j.start_tai_ns + j.end_tai_ns, j.created_at))


def generic_metrics(job_type: str, jobs: Sequence[Job]) -> list[Metric]:
    """A metric for every number or 3-vector found in the summaries of ``job_type`` (first seen order)."""
    shapes: dict[str, int] = {}
    for job in jobs:
        if job.type == job_type:
            for key, values in flatten_numbers((job.result or {}).get("summary") or {}).items():
                shapes.setdefault(key, len(values))
    out = []
    sigma_keys = {k for k in (_sigma_key(shapes, key) for key in shapes) if k}
    for key, n in shapes.items():
        scale, unit, title = 1.0, "", key
        for suffix, u, f in (("_rad_s", "deg/h", DEG_H_PER_RAD_S), ("_rad", "arcsec", ARCSEC_PER_RAD)):
            if key.endswith(suffix):
                scale, unit, title = f, u, f"{key[: -len(suffix)]}"
                break
        comps = ("x", "y", "z") if n == 3 else tuple(str(i + 1) for i in range(n)) if n > 1 else ("",)
        sigma = _sigma_key(shapes, key)
        if key in sigma_keys:
            continue
        out.append(Metric(job_type, key, title, unit, scale, components=comps, sigma=sigma,
                          limits=_generic_limits(job_type, key, scale, n)))
    return out


def _sigma_key(keys: Iterable[str], key: str) -> str | None:
    """The key of ``key``'s 1-sigma among ``keys`` (``gyro_bias_rad_s`` -> ``gyro_bias_sigma_rad_s``,
    ``scale_factor_error`` -> ``scale_factor_error_sigma``)."""
    present = set(keys)
    for suffix in ("_rad_s", "_rad", "_arcsec_s", "_arcsec", "_deg_s", "_deg", "_m_s", "_m", "_s"):
        if key.endswith(suffix) and f"{key[: -len(suffix)]}_sigma{suffix}" in present:
            return f"{key[: -len(suffix)]}_sigma{suffix}"
    return f"{key}_sigma" if f"{key}_sigma" in present else None


def _generic_limits(job_type: str, key: str, scale: float,
                    n: int) -> Callable[[Specifications], list[tuple[float | None, float | None]] | None]:
    """Lines of the generic ``specifications.limits`` entries on this key, in the metric's unit."""

    def limits(specs: Specifications) -> list[tuple[float | None, float | None]] | None:
        for lim in specs.limits:
            if lim.job_type == job_type and lim.key == key and lim.scale:
                f = scale / lim.scale
                lo = None if lim.min is None else lim.min * f
                hi = None if lim.max is None else lim.max * f
                if lim.abs:
                    lo = None if hi is None else -hi
                return [(lo, hi)] * n
        return None

    return limits


def trends(jobs: Sequence[Job], metrics: Sequence[Metric], specs: Specifications | None) -> list[Trend]:
    """The points of each metric (metrics without any point are left out)."""
    out = []
    for metric in metrics:
        points = []
        for job in jobs:
            if job.type != metric.job_type:
                continue
            summary = (job.result or {}).get("summary") or {}
            values = _values(metric, summary)
            if values is not None:
                sigmas = _values(replace(metric, key=metric.sigma, stats=()), summary) if metric.sigma else None
                if sigmas is not None and len(sigmas) != len(values):
                    sigmas = None
                points.append(Point(job.id, job.type, _series(job), job.start_tai_ns, job.end_tai_ns, values, sigmas))
        if points:
            out.append(Trend(metric, tuple(points), metric.limits(specs) if specs is not None else None))
    return out


def _dates(tai_ns: Sequence[int]) -> np.ndarray:
    return np.asarray(timescales.tai_ns_to_epoch_ns(np.asarray(tai_ns, dtype=np.int64), "utc")).astype(
        "datetime64[ns]")


ANGLE_WORDS = ("pitch", "yaw", "roll")


def _is_angle(metric: Metric) -> bool:
    """Attitude angles in degrees wrap at +-180: their trends are drawn unwrapped."""
    return metric.unit == "deg" and any(w in metric.key for w in ANGLE_WORDS)


def _continuous(y: np.ndarray) -> np.ndarray:
    ok = np.isfinite(y)
    if ok.sum() > 1:
        y = y.copy()
        y[ok] = np.rad2deg(np.unwrap(np.deg2rad(y[ok])))
        y[ok] -= 360.0 * np.round(np.nanmean(y[ok]) / 360.0)
    return y


def _date_axis(ax: Any, lo: np.datetime64, hi: np.datetime64) -> None:
    """Full dates on the time axis (year, month, day; the time of day when the span is short)."""
    from matplotlib import dates as mdates

    span_days = float((hi - lo) / np.timedelta64(1, "D"))
    locator = mdates.AutoDateLocator(minticks=3, maxticks=8)
    ax.xaxis.set_major_locator(locator)
    ax.xaxis.set_major_formatter(mdates.DateFormatter("%Y-%m-%d %H:%M" if span_days < 3 else "%Y-%m-%d"))
    ax.set_xlabel("middle of each job's window (UTC)")


def figure(trend: Trend) -> Figure:
    """One trend: a line per component (and sensor) with ±1σ error bars where the jobs report them,
    dashed lines at the specification limits, full dates on the time axis."""
    m = trend.metric
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 3.4), label=m.title, layout="constrained")
    ax = fig.add_subplot()
    series = sorted({p.series for p in trend.points})
    colors = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink")
    markers = ("o", "s", "^", "D", "v", "P")
    n_comp = max(len(p.values) for p in trend.points)
    for si, name in enumerate(series):
        pts = [p for p in trend.points if p.series == name]
        x = _dates([p.mid_tai_ns for p in pts])
        for c in range(n_comp):
            y = np.array([p.values[c] if c < len(p.values) and p.values[c] is not None else np.nan for p in pts])
            if _is_angle(m):
                y = _continuous(y)
            err = np.array([p.sigmas[c] if p.sigmas is not None and c < len(p.sigmas) and p.sigmas[c] is not None
                            else np.nan for p in pts])
            comp = m.components[c] if c < len(m.components) else str(c + 1)
            tag = " ".join(t for t in (name, comp) if t)
            style: dict[str, Any] = {"marker": markers[si % len(markers)], "color": colors[c % len(colors)],
                                     "linewidth": 1, "markersize": 4, "label": tag or m.key}
            if np.isfinite(err).any():
                ax.errorbar(x, y, yerr=np.where(np.isfinite(err), err, 0.0), capsize=3, elinewidth=0.8, **style)
            else:
                ax.plot(x, y, **style)
    if trend.limits:
        drawn: set[float] = set()
        per_axis = len(set(trend.limits[:n_comp])) > 1
        for c, (lo, hi) in enumerate(trend.limits[:n_comp]):
            for v in (lo, hi):
                if v is not None and v not in drawn:
                    drawn.add(v)
                    ax.axhline(v, color=colors[c % len(colors)] if per_axis else "tab:red", linestyle="--",
                               linewidth=1, label="specification limit" if len(drawn) == 1 else None)
    x = _dates([p.mid_tai_ns for p in trend.points])
    lo_x, hi_x = x.min(), x.max()
    pad = max((hi_x - lo_x) * 0.05, np.timedelta64(1, "h"))
    ax.set_xlim(lo_x - pad, hi_x + pad)
    _date_axis(ax, lo_x - pad, hi_x + pad)
    has_sigma = any(p.sigmas is not None for p in trend.points)
    ax.set_ylabel((m.unit or m.key) + (" (±1σ)" if has_sigma else ""))
    ax.set_title(m.title + (" — unwrapped at ±180°" if _is_angle(m) else ""))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", ncols=min(7, n_comp * len(series) + 1))
    for label in ax.get_xticklabels():
        label.set_rotation(20)
        label.set_horizontalalignment("right")
    return fig


def figure_png_b64(trend: Trend) -> str:
    buf = io.BytesIO()
    figure(trend).savefig(buf, format="png", dpi=100, bbox_inches="tight")
    return base64.b64encode(buf.getvalue()).decode()


def rows(trend_list: Sequence[Trend]) -> list[dict[str, Any]]:
    """Long-format rows (one per job, metric and component) for tables and CSV downloads."""
    out = []
    for t in trend_list:
        for p in t.points:
            for c, v in enumerate(p.values):
                sigma = p.sigmas[c] if p.sigmas is not None and c < len(p.sigmas) else None
                out.append({"job_id": p.job_id, "job_type": p.job_type, "series": p.series,
                            "window_start": iso(p.window_start_tai_ns), "window_end": iso(p.window_end_tai_ns),
                            "metric": t.metric.key, "component": t.metric.components[c]
                            if c < len(t.metric.components) else str(c + 1), "value": v, "unit": t.metric.unit,
                            "sigma": sigma})
    return out
