"""Job ``reconstruction``: a pipeline of the registered analysis jobs on one window, one report.

Stages, in order, each the ``run`` of its registered job type (those not registered are left out and
named in the notes): data_screening -> star_tracker_accuracy -> gyro_bias_fit -> orbital_attitude ->
alignment_calibration (the last only "where configured": the configuration has a gyro and a star
tracker, or ``calibrate_alignment`` is true). A stage whose streams are missing from the window, or whose arc
lacks what :data:`ARC_REQUIREMENTS` asks (alignment_calibration: rate excitation), is skipped with the reason.

What flows between stages:

- **screened data**: when data_screening succeeded, the samples its ``flags`` table rejects are removed
  from the inputs of every later stage, by the runner's own mechanism
  (:func:`processing.screening.flags.filter_streams`), except rejected gyro rates, which are bridged by
  interpolating their accepted neighbours (``gyro_rejections="bridge"``, holes up to ``max_bridge_s``) so
  that rejections do not become gaps that break the gyro fits (counted as ``gyro_bridged``);
- **calibrations**: when gyro_bias_fit succeeded, its body-frame bias (``w_meas = w_true + b``) is
  removed from the gyro rates given to orbital_attitude (``w_G - R(q_BG)^T b_B``); alignment_calibration
  gets the screened but uncorrected rates, since it estimates the drift itself. The values used are
  listed under ``calibrations`` in the summary.

After data_screening the stages run in two branches side by side (:data:`BRANCHES`, ``parallel_stages``):
star_tracker_accuracy in one, gyro_bias_fit -> orbital_attitude -> alignment_calibration in the other, as
threads of the worker or as tasks of the Dask cluster (app.jobs.partitions.map_concurrent). The result is
assembled in pipeline order, so it is the same as when the stages run one after the other.

Progress is weighted by the stages' typical cost; a stage that fails with a task error ends the
pipeline (the first such stage in pipeline order; or, with ``continue_on_error``, is recorded and the next
stage runs); any other exception is an internal error and goes to the runner. The summary has every
stage's own summary under ``stages.<name>.summary``; tables, files and figures keep their names, prefixed with
the stage (``gyro_bias_fit__residuals.csv``), so the standard job report is the combined report.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from app.jobs.partitions import map_concurrent
from app.jobs.registry import JobType
from app.jobs.types.reconstruction_flow import apply_screening, bias_from, correct_gyro_bias
from processing.streams import STREAMS
from processing.tasks import Progress, ResultWarning, TaskError, TaskInputs, TaskResult

STAGES: tuple[tuple[str, float], ...] = (  # (job type, relative cost for the progress bar)
    ("data_screening", 1.0),
    ("star_tracker_accuracy", 2.0),
    ("gyro_bias_fit", 3.0),
    ("orbital_attitude", 1.0),
    ("alignment_calibration", 2.0),
)
STAGE_NAMES = tuple(name for name, _ in STAGES)
SEPARATOR = "__"
PROGRESS_SPAN = (0.05, 0.88)  # the runner reports 0.05 before the task and 0.9 after it
BIAS_CORRECTED_STAGES = ("orbital_attitude",)


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    stages: list[str] | None = Field(None, description=f"stages to run, in pipeline order; default: every "
                                                       f"registered one of {', '.join(STAGE_NAMES)}")
    stage_params: dict[str, dict[str, Any]] = Field(default_factory=dict,
                                                    description="parameters of each stage's job type")
    calibrate_alignment: bool | None = Field(None, description="run alignment_calibration; default: when the "
                                                               "configuration has a gyro and a star tracker")
    apply_screening: bool = Field(True, description="drop the samples data_screening rejects from later stages")
    gyro_rejections: Literal["bridge", "drop"] = Field(
        "bridge", description="rejected gyro rates: bridge = replaced by linear interpolation of the accepted "
                              "neighbours where the hole is at most max_bridge_s (dropping them would open gaps "
                              "in the integrated rates that break the gyro fits), drop = removed like the others")
    max_bridge_s: float = Field(5.0, gt=0.0, le=60.0, description="longest hole of rejected gyro samples bridged")
    apply_gyro_bias: bool = Field(True, description="remove the fitted gyro bias from the rates of "
                                                    "orbital_attitude")
    continue_on_error: bool = Field(False, description="record a failing stage and go on with the next")
    parallel_stages: bool = Field(True, description=(
        "run the branches of the pipeline that depend only on the screened data (star_tracker_accuracy; "
        "gyro_bias_fit -> orbital_attitude -> alignment_calibration) side by side: threads of the worker, or "
        "tasks of the Dask cluster; the result is the same as in order (false)"))
    min_alignment_rate_variation_deg_s: float = Field(
        0.01, ge=0.0, le=10.0, description=(
            "alignment_calibration runs only when the body rate (60-s means) varies by at least this much (std "
            "about its mean, on some axis): a constant rate cannot be told from gyro drift, so the arc cannot "
            "determine a misalignment and no calibration would be stored (0: always run)"))

    @field_validator("stage_params")
    @classmethod
    def _stages_known_and_valid(cls, value: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
        """Each stage's parameters checked against its job type's Params at submission (not only when the
        pipeline reaches the stage), and stored as that model's validated values."""
        unknown = sorted(set(value) - set(STAGE_NAMES))
        if unknown:
            raise ValueError(f"unknown stages {unknown}; stages: {', '.join(STAGE_NAMES)}")
        available = _available()
        out = {}
        for name, given in value.items():
            jt = available.get(name)
            if jt is None:  # not installed here: the pipeline notes it and leaves the stage out
                out[name] = given
                continue
            try:
                out[name] = jt.params.model_validate(given).model_dump(mode="json")
            except ValidationError as exc:
                problems = "; ".join(f"{'.'.join(map(str, e['loc'])) or name}: {e['msg']}" for e in exc.errors())
                raise ValueError(f"{name}: {problems}") from None
        return out


