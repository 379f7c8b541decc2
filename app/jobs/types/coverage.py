"""Job ``telemetry_coverage``: per stream and sensor, sample counts, sampling period and gaps."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure
from pydantic import BaseModel, ConfigDict, Field

from app.jobs.registry import JobType, always
from app.reports.headline import Answer
from processing.screening.coverage import find_gaps
from processing.tasks import Progress, TaskInputs, TaskResult
from processing.units import NS_PER_S

GAPS_IN_SUMMARY = 10
"""Gaps listed per stream in the summary (the ``gaps`` table has every gap): GET /jobs/{id} stays small."""


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    gap_factor: float = Field(1.5, gt=1.0, le=100.0,
                              description="an interval longer than gap_factor x the nominal period is a gap")


def run(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    streams: list[dict[str, Any]] = []
    gap_rows: dict[str, list[Any]] = {k: [] for k in ("stream", "sensor", "before_tai_ns", "after_tai_ns",
                                                      "duration_s", "missing")}
    names = sorted(inputs.streams)
    for i, name in enumerate(names):
        progress(0.05 + 0.8 * i / max(1, len(names)), f"gaps of {name}")
        cols = inputs.streams[name]
        sensors = np.asarray(cols["sensor"], dtype=object).astype(str)
        t_all = np.asarray(cols["time_tai_ns"], dtype=np.int64)
        for sensor in sorted(set(sensors.tolist())):
            t = np.unique(t_all[sensors == sensor])  # several rows per time (panels, satellites) count once
            entry: dict[str, Any] = {
                "stream": name, "sensor": sensor, "n_samples": int(np.sum(sensors == sensor)),
                "n_epochs": int(t.size), "first_tai_ns": int(t[0]), "last_tai_ns": int(t[-1]),
                "leading_s": (int(t[0]) - inputs.start_tai_ns) / NS_PER_S,
                "trailing_s": (inputs.end_tai_ns - int(t[-1])) / NS_PER_S,
            }
            if t.size >= 2:
                gaps = find_gaps(t, factor=params.gap_factor)
                expected = (int(t[-1]) - int(t[0])) / gaps.nominal_period_ns + 1
                entry.update(
                    period_s=gaps.nominal_period_ns / NS_PER_S, n_gaps=gaps.count,
                    gap_total_s=float(gaps.duration_ns.sum()) / NS_PER_S, missing_samples=int(gaps.missing.sum()),
                    completeness=float(t.size / expected),
                    longest_gap_s=float(gaps.duration_ns.max()) / NS_PER_S if gaps.count else 0.0,
                    gaps=[{"before_tai_ns": int(b), "after_tai_ns": int(a), "duration_s": (a - b) / NS_PER_S,
                           "missing": int(m)}
                          for b, a, m in zip(gaps.before_tai_ns[:GAPS_IN_SUMMARY], gaps.after_tai_ns[:GAPS_IN_SUMMARY],
                                             gaps.missing[:GAPS_IN_SUMMARY], strict=True)],
                    gaps_listed=min(gaps.count, GAPS_IN_SUMMARY),
                )
                gap_rows["stream"] += [name] * gaps.count
                gap_rows["sensor"] += [sensor] * gaps.count
                gap_rows["before_tai_ns"] += gaps.before_tai_ns.tolist()
                gap_rows["after_tai_ns"] += gaps.after_tai_ns.tolist()
                gap_rows["duration_s"] += (gaps.duration_ns / NS_PER_S).tolist()
                gap_rows["missing"] += gaps.missing.tolist()
            else:
                entry.update(period_s=None, n_gaps=0, gap_total_s=0.0, missing_samples=0, completeness=None,
                             longest_gap_s=0.0, gaps=[], gaps_listed=0)
            streams.append(entry)
    summary = {
        "window_start_tai_ns": inputs.start_tai_ns, "window_end_tai_ns": inputs.end_tai_ns,
        "gap_factor": params.gap_factor, "n_streams": len(names),
        "n_gaps": int(sum(s["n_gaps"] for s in streams)), "streams": streams,
        "gaps_in_summary": f"the first {GAPS_IN_SUMMARY} gaps per stream; every gap is in the gaps table",
    }
    cov = {"stream": [s["stream"] for s in streams], "sensor": [s["sensor"] for s in streams],
           "n_samples": [s["n_samples"] for s in streams], "period_s": [s["period_s"] for s in streams],
           "n_gaps": [s["n_gaps"] for s in streams], "completeness": [s["completeness"] for s in streams]}
    tables = {"coverage": {k: np.asarray(v, dtype=object if k in ("stream", "sensor") else float)
                           for k, v in cov.items()},
              "gaps": {"time_tai_ns": np.asarray(gap_rows["before_tai_ns"], dtype=np.int64),
                       **{k: np.asarray(v) for k, v in gap_rows.items() if k != "before_tai_ns"}}}
    if not gap_rows["stream"]:
        tables["gaps"] = {"time_tai_ns": np.zeros(0, np.int64), "stream": np.zeros(0, object),
                          "sensor": np.zeros(0, object), "after_tai_ns": np.zeros(0, np.int64),
                          "duration_s": np.zeros(0), "missing": np.zeros(0, np.int64)}
    return TaskResult(summary=summary, tables=tables)


def figures(result: TaskResult, params: Params) -> dict[str, Figure]:
    streams = result.summary["streams"]
    fig = Figure(figsize=(9, 0.5 + 0.45 * max(1, len(streams))), label="Telemetry coverage and gaps")
    ax = fig.add_subplot()
    t0 = result.summary["window_start_tai_ns"]
    gaps = result.tables.get("gaps", {})
    g_stream = np.asarray(gaps.get("stream", []), dtype=object).astype(str)
    g_sensor = np.asarray(gaps.get("sensor", []), dtype=object).astype(str)
    g_start = np.asarray(gaps.get("time_tai_ns", []), dtype=np.int64)
    g_dur = np.asarray(gaps.get("duration_s", []), dtype=float)
    for i, s in enumerate(streams):
        span = ((s["first_tai_ns"] - t0) / NS_PER_S, (s["last_tai_ns"] - s["first_tai_ns"]) / NS_PER_S)
        ax.broken_barh([span], (i - 0.3, 0.6),
                       color="tab:green")
        sel = (g_stream == s["stream"]) & (g_sensor == s["sensor"])
        if np.any(sel):
            ax.broken_barh(list(zip(((g_start[sel] - t0) / NS_PER_S).tolist(), g_dur[sel].tolist(), strict=True)),
                           (i - 0.3, 0.6), color="tab:red")
    ax.set_yticks(range(len(streams)), [f"{s['stream']} / {s['sensor']}" for s in streams])
    ax.set_xlabel("time since window start [s]")
    ax.set_title("Coverage (green) and gaps (red)")
    ax.grid(axis="x", alpha=0.3)
    return {"coverage": fig}


JOB = JobType(
    name="telemetry_coverage", title="Telemetry coverage and gaps", paper="", params=Params, run=run,
    any_stream=True, figures=figures, figure_names=always("coverage"),
    description="Per stream and sensor: samples, nominal period, gaps (last sample before, first after, "
                "missing samples) and completeness over the window.",
    headline=(Answer("n_gaps", "Gaps in the window"), Answer("n_streams", "Streams with samples")),
)
