"""Job reports: a JSON document, a self-contained HTML page (figures inline) and its PDF.

Figures the job makes on request (``ATTITUDE_FIGURES=lazy``, app.services.figures) are drawn and stored when the
HTML or PDF report is built, so the report shows every figure as when the job drew them; the JSON lists them.

One report per job, generic over job types: what was processed (spacecraft, sensors, window, sample
counts, gaps), with which settings (parameters, reference data, configuration and software versions),
the summary laid out by :mod:`app.reports.summary`, pass/fail against the spacecraft's specification
limits (:mod:`app.reports.specs`), sections the job type contributes (:mod:`app.reports.sections`),
figures and tables; and how to reproduce it (the exact job request and input window).
"""

from __future__ import annotations

import base64
import io
import json
import urllib.parse
from dataclasses import replace
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
from jinja2 import Environment, FileSystemLoader, select_autoescape
from sqlalchemy import select
from sqlalchemy.orm import Session, object_session

from app.jobs.registry import JobType, registry
from app.jobs.runner import CALIBRATION_PREFIX, SCREENING_KEY, stream_names
from app.reports import headline as headlib
from app.reports import specs as speclib
from app.reports.inputs import describe_stored_window, retracted_by_job
from app.reports.pdf import html_to_pdf
from app.reports.sections import ReportContext, as_cell, contributed_sections
from app.reports.summary import iso, layout, layouts, split_columns, wall
from app.services import figures
from storage.jobs import ArtifactStore
from storage.models import Calibration, Job, ReferenceDataset, Spacecraft, SpacecraftConfig
from storage.parquet_store import ParquetStore

_env = Environment(loader=FileSystemLoader(Path(__file__).parent / "templates"),
                   autoescape=select_autoescape(["html"]), trim_blocks=True, lstrip_blocks=True)
_env.filters["iso"] = iso
_env.filters["wall"] = wall


def pretty_json(value: Any, indent: int = 0) -> str:
    """JSON with objects one key a line and short lists of numbers or strings on one line."""
    pad = " " * (indent + 2)
    if isinstance(value, dict) and value:
        items = [f"{pad}{json.dumps(str(k))}: {pretty_json(v, indent + 2)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + "\n" + " " * indent + "}"
    if isinstance(value, list) and value and any(isinstance(v, (dict, list)) for v in value):
        return "[\n" + ",\n".join(pad + pretty_json(v, indent + 2) for v in value) + "\n" + " " * indent + "]"
    return json.dumps(value)


_env.filters["pretty_json"] = pretty_json


def _reference_info(session: Session | None, chosen: dict[str, str]) -> dict[str, Any]:
    """What each pinned input of the job is: reference data sets, the screening job, calibration versions."""
    info: dict[str, Any] = {}
    for kind, ref_id in chosen.items():
        if kind == SCREENING_KEY:
            j = session.get(Job, ref_id) if session is not None else None
            info[kind] = {"id": ref_id, "name": f"data_screening job {ref_id[:8]} ({iso(j.start_tai_ns)} .. "
                                              f"{iso(j.end_tai_ns)})" if j else "(deleted job)",
                          "url": f"/ui/jobs/{ref_id}" if j else None, "checksum_sha256": None}
        elif kind.startswith(CALIBRATION_PREFIX):
            c = session.get(Calibration, ref_id) if session is not None else None
            info[kind] = {"id": ref_id, "name": f"{c.kind} calibration version {c.version}" if c else "(deleted)",
                          "url": f"/ui/jobs/{c.job_id}" if c and c.job_id else None, "checksum_sha256": None}
        else:
            d = session.get(ReferenceDataset, ref_id) if session is not None else None
            info[kind] = {"id": ref_id, "name": d.name if d else "(deleted)", "url": None,
                          "checksum_sha256": d.checksum_sha256 if d else None}
    return info