def _available() -> dict[str, JobType]:
    from app.jobs.registry import registry

    jobs = registry()
    return {name: jobs[name] for name in STAGE_NAMES if name in jobs}


def _stage_params(available: Mapping[str, JobType], params: Params) -> dict[str, BaseModel]:
    unknown = sorted(set(params.stage_params) - set(STAGE_NAMES))
    if unknown:
        raise TaskError(f"stage_params for unknown stages {unknown}; stages: {', '.join(STAGE_NAMES)}")
    out = {}
    for name, jt in available.items():
        try:
            out[name] = jt.params.model_validate(params.stage_params.get(name, {}))
        except ValidationError as exc:
            raise TaskError(f"stage_params.{name}: {exc}") from None
    return out


def plan(inputs: TaskInputs, params: Params, available: Mapping[str, JobType]) -> tuple[list[str], list[str]]:
    """The stages to run and notes on those left out."""
    notes = []
    wanted = list(STAGE_NAMES) if params.stages is None else params.stages
    bad = [s for s in wanted if s not in STAGE_NAMES]
    if bad:
        raise TaskError(f"unknown stages {bad}; stages: {', '.join(STAGE_NAMES)}")
    missing = [s for s in wanted if s not in available]
    if missing:
        notes.append(f"stages not available in this installation: {', '.join(missing)}")
    calibrate = params.calibrate_alignment
    if calibrate is None:
        calibrate = inputs.spacecraft.has_gyro and bool(inputs.spacecraft.star_trackers)
        if not calibrate and "alignment_calibration" in available and params.stages is None:
            notes.append("alignment_calibration skipped: the configuration has no gyro and star tracker pair")
    order = [s for s in STAGE_NAMES if s in wanted and s in available
             and (s != "alignment_calibration" or calibrate)]
    if not order:
        raise TaskError("no pipeline stage can run: " + (notes[0] if notes else "none selected"))
    return order, notes


def _stage_inputs(inputs: TaskInputs, streams: Mapping[str, Mapping[str, NDArray[Any]]],
                  jt: JobType) -> TaskInputs | str:
    """The stage's view of the window, or why it cannot run."""
    names = tuple(STREAMS) if jt.any_stream else jt.streams + jt.optional_streams
    present = {n: streams[n] for n in names if n in streams and len(streams[n]["time_tai_ns"])}
    missing = [s for s in jt.streams if s not in present]
    if missing:
        return f"no {', '.join(missing)} samples in the window"
    if jt.any_stream and not present:
        return "no telemetry in the window"
    reference = {k: v for k, v in inputs.reference.items() if k in jt.reference}
    return TaskInputs(streams=present, spacecraft=inputs.spacecraft, start_tai_ns=inputs.start_tai_ns,
                      end_tai_ns=inputs.end_tai_ns, reference=reference)


RATE_VARIATION_WINDOW_S = 60.0


