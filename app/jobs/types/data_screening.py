"""Job ``data_screening`` (paper 002, eqs. 15-17): flag bad telemetry samples with the reasons.

Thin layer over :func:`processing.screening.criteria.screen`. Every sample of the screened streams gets a row in
the ``flags`` table (accepted, and the ';'-joined names of the criteria that rejected it); nothing is
deleted. Later jobs run with ``screened = true`` use only the accepted samples (the runner filters their
inputs with :func:`processing.screening.flags.filter_streams` and the stored ``flags`` table).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, Literal

import numpy as np
from matplotlib.figure import Figure
from pydantic import BaseModel, ConfigDict, Field

from app.jobs.partitions import map_partitions
from app.jobs.registry import JobType
from app.reports.headline import Answer
from processing.screening.criteria import ScreeningParams, screen
from processing.screening.flags import flags_table
from processing.streams import STREAMS
from processing.tasks import Progress, ResultWarning, TaskError, TaskInputs, TaskResult
from processing.units import NS_PER_S

SCREENABLE = ("gnss", "magnetometer", "panel_currents", "gnss_visibility", "star_tracker", "gyro",
              "gyro_increments", "sun_sensor", "magnetorquer")
STATISTIC_CRITERIA = ("energy", "field_magnitude", "panel_eclipse", "panel_sun_norm", "orbit_plane", "velocity")
"""Criteria whose tested quantity is kept in the ``statistics`` table (and plotted)."""


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    streams: list[Literal["gnss", "magnetometer", "panel_currents", "gnss_visibility", "star_tracker", "gyro",
                          "gyro_increments", "sun_sensor", "magnetorquer"]] | None = Field(
        None, description="streams to screen; default: every stream with samples in the window")
    energy_model: Literal["j2", "two_body"] = Field(
        "j2", description="energy integral of eq. 15 with the J2 potential (conserved) or two-body (the paper)")
    use_reference_orbit: bool = Field(True, description="compare the energy with an uploaded reference_orbit")
    gnss_position_error_m: float = Field(10.0, gt=0, description="dr of eq. 15: receiver position error (1 sigma)")
    gnss_velocity_error_m_s: float = Field(0.1, gt=0, description="dv of eq. 15: receiver velocity error")
    k_energy: float = Field(4.0, gt=1, description="k1 of eq. 15")
    energy_model_error_m2_s2: float | None = Field(
        None, ge=0, description="model error added to dh (default 300 for j2, 2.5e5 for two_body)")
    k_plane: float = Field(5.0, gt=1, description="orbit-plane check: k x (dv/v + dr/r)")
    k_kinematic: float = Field(6.0, gt=1, description="position increments vs integrated velocity")
    k_velocity: float = Field(6.0, gt=1, description="velocity vs the slope of the positions")
    magnetometer_error_nT: float = Field(100.0, ge=0, description="dH_instr of eq. 16")
    field_model_error_nT: float = Field(150.0, ge=0, description="dH_mod of eq. 16 (IGRF-14 in LEO)")
    k_field: float = Field(3.0, gt=1, description="k2 of eq. 16")
    current_error_a: float = Field(0.02, ge=0, description="dI_instr of eq. 17")
    current_model_error_a: float = Field(0.03, ge=0, description="dI_mod of eq. 17 (albedo, temperature)")
    k_current: float = Field(3.0, gt=1, description="k3 of eq. 17")
    sun_norm: bool = Field(True, description="eq. 17 without attitude: lit panels must give a unit sun vector")
    spike_half_window: int = Field(5, ge=2, le=50, description="Hampel window half-width (samples)")
    k_spike: float = Field(6.0, gt=2, description="Hampel threshold in robust sigmas")
    stuck_min_run: int = Field(10, ge=3, description="equal consecutive samples that make a stuck run")
    time_grid_tolerance: float = Field(0.25, gt=0, lt=0.5, description="off-grid tolerance (fraction of period)")
    max_rate_deg_s: float = Field(5.7, gt=0, description="star tracker without gyro: largest plausible rate")
    star_tracker_error_arcsec: float = Field(10.0, gt=0, description="star-tracker noise for quaternion jumps")
    k_time_tag: float = Field(6.0, ge=0, description="GNSS time_tag: a time shift beyond k x dr/|v| (0: off)")
    transient_consistency: bool = Field(
        True, description="a gyro spike whose angle the star tracker sees too is a real transient, not rejected")


def _screening_params(p: Params) -> ScreeningParams:
    return ScreeningParams(
        gnss_position_error_m=p.gnss_position_error_m, gnss_velocity_error_m_s=p.gnss_velocity_error_m_s,
        k_energy=p.k_energy, energy_model=p.energy_model, energy_model_error_m2_s2=p.energy_model_error_m2_s2,
        k_plane=p.k_plane, k_kinematic=p.k_kinematic, k_velocity=p.k_velocity,
        magnetometer_error_nT=p.magnetometer_error_nT, field_model_error_nT=p.field_model_error_nT,
        k_field=p.k_field, current_error_a=p.current_error_a, current_model_error_a=p.current_model_error_a,
        k_current=p.k_current, sun_norm=p.sun_norm, spike_half_window=p.spike_half_window, k_spike=p.k_spike,
        stuck_min_run=p.stuck_min_run, time_grid_tolerance=p.time_grid_tolerance,
        max_rate_rad_s=float(np.deg2rad(p.max_rate_deg_s)),
        star_tracker_error_rad=float(np.deg2rad(p.star_tracker_error_arcsec / 3600.0)),
        k_time_tag=p.k_time_tag, transient_consistency=p.transient_consistency,
    )


def stream_map(func: Callable[[Any], Any], parts: Sequence[Any]) -> list[Any]:
    """The streams screened across the executor's workers (app.jobs.partitions), in the two passes of
    processing.screening.criteria.screen."""
    return map_partitions(func, parts, stage="streams")


def input_streams(params: Params) -> tuple[str, ...]:
    """The streams a run reads: every one by default; with ``streams``, those, GNSS (its accepted states give
    the position the other criteria need) and, for the star tracker, the gyro (the rate its jumps are judged
    with)."""
    if params.streams is None:
        return tuple(STREAMS)
    extra = ("gnss",) + (("gyro",) if "star_tracker" in params.streams else ())
    return tuple(dict.fromkeys([*params.streams, *extra]))


def run(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    present = [s for s in SCREENABLE if s in inputs.streams and len(inputs.streams[s]["time_tai_ns"])]
    selected = present if params.streams is None else [s for s in params.streams if s in present]
    if not selected:
        wanted: list[str] = list(params.streams or SCREENABLE)
        raise TaskError(f"none of the streams to screen ({', '.join(wanted)}) has samples in the window")
    notes: list[str] = []
    if params.streams is not None:
        absent = sorted(set(params.streams) - set(present))
        if absent:
            notes.append(f"no samples of {', '.join(absent)} in the window")
    reference = None
    frame = "ITRF"
    energy_reference = "robust linear fit of the window's own energy"
    orbit = inputs.reference.get("reference_orbit")
    if params.use_reference_orbit and orbit is not None:
        reference = orbit.columns
        frame = "ITRF" if orbit.details.get("earth_fixed", True) else "GCRF"
        energy_reference = f"reference orbit {orbit.name} ({orbit.details.get('frame', frame)})"
    nav_ref = inputs.reference.get("rinex_nav")
    progress(0.1, "screening")
    result = screen(inputs.streams, inputs.spacecraft, _screening_params(params), reference_orbit=reference,
                    reference_frame=frame, nav=None if nav_ref is None else nav_ref.columns, selected=selected,
                    mapper=stream_map)
    notes += result.notes
    progress(0.7, "flags table")
    crit = result.summary()
    total = int(sum(result.n_rows.values()))
    rejected = int(sum(int(result.rejected(s).sum()) for s in result.n_rows))
    summary: dict[str, Any] = {
        "streams": {s: {c: {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in d.items()}
                        for c, d in per.items()} for s, per in crit.items()},
        "n_total": total, "n_rejected": rejected, "rejected_fraction": rejected / total if total else 0.0,
        "energy_model": params.energy_model, "energy_reference": energy_reference,
        "navigation_data": None if nav_ref is None else nav_ref.name,
        "screened_streams": list(result.n_rows),
        "findings": result.findings,
    }
    warnings = _warnings(result.findings)
    tables = {"flags": flags_table(result, inputs.streams)}
    stat_rows: dict[str, list[Any]] = {k: [] for k in ("time_tai_ns", "stream", "criterion", "statistic",
                                                        "threshold", "flagged")}
    for c in result.criteria:
        if c.name not in STATISTIC_CRITERIA:
            continue
        rows = np.flatnonzero(c.applied)
        t = np.asarray(inputs.streams[c.stream]["time_tai_ns"], dtype=np.int64)[rows]
        if c.stream == "panel_currents" and c.name == "panel_sun_norm":  # one value per epoch
            t, first = np.unique(t, return_index=True)
            rows = rows[first]
        stat_rows["time_tai_ns"].append(t)
        stat_rows["stream"].append(np.full(rows.size, c.stream, dtype=object))
        stat_rows["criterion"].append(np.full(rows.size, c.name, dtype=object))
        stat_rows["statistic"].append(c.statistic[rows])
        stat_rows["threshold"].append(np.full(rows.size, c.threshold))
        stat_rows["flagged"].append(c.flagged[rows])
    if stat_rows["stream"]:
        tables["statistics"] = {k: np.concatenate(v) for k, v in stat_rows.items()}
    progress(0.9, "done")
    return TaskResult(summary=summary, tables=tables, notes=notes, warnings=warnings)


def _warnings(findings: dict[str, Any]) -> list[ResultWarning]:
    """GNSS states whose tags are off by a time shift (``time_offset``, with the estimated offset)."""
    out = []
    for f in findings.get("gnss_time_tags", []):
        tau = f["offset_s_median"]
        out.append(ResultWarning(
            "time_offset",
            f"{f['n_states']} GNSS states in {f['n_runs']} runs are time-tagged {abs(tau):.3g} s "
            f"{'late' if tau > 0 else 'early'} (median; {f['offset_s_min']:.3g} to {f['offset_s_max']:.3g} s): their "
            "positions and velocities are those of the orbit {:.3g} s {}; they are rejected by the time_tag "
            "criterion (not their neighbours): correct the receiver's time tags at the source".format(
                abs(tau), "earlier" if tau > 0 else "later"),
            {"stream": "gnss", **f}))
    return out


def _rejected_by(reasons: np.ndarray, criterion: str) -> np.ndarray:
    """Rows whose ';'-joined reasons name ``criterion``.

    Only the rows with a reason are searched (an empty one names no criterion): the string operations run on
    the rejected samples, not on every row of the flags table."""
    text = reasons.astype(str, copy=False)
    out = np.zeros(text.shape, dtype=bool)
    named = np.flatnonzero(text != "")
    out[named] = np.char.find(np.char.add(np.char.add(";", text[named]), ";"), f";{criterion};") >= 0
    return out


def _timeline(result: TaskResult, t0: int) -> Figure:
    """One row per stream (every rejected sample once) and one per stream and criterion."""
    flags = result.tables["flags"]
    t_all = np.asarray(flags["time_tai_ns"], dtype=np.int64)
    reasons = np.asarray(flags["reasons"]).astype(str)
    streams = np.asarray(flags["stream"]).astype(str)
    rejected = ~np.asarray(flags["accepted"], dtype=bool)
    rows: list[tuple[str, np.ndarray, str]] = []  # label, selection, colour
    for s, per in result.summary["streams"].items():
        n_any = int(per.get("any", {}).get("n_rejected", 0))
        if n_any == 0:
            continue
        rows.append((f"{s}: any criterion ({n_any})", (streams == s) & rejected, "k"))
        for c, d in per.items():
            if c != "any" and d["n_rejected"] > 0:
                rows.append((f"{s} / {c} ({d['n_rejected']})", (streams == s) & _rejected_by(reasons, c), "tab:red"))
    n_rej, n_tot = int(result.summary["n_rejected"]), int(result.summary["n_total"])
    fig = Figure(figsize=(10, 1.4 + 0.32 * max(1, len(rows))), layout="constrained",
                 label="Rejected samples by stream and criterion")
    ax = fig.add_subplot()
    for i, (_label, sel, colour) in enumerate(rows):
        ax.plot((t_all[sel] - t0) / NS_PER_S / 60.0, np.full(int(sel.sum()), len(rows) - 1 - i), "|", color=colour,
                ms=10, gid=_label)
    ax.set_yticks(range(len(rows)), [r[0] for r in reversed(rows)], fontsize=8)
    ax.set_ylim(-0.7, max(1, len(rows)) - 0.3)
    span_min = float(t_all.max() - t0) / NS_PER_S / 60.0
    ax.set_xlim(-0.02 * span_min, 1.02 * span_min)  # the whole screened window, not just the rejections
    ax.set_xlabel(f"minutes since {_iso_utc(t0)}")
    ax.set_title(f"Rejected samples: {n_rej:,} of {n_tot:,} (each mark is one sample; a sample may fail several "
                 "criteria)", fontsize=10)
    ax.grid(axis="x", alpha=0.3)
    return fig


CRITERION_LABELS = {"energy": "|h - h_ref| [m²/s²]\n(eq. 15)", "field_magnitude": "| |H| - |H_model| | [nT]\n(eq. 16)",
                    "panel_eclipse": "I - ν I_max [A]\n(eq. 17, shadow)", "panel_sun_norm": "| |s| - 1 |\n(eq. 17)",
                    "orbit_plane": "orbit-normal\ndeviation [rad]", "velocity": "|v - v_fit| [m/s]"}


def _criteria(stats: dict[str, Any], t0: int) -> Figure:
    crit_col = np.asarray(stats["criterion"]).astype(str)
    crits = [c for c in STATISTIC_CRITERIA if np.any(crit_col == c)]
    fig = Figure(figsize=(10, 2.2 * len(crits) + 0.6), layout="constrained",
                 label="Criteria of 002 eqs. 15-17 against time")
    axes = fig.subplots(len(crits), 1, sharex=True, squeeze=False)[:, 0]
    for i, (ax, c) in enumerate(zip(axes, crits, strict=True)):
        sel = crit_col == c
        t = (np.asarray(stats["time_tai_ns"], np.int64)[sel] - t0) / NS_PER_S / 60.0
        y = np.asarray(stats["statistic"], float)[sel]
        f = np.asarray(stats["flagged"], bool)[sel]
        th = float(np.nanmax(np.asarray(stats["threshold"], float)[sel]))
        log = c != "panel_eclipse" and np.isfinite(th) and th > 0
        if log:  # magnitudes (>= 0) on a log axis; the few below th/1e4 are drawn on its floor
            floor = th * 1e-4
            y = np.where(np.isfinite(y), np.maximum(y, floor), y)
            ax.set_yscale("log")
        ax.plot(t[~f], y[~f], ".", ms=2, color="tab:blue", label="accepted")
        ax.plot(t[f], y[f], "x", ms=5, color="tab:red", label="rejected")
        if np.isfinite(th):
            ax.axhline(th, color="k", lw=0.8, ls="--", label="threshold")
        if log:
            ax.set_ylim(bottom=max(floor / 2.0, ax.get_ylim()[0]))
        ax.set_ylabel(CRITERION_LABELS.get(c, c), fontsize=8)
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(fontsize=7, loc="upper right", ncols=3)
    axes[-1].set_xlabel(f"minutes since {_iso_utc(t0)}")
    return fig


def _iso_utc(t_tai_ns: int) -> str:
    from processing.time import timescales

    return str(timescales.tai_ns_to_iso(np.array([t_tai_ns], dtype=np.int64))[0])


def figures(result: TaskResult, params: Params) -> dict[str, Figure]:
    flags = result.tables.get("flags")
    out: dict[str, Figure] = {}
    if flags is None or len(flags["time_tai_ns"]) == 0:
        return out
    t0 = int(np.asarray(flags["time_tai_ns"], dtype=np.int64).min())
    out["flags_timeline"] = _timeline(result, t0)
    stats = result.tables.get("statistics")
    if stats is not None and len(stats["time_tai_ns"]):
        out["criteria"] = _criteria(stats, t0)
    return out


def figure_names(summary: Mapping[str, Any], rows: Mapping[str, int]) -> list[str]:
    """The names :func:`figures` gives (from the tables' row counts)."""
    if not rows.get("flags"):
        return []
    return ["flags_timeline", *(["criteria"] if rows.get("statistics") else [])]


JOB = JobType(
    name="data_screening", title="Telemetry screening (002 eqs. 15-17)", paper="002 eqs. 15-17", params=Params,
    run=run, any_stream=True, input_streams=input_streams, figures=figures, figure_names=figure_names,
    reference=("rinex_nav", "reference_orbit"),
    description="Flags every sample of GNSS, magnetometer, panel-current, visibility and other streams with the "
                "criteria it fails: energy integral (eq. 15, J2-aware), field magnitude against IGRF-14 (eq. 16), "
                "panel currents against the shadow/unit-sun models (eq. 17), orbit plane, kinematic and velocity "
                "consistency, spikes, stuck values and time-grid errors. Nothing is deleted.",
    headline=(Answer("n_rejected", "Rejected samples, all streams"),
              Answer("rejected_fraction", "Rejected share of the samples", unit="%", scale=100.0),
              Answer("streams.*.any.n_rejected", "Rejected samples per stream")),
)