def _config(session: Session | None, spacecraft_id: int, version: int | None = None) -> tuple[int | None, Any]:
    """(version, config) of the given or the latest configuration version."""
    if session is None:
        return None, None
    q = select(SpacecraftConfig.version, SpacecraftConfig.config).where(SpacecraftConfig.spacecraft_id == spacecraft_id)
    q = q.where(SpacecraftConfig.version == version) if version is not None else q.order_by(
        SpacecraftConfig.version.desc()).limit(1)
    row = session.execute(q).first()
    return (int(row[0]), row[1]) if row else (None, None)


def _query(params: dict[str, Any]) -> str:
    return urllib.parse.urlencode(params, safe=":")


def rerun_request(job: Job, sc: Spacecraft, job_type: JobType | None) -> dict[str, Any]:
    """The ``POST /api/v1/jobs`` body that runs this job again on the same window and settings.

    Times are exact ISO 8601 UTC readings of the stored TAI nanoseconds; reference kinds the job ran
    without are pinned to "none" so that a newer data set is not picked up.
    """
    body: dict[str, Any] = {"type": job.type, "spacecraft": sc.name, "start": iso(job.start_tai_ns),
                            "end": iso(job.end_tai_ns), "time_scale": "utc", "params": dict(job.params or {})}
    if job_type is not None and not stream_names(job_type):  # reads no telemetry: the window is the submit time
        del body["start"], body["end"]
    kinds = job_type.reference if job_type is not None else tuple(job.reference or {})
    if kinds:
        body["reference"] = {k: (job.reference or {}).get(k, "none") for k in kinds}
    return body


def _reproduce(job: Job, sc: Spacecraft, job_type: JobType | None, latest_version: int | None,
               streams: list[str]) -> dict[str, Any]:
    body = rerun_request(job, sc, job_type)
    ui_query = {"type": body["type"], "spacecraft": sc.name, "start": body.get("start", ""),
                "end": body.get("end", ""), "params": json.dumps(body["params"], sort_keys=True)}
    if "reference" in body:
        ui_query["reference"] = json.dumps(body["reference"], sort_keys=True)
    window = {"start": iso(job.start_tai_ns), "end": iso(job.end_tai_ns)}
    name = urllib.parse.quote(sc.name, safe="")
    out: dict[str, Any] = {
        "endpoint": "POST /api/v1/jobs", "request": body,
        "ui_url": f"/ui/jobs/new?{_query(ui_query)}",
        "timeline_url": f"/ui/spacecraft/{name}?{_query(window)}",
        "input_window": {s: {"api": f"/api/v1/spacecraft/{name}/telemetry/{s}?{_query({**window, 'format': 'csv'})}",
                             "ui": f"/ui/spacecraft/{name}/telemetry/{s}.csv?{_query(window)}"} for s in streams},
        "note": None,
    }
    if latest_version is not None and latest_version != job.config_version:
        out["note"] = (f"This job used configuration version {job.config_version}; the spacecraft's configuration "
                       f"is now version {latest_version}, which a rerun would use.")
    return out


def stage_headlines(summary: dict[str, Any] | None,
                    specifications: speclib.Specifications | None) -> list[dict[str, Any]]:
    """A pipeline's stages (``summary.stages.<job type>``), each with its own headline, checks and verdict.

    The checks are returned under ``checks`` with keys and labels naming the stage (for the pipeline's
    own specification table); an empty list for jobs that are not pipelines."""
    stages = (summary or {}).get("stages")
    if not isinstance(stages, dict):
        return []
    types = registry()
    out = []
    for name, stage in stages.items():
        jt = types.get(name)
        if not isinstance(stage, dict) or jt is None:
            continue
        stage_summary = stage.get("summary") if stage.get("status") == "succeeded" else None
        checks = speclib.evaluate(name, stage_summary, specifications)
        answers = jt.headline if jt.headline is not None else headlib.default_answers(stage_summary, checks)
        out.append({"stage": name, "title": jt.title, "status": stage.get("status"),
                    "reason": stage.get("reason") or stage.get("error"), "verdict": speclib.verdict(checks),
                    "rows": headlib.rows(answers, stage_summary, checks),
                    "checks": [replace(c, key=f"stages.{name}.summary.{c.key}", label=f"{name}: {c.label}")
                               for c in checks]})
    return out