def _alignment_excited(inputs: TaskInputs, min_variation_deg_s: float) -> TaskInputs | str:
    """The inputs, or why the arc cannot calibrate the alignment: the std of the 60-s mean gyro rates about
    their mean, per axis, below min_variation_deg_s on every axis (a constant rate is indistinguishable from
    drift; 000 needs slews or scans)."""
    if min_variation_deg_s <= 0 or "gyro" not in inputs.streams:
        return inputs
    g = inputs.streams["gyro"]
    t = np.asarray(g["time_tai_ns"], dtype=np.int64)
    if t.size < 3:
        return inputs
    w = np.stack([np.asarray(g[c], dtype=np.float64) for c in ("wx", "wy", "wz")], axis=1)
    bins = (t - t[0]) // int(RATE_VARIATION_WINDOW_S * 1e9)
    _, index, counts = np.unique(bins, return_inverse=True, return_counts=True)
    means = np.zeros((counts.size, 3))
    np.add.at(means, index, w)
    means /= counts[:, None]
    variation = np.degrees(means.std(axis=0)) if counts.size > 1 else np.zeros(3)
    if np.all(variation < min_variation_deg_s):
        return (f"the body rate hardly varies over the arc (std of the {RATE_VARIATION_WINDOW_S:.0f}-s mean gyro "
                f"rates {', '.join(f'{v:.4f}' for v in variation)} deg/s about x, y, z, all below "
                f"min_alignment_rate_variation_deg_s = {min_variation_deg_s}): a constant rate cannot be told "
                "from gyro drift, so no misalignment or calibration would come of it; run alignment_calibration "
                "on an arc with slews or scans")
    return inputs


ArcCheck = Callable[[TaskInputs, Params], TaskInputs | str]
ARC_REQUIREMENTS: dict[str, tuple[ArcCheck, ...]] = {
    "alignment_calibration": (lambda inputs, params: _alignment_excited(inputs,
                                                                       params.min_alignment_rate_variation_deg_s),),
}
"""What each stage needs the arc to offer beyond its streams (those are checked by :func:`_stage_inputs`):
checks run in order on the stage's inputs, each giving them back or the reason the stage is skipped (recorded
as ``stages.<name>.status = "skipped"`` with that reason, and a note)."""


@dataclass
class _Outcome:
    """One stage's part of the pipeline result: its ``stages`` entry, its result when it ran, the notes it
    adds (in order) and the calibrations it passes on."""

    name: str
    record: dict[str, Any]
    result: TaskResult | None = None
    notes: list[str] = field(default_factory=list)
    calibrations: dict[str, Any] = field(default_factory=dict)

    @property
    def stops(self) -> bool:
        """A failed stage that ends the pipeline (``continue_on_error`` false)."""
        return "stop" in self.record


@dataclass(frozen=True)
class _Branch:
    """Stages that run one after the other on the same screened streams (a branch of the pipeline)."""

    names: tuple[str, ...]
    inputs: TaskInputs
    streams: dict[str, dict[str, NDArray[Any]]]
    params: Params
    stage_params: dict[str, BaseModel]
    order: tuple[str, ...]


def _run_stage(name: str, jt: JobType, inputs: TaskInputs, view: Mapping[str, Mapping[str, NDArray[Any]]],
               params: Params, stage_params: BaseModel, progress: Progress) -> _Outcome:
    """The stage on its view of the window: skipped with the reason, failed (a TaskError; ``record["stop"]``
    when the pipeline must end) or succeeded with its result."""
    stage_inputs = _stage_inputs(inputs, view, jt)
    for arc_check in ARC_REQUIREMENTS.get(name, ()):
        if not isinstance(stage_inputs, str):
            stage_inputs = arc_check(stage_inputs, params)
    if isinstance(stage_inputs, str):
        progress(1.0, "skipped")
        return _Outcome(name, {"status": "skipped", "reason": stage_inputs}, notes=[f"{name} skipped: {stage_inputs}"])
    progress(0.0, "starting")
    try:
        result = jt.run(stage_inputs, stage_params, progress)
    except TaskError as exc:  # JobCancelled and crashes (a ValueError included) propagate to the runner
        record: dict[str, Any] = {"status": "failed", "error": str(exc) or type(exc).__name__}
        if not params.continue_on_error:
            return _Outcome(name, {**record, "stop": f"pipeline stage {name} failed: {exc}"})
        return _Outcome(name, record, notes=[f"{name} failed: {exc}"])
    progress(1.0, "done")
    record = {"status": "succeeded",
              "summary": {"warnings": [w.as_dict() for w in result.warnings], **result.summary},
              "notes": list(result.notes), "params": stage_params.model_dump(mode="json")}
    return _Outcome(name, record, result, notes=[f"{name}: {n}" for n in result.notes])