def brief(job: Job, job_type: JobType | None, specifications: speclib.Specifications | None) -> dict[str, Any]:
    """The headline of a finished job in one line (for job lists): the first answer, all its components,
    and the verdict of every answer."""
    summary = (job.result or {}).get("summary") if job.status == "succeeded" else None
    if not summary:
        return {"text": "", "verdict": "none"}
    checks = speclib.evaluate(job.type, summary, specifications)
    stages = stage_headlines(summary, specifications)
    checks += [c for st in stages for c in st.pop("checks")]
    answers = job_type.headline if job_type is not None and job_type.headline is not None else \
        headlib.default_answers(summary, checks)
    rows = headlib.rows(answers, summary, checks) or [r for st in stages for r in st["rows"]]
    if not rows:
        return {"text": "", "verdict": speclib.verdict(checks)}
    first = [r for r in rows if r["key"] == rows[0]["key"]]
    values = ", ".join(r["text"] for r in first)
    unit = f" {first[0]['unit']}" if first[0]["unit"] else ""
    return {"text": f"{first[0]['quantity']}: {values}{unit}", "verdict": speclib.verdict(checks)}


def report_json(job: Job, sc: Spacecraft, job_type: JobType | None, *,
                telemetry: ParquetStore | None = None) -> dict[str, Any]:
    """The report as a JSON document (also the data the HTML and PDF are drawn from).

    ``telemetry``: the telemetry store, used to describe the input window of jobs that did not record
    their input coverage (sample gaps) when they ran.
    """
    session = object_session(job)
    _, config = _config(session, sc.id, job.config_version)
    latest_version, latest_config = _config(session, sc.id)
    stored = job.result or {}
    inputs = stored.get("inputs", {}) or {}
    coverage: dict[str, Any] = {"source": "job", "streams": stored.get("input_coverage")}
    if coverage["streams"] is None:
        coverage = {"source": "unavailable", "streams": {}}
        if telemetry is not None and session is not None and inputs:
            coverage = {"source": "store", "streams": describe_stored_window(
                session, telemetry, sc.id, list(inputs), job.start_tai_ns, job.end_tai_ns)}
    specifications = speclib.parse(latest_config)
    summary = stored.get("summary")
    checks = speclib.evaluate(job.type, summary, specifications)
    stages = stage_headlines(summary, specifications)
    checks += [c for st in stages for c in st.pop("checks")]
    streams = sorted(set(inputs) | set(job_type.streams if job_type else ()))
    answers = job_type.headline if job_type is not None and job_type.headline is not None else \
        headlib.default_answers(summary, checks)
    return {  # the warnings and the answers first (a reader of the JSON sees them before anything else)
        "warnings": (stored.get("summary") or {}).get("warnings", []),
        "headline": {"verdict": speclib.verdict(checks), "rows": headlib.rows(answers, summary, checks),
                     "stages": stages},
        "retracted_inputs": retracted_by_job(session, [job.id]).get(job.id, []) if session is not None else [],
        "job": {"id": job.id, "type": job.type, "title": job_type.title if job_type else job.type,
                "paper": job_type.paper if job_type else "", "description": job_type.description if job_type else "",
                "status": job.status, "error": job.error, "created_at": job.created_at.isoformat(),
                "started_at": job.started_at.isoformat() if job.started_at else None,
                "finished_at": job.finished_at.isoformat() if job.finished_at else None},
        "spacecraft": sc.name,
        "window": {"start": iso(job.start_tai_ns), "end": iso(job.end_tai_ns),
                   "duration_s": (job.end_tai_ns - job.start_tai_ns) / 1e9,
                   "start_tai_ns": job.start_tai_ns, "end_tai_ns": job.end_tai_ns},
        "inputs": inputs,
        "input_coverage": coverage,
        "parameters": job.params,
        "reference": _reference_info(session, job.reference or {}),
        "configuration": {"version": job.config_version, "config": config},
        "software_version": job.software_version,
        "summary": summary,
        "notes": stored.get("notes", []),
        "specifications": {
            "configuration_version": latest_version if specifications is not None else None,
            "verdict": speclib.verdict(checks),
            "checks": [{"label": c.label, "key": c.key, "unit": c.unit, "components": list(c.components),
                        "values": list(c.values), "limit": c.limit, "passed": list(c.passed), "ok": c.ok}
                       for c in checks]},
        "reproduce": _reproduce(job, sc, job_type, latest_version, streams),
        "artifacts": artifact_entries(job),
    }


def artifact_entries(job: Job) -> list[dict[str, Any]]:
    """The report's list of the job's artifacts: the stored ones, then the figures made on request
    (``on_request``: drawn and stored when first downloaded, or when the HTML/PDF report is built)."""
    return [{"name": a["name"], "kind": a["kind"], "media_type": a["media_type"], "size_bytes": a["size_bytes"],
             "description": a["description"], "on_request": a["on_request"],
             "url": f"/api/v1/jobs/{job.id}/artifacts/{a['name']}"} for a in figures.listing(job)]


def with_figures(data: dict[str, Any], job: Job, store: ArtifactStore) -> tuple[dict[str, Any], list[str]]:
    """Draw and store the figures the job makes on request and has not made yet (a report embeds every figure,
    as when the job drew them); the report data with its artifact list updated, and what could not be drawn."""
    session = object_session(job)
    if session is None or not figures.recorded_names(job):
        return data, []
    problems = figures.make_figures(session, store, job)
    return {**data, "artifacts": artifact_entries(job)}, problems


def _png(fig: Any) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    return buf.getvalue()


def _sections(data: dict[str, Any], job: Job, store: ArtifactStore, job_type: JobType | None,
              figure_files: dict[str, bytes]) -> tuple[list[dict[str, Any]], list[str], set[str]]:
    """Rendered contributed sections, problems, and the stored figure names they placed."""
    if job_type is None or data["summary"] is None:
        return [], [], set()
    try:
        params: Any = job_type.params.model_validate(job.params)
    except ValueError:
        params = dict(job.params)
    by_name = {a.name: a for a in job.artifacts}

    def load_table(name: str) -> bytes | None:
        art = by_name.get(f"{name}.parquet")
        path = store.path(art) if art is not None else None
        return path.read_bytes() if path is not None and path.is_file() else None

    ctx = ReportContext(job_type=job.type, summary=data["summary"], params=params,
                        config=data["configuration"]["config"] or {},
                        specifications=speclib.parse(_config(object_session(job), job.spacecraft_id)[1]),
                        load_table=load_table)
    sections, problems = contributed_sections(job_type, ctx)
    placed: set[str] = set()
    out = []
    for s in sections:
        figs = []
        for name in s.figure_names:
            if f"{name}.png" in figure_files:
                figs.append({"title": by_name[f"{name}.png"].description or name,
                             "data": base64.b64encode(figure_files[f"{name}.png"]).decode()})
                placed.add(f"{name}.png")
        for name, fig in s.figures.items():
            figs.append({"title": str(fig.get_label() or name), "data": base64.b64encode(_png(fig)).decode()})
        tables = []
        for t in s.tables:
            rows = [[as_cell(v) for v in r] for r in t.rows]
            tables.append({"title": t.title, "caption": t.caption, "columns": list(t.columns), "rows": rows,
                           "parts": split_columns([str(c) for c in t.columns], rows)})
        out.append({"title": s.title, "paragraphs": list(s.paragraphs), "figures": figs, "tables": tables})
    return out, problems, placed