def _run_branch(branch: _Branch, progress: Progress) -> list[_Outcome]:
    """The branch's stages in order (module level: a Dask task runs it). gyro_bias_fit's bias is removed from
    the rates of the later stages of :data:`BIAS_CORRECTED_STAGES`; a stage that must end the pipeline ends
    the branch."""
    available = _available()
    bias_free: dict[str, NDArray[Any]] | None = None
    out: list[_Outcome] = []
    for name in branch.names:
        view: Mapping[str, Mapping[str, NDArray[Any]]] = branch.streams
        if name in BIAS_CORRECTED_STAGES and bias_free is not None:
            view = {**branch.streams, "gyro": bias_free}

        def stage_progress(fraction: float, stage: str, _name: str = name) -> None:
            progress(fraction, f"{_name}: {stage}")

        outcome = _run_stage(name, available[name], branch.inputs, view, branch.params, branch.stage_params[name],
                             stage_progress)
        out.append(outcome)
        if outcome.stops:
            break
        if (name == "gyro_bias_fit" and outcome.result is not None and branch.params.apply_gyro_bias
                and "gyro" in branch.streams):
            bias = bias_from(outcome.result.summary)
            if bias is not None:
                bias_free = correct_gyro_bias(branch.streams["gyro"], bias, branch.inputs.spacecraft)
                outcome.calibrations = {"gyro_bias_rad_s": bias.tolist(), "gyro_bias_applied_to": [
                    s for s in BIAS_CORRECTED_STAGES if s in branch.order]}
    return out


BRANCHES: tuple[tuple[str, ...], ...] = (
    ("star_tracker_accuracy",),
    ("gyro_bias_fit", "orbital_attitude", "alignment_calibration"),
)
"""The stages after data_screening, in branches that depend on nothing but the screened streams: each branch
runs its stages in order (orbital_attitude needs gyro_bias_fit's bias), the branches side by side
(``parallel_stages``). Every stage of :data:`STAGES` but data_screening is in exactly one branch."""


class _Meter:
    """The pipeline's progress from its stages' own fractions, weighted by :data:`STAGES`' costs; safe to call
    from the threads of concurrent branches (the bar moves by the sum, the message is the latest)."""

    def __init__(self, progress: Progress, order: Sequence[str]) -> None:
        self.progress = progress
        self.weights = {s: dict(STAGES)[s] for s in order}
        self.total = sum(self.weights.values())
        self.fractions = dict.fromkeys(order, 0.0)
        self.label = "starting"
        self.lock = threading.Lock()

    def overall(self) -> float:
        lo, hi = PROGRESS_SPAN
        return lo + (hi - lo) * sum(self.weights[s] * f for s, f in self.fractions.items()) / self.total

    def stage(self, name: str) -> Progress:
        def report(fraction: float, label: str) -> None:
            fraction = min(max(fraction, 0.0), 1.0) if math.isfinite(fraction) else 0.0
            with self.lock:  # held while reporting, so that the values reported never go back
                self.fractions[name] = max(self.fractions[name], fraction)
                self.label = label
                self.progress(self.overall(), label)
        return report

    def again(self) -> None:
        """The latest value and message once more, so that the runner's callback checks for a cancel."""
        with self.lock:
            self.progress(self.overall(), self.label)

    def branch(self, names: Sequence[str]) -> Progress:
        """A branch's callback: the stage is the prefix of the label (``<stage>: <what>``); a label without one
        is the whole branch's (a Dask task's start and end, reported by the job's thread), shown as
        ``<stage> -> <stage>: <what>``."""
        def report(fraction: float, label: str) -> None:
            name = label.split(":", 1)[0]
            if name in self.weights:
                self.stage(name)(fraction, label)
                return
            with self.lock:
                for s in names[:-1]:
                    self.fractions[s] = max(self.fractions[s], fraction)
            self.stage(names[-1])(fraction, f"{' -> '.join(names)}: {label}")
        return report