def _table_info(job: Job, store: ArtifactStore) -> list[dict[str, Any]]:
    out = []
    for a in job.artifacts:
        if a.kind != "table" or not a.name.endswith(".parquet"):
            continue
        stem = a.name[: -len(".parquet")]
        path = store.path(a)
        rows = cols = None
        if path.is_file():
            meta = pq.read_schema(path)
            cols = list(meta.names)
            rows = pq.read_metadata(path).num_rows
        out.append({"name": stem, "rows": rows, "columns": cols or [], "parquet": a.name,
                    "csv": f"{stem}.csv"})  # stored, or made from the Parquet on request
    return out


def render_html(data: dict[str, Any], job: Job, store: ArtifactStore, *, ui: bool = False,
                for_print: bool = False) -> str:
    """The self-contained HTML report. ``ui``: with the web UI's navigation; ``for_print``: for the PDF."""
    job_type = registry().get(job.type)
    data, figure_problems = with_figures(data, job, store)
    figure_files: dict[str, bytes] = {}
    for a in job.artifacts:
        if a.kind == "figure" and a.media_type == "image/png":
            path = store.path(a)
            if path.is_file():
                figure_files[a.name] = path.read_bytes()
    sections, problems, placed = _sections(data, job, store, job_type, figure_files)
    descriptions = {a.name: a.description for a in job.artifacts}
    figure_list = [{"name": name, "title": descriptions.get(name) or name, "data": base64.b64encode(png).decode()}
                   for name, png in figure_files.items() if name not in placed]
    return _env.get_template("job_report.html").render(
        d=data, summaries=layouts(data["summary"]), sections=sections, problems=problems + figure_problems,
        figures=figure_list,
        tables=_table_info(job, store), ui=ui, for_print=for_print, job_id=job.id)


def _facts(data: dict[str, Any]) -> list[tuple[str, str]]:
    """Key facts of a report as text lines (for the PDF drawn without Chromium)."""
    rows = data["headline"]["rows"] + [r for st in data["headline"]["stages"] for r in st["rows"]]
    answers = [(f"{r['quantity']} {r['component']}".strip(),
                " ".join(x for x in (r["text"], r["unit"], f"[{r['frame']}]" if r["frame"] else "", r["verdict"]) if x))
               for r in rows]
    facts = [("Spacecraft", data["spacecraft"]), ("Job", f"{data['job']['id']} ({data['job']['status']})"),
             *answers,
             ("Window (UTC)", f"{data['window']['start']} .. {data['window']['end']}"),
             ("Inputs", "; ".join(f"{s}: " + ", ".join(f"{k} {n}" for k, n in v.items())
                                  for s, v in data["inputs"].items()) or "none"),
             ("Parameters", json.dumps(data["parameters"])),
             ("Configuration version", str(data["configuration"]["version"])),
             ("Software version", data["software_version"]),
             ("Specification", data["specifications"]["verdict"])]
    if data["job"]["error"]:
        facts.append(("Error", data["job"]["error"]))
    lay = layout(data["summary"])
    facts += lay.scalars + [(k, "[" + ", ".join(v) + "]") for k, v in lay.vectors]
    facts += [(k, ", ".join(f"{s}={x}" for s, x in v.items())) for k, v in lay.stats]
    return facts


def render_pdf(data: dict[str, Any], job: Job, store: ArtifactStore) -> bytes:
    """The report as PDF (Chromium's print of the HTML report; see app.reports.pdf)."""
    html = render_html(data, job, store, for_print=True)
    pngs = [(a.description or a.name, store.path(a).read_bytes()) for a in job.artifacts
            if a.kind == "figure" and a.media_type == "image/png" and store.path(a).is_file()]
    pdf, _engine = html_to_pdf(html, f"{data['job']['title']} — {data['spacecraft']}", _facts(data), pngs)
    return pdf