def run(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    available = _available()
    order, notes = plan(inputs, params, available)
    stage_params = _stage_params(available, params)
    meter = _Meter(progress, order)
    streams: dict[str, dict[str, NDArray[Any]]] = {k: dict(v) for k, v in inputs.streams.items()}
    outcomes: list[_Outcome] = []
    if "data_screening" in order:
        screening = _run_stage("data_screening", available["data_screening"], inputs, streams, params,
                               stage_params["data_screening"],
                               lambda f, label: meter.stage("data_screening")(f, f"data_screening: {label}"))
        outcomes.append(screening)
        if screening.result is not None and params.apply_screening:
            streams, removed = apply_screening(
                streams, screening.result,
                bridge_gyro_s=params.max_bridge_s if params.gyro_rejections == "bridge" else None)
            screening.calibrations = {"screened_out": removed}
            if not removed:
                screening.notes.append("data_screening rejected no samples (or its flags were not understood)")
    if not (outcomes and outcomes[0].stops):
        context = replace(inputs, streams={})  # the branches take the screened streams, not the raw ones again
        branches = [_Branch(tuple(s for s in names if s in order), context, streams, params, stage_params,
                            tuple(order)) for names in BRANCHES]
        branches = [b for b in branches if b.names]
        if params.parallel_stages:
            for branch_outcomes in map_concurrent(_run_branch, branches, [meter.branch(b.names) for b in branches],
                                                  poll=lambda done: meter.again()):
                outcomes += branch_outcomes
        else:
            for b in branches:
                outcomes += _run_branch(b, meter.branch(b.names))
    return _merge(outcomes, order, notes)


def _merge(outcomes: Sequence[_Outcome], order: Sequence[str], notes: list[str]) -> TaskResult:
    """The pipeline's result from its stages' outcomes, taken in pipeline order (so the same whichever ran
    first): a stage that must end the pipeline raises its TaskError, as a serial run would have."""
    by_name = {o.name: o for o in outcomes}
    stages: dict[str, dict[str, Any]] = {}
    calibrations: dict[str, Any] = {}
    tables: dict[str, dict[str, NDArray[Any]]] = {}
    files: dict[str, tuple[bytes, str]] = {}
    warnings: list[ResultWarning] = []
    for name in order:
        o = by_name.get(name)
        if o is None:
            continue
        if o.stops:
            raise TaskError(o.record["stop"])
        stages[name] = o.record
        notes.extend(o.notes)
        calibrations.update(o.calibrations)
        if o.result is None:
            continue
        warnings += [ResultWarning(w.code, f"{name}: {w.message}", {**w.evidence, "stage": name})
                     for w in o.result.warnings]
        for table_name, columns in o.result.tables.items():
            tables[f"{name}{SEPARATOR}{table_name}"] = columns
        for file_name, content in o.result.files.items():
            files[f"{name}{SEPARATOR}{file_name}"] = content
    summary: dict[str, Any] = {
        "stages_run": [s for s in order if stages.get(s, {}).get("status") == "succeeded"],
        "stages": stages,
        "calibrations": calibrations,
    }
    return TaskResult(summary=summary, tables=tables, notes=notes, files=files, warnings=warnings)


def figures(result: TaskResult, params: Params) -> dict[str, Figure]:
    """Each succeeded stage's figures, named ``<stage>__<figure>``."""
    available = _available()
    out: dict[str, Figure] = {}
    for name, stage in result.summary.get("stages", {}).items():
        jt = available.get(name)
        if jt is None or stage.get("status") != "succeeded":
            continue
        prefix = f"{name}{SEPARATOR}"
        stage_result = TaskResult(summary=stage["summary"], notes=stage.get("notes", []),
                                  tables={k[len(prefix):]: v for k, v in result.tables.items() if k.startswith(prefix)},
                                  files={k[len(prefix):]: v for k, v in result.files.items() if k.startswith(prefix)})
        stage_params = jt.params.model_validate(stage.get("params", {}))
        for fig_name, fig in jt.figures(stage_result, stage_params).items():
            out[f"{prefix}{fig_name}"] = fig
    return out


def figure_names(summary: Mapping[str, Any], rows: Mapping[str, int]) -> list[str] | None:
    """The names :func:`figures` gives: each succeeded stage's own ``figure_names``, prefixed; None when a stage's
    are not known without drawing."""
    available = _available()
    out: list[str] = []
    for name, stage in (summary.get("stages") or {}).items():
        jt = available.get(name)
        if jt is None or not isinstance(stage, Mapping) or stage.get("status") != "succeeded":
            continue
        prefix = f"{name}{SEPARATOR}"
        names = jt.names_of_figures(stage.get("summary") or {},
                                    {k[len(prefix):]: n for k, n in rows.items() if k.startswith(prefix)})
        if names is None:
            return None
        out += [prefix + n for n in names]
    return out


JOB = JobType(
    name="reconstruction", title="Attitude reconstruction pipeline", paper="002, 003, 000", params=Params, run=run,
    any_stream=True, figures=figures, figure_names=figure_names,
    description="Screening -> star-tracker accuracy -> gyro fit -> orbital attitude (-> alignment calibration) on "
                "one window, passing screened data and the gyro bias along; one combined report.",
    headline=(),  # each stage's own headline (app.reports.job_report)
)
