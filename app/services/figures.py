"""A job's figures on request: listed before they exist, drawn from the stored artifacts when first asked for,
then stored as the artifact ``<name>.png`` (kind figure) and served as stored (app.jobs.figures).

Two first requests at once may both draw a figure: each writes the PNG to a temporary file and publishes it
under the final name atomically (storage.jobs.ArtifactStore.write), the two renderings are the same bytes, and
the artifact row (unique per job and name) is added once; the request that loses the race uses the other's row.
The figures of one job stay within the job's artifact bound (app.jobs.outputs.JOB_ARTIFACT_MAX_BYTES), as when
the job stored them.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from typing import Any

import pyarrow.parquet as pq
from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from app.jobs.figures import MissingData, draw, stored_result
from app.jobs.outputs import JOB_ARTIFACT_MAX_BYTES
from app.jobs.registry import registry
from app.services.errors import Conflict, NotFound
from storage.jobs import ArtifactStore, add_artifacts
from storage.models import Artifact, Job

log = logging.getLogger("attitude.figures")

ON_REQUEST = "made on request from the stored results"


def recorded_names(job: Job) -> list[str]:
    """The figures the job can make that it did not store (recorded at job end with ``ATTITUDE_FIGURES=lazy``)."""
    record = (job.result or {}).get("figures") or {}
    if job.status != "succeeded" or record.get("mode") != "lazy":
        return []
    stored = {a.name for a in job.artifacts}
    return [n for n in record.get("names") or [] if f"{n}.png" not in stored]


def bounds_note(job: Job) -> str:
    """What the output bounds did to the tables the figures are drawn from ("" when nothing)."""
    outputs = ((job.result or {}).get("summary") or {}).get("outputs") or {}
    parts = [f"table {t} has its first {v['stored_rows']} of {v['rows']} rows"
             for t, v in (outputs.get("truncated") or {}).items()]
    omitted = [n for n in outputs.get("omitted") or [] if n.endswith(".parquet")]
    if omitted:
        parts.append(f"left out: {', '.join(omitted)}")
    return f"drawn from the stored tables ({'; '.join(parts)})" if parts else ""


def listing(job: Job) -> list[dict[str, Any]]:
    """The job's artifacts, stored ones first, then the figures it makes on request (``on_request`` true, no size
    or checksum yet)."""
    out: list[dict[str, Any]] = [
        {"name": a.name, "kind": a.kind, "media_type": a.media_type, "size_bytes": a.size_bytes,
         "checksum_sha256": a.checksum_sha256, "description": a.description, "on_request": False}
        for a in job.artifacts]
    note = bounds_note(job)
    for name in recorded_names(job):
        out.append({"name": f"{name}.png", "kind": "figure", "media_type": "image/png", "size_bytes": None,
                    "checksum_sha256": None, "description": f"figure {name}, {ON_REQUEST}" + (f"; {note}" if note
                                                                                                  else ""),
                    "on_request": True})
    return out


def make_figures(session: Session, store: ArtifactStore, job: Job, names: Iterable[str] | None = None,
                 ) -> list[str]:
    """Draw and store the job's figures among ``names`` (None: every recorded one) that are not stored yet.

    Returns the names that could not be made, each with its reason, as text (a report lists them); a single
    figure asked for by name raises instead (:func:`figure_artifact`)."""
    missing = recorded_names(job) if names is None else [
        n for n in names if f"{n}.png" not in {a.name for a in job.artifacts}]
    if not missing:
        return []
    try:
        made = _draw_and_store(session, store, job, set(missing))
    except Conflict as exc:
        return [f"figures {', '.join(missing)}: {exc.detail}"]
    return [f"figure {n}: not drawn ({made.get(n, 'the job type draws no such figure from these results')})"
            for n in missing if made.get(n) is not True]


def figure_artifact(session: Session, store: ArtifactStore, job: Job, name: str) -> Artifact:
    """The stored artifact of figure ``name`` (no ``.png``), drawn and stored first when the job made it on request.
    NotFound: the job has no such figure; Conflict: it cannot be drawn from what the job stored (reason given)."""
    if job.status != "succeeded":
        raise NotFound(f"job {job.id} has no artifact {name + '.png'!r} (it is {job.status})")
    record = (job.result or {}).get("figures") or {}
    if record.get("mode") != "lazy" or (record.get("names") is not None and name not in record["names"]):
        raise NotFound(f"job {job.id} has no artifact {name + '.png'!r}")
    made = _draw_and_store(session, store, job, {name})
    if made.get(name) is not True:
        raise Conflict(f"figure {name} of job {job.id} cannot be drawn: "
                       f"{made.get(name, 'the job type draws no such figure from these results')}")
    art = session.scalar(select(Artifact).where(Artifact.job_id == job.id, Artifact.name == f"{name}.png"))
    assert art is not None
    return art


def _draw_and_store(session: Session, store: ArtifactStore, job: Job, wanted: set[str]) -> dict[str, Any]:
    """name -> True (stored) or the reason it was not, for the ``wanted`` figures the job type drew."""
    job_type = registry().get(job.type)
    if job_type is None:
        raise Conflict(f"job type {job.type!r} is no longer registered: its figures cannot be drawn")
    by_name = {a.name: a for a in job.artifacts}
    summary = (job.result or {}).get("summary") or {}
    tables = {a.name[: -len(".parquet")]: (lambda a=a: pq.read_table(store.path(a)))
              for a in job.artifacts if a.kind == "table" and a.name.endswith(".parquet")}
    files = {a.name: ((lambda a=a: store.path(a).read_bytes()), a.media_type)
             for a in job.artifacts if a.kind == "file"}
    try:
        params: Any = job_type.params.model_validate(job.params)
        drawn, names = draw(job_type, stored_result(summary, tables, files), params, wanted)
    except MissingData as exc:
        note = bounds_note(job)
        raise Conflict(f"the job did not store the table or file {exc.args[0]!r} its figures are drawn from"
                       + (f" ({note})" if note else "")) from exc
    except Exception as exc:  # noqa: BLE001 - drawing from stored data that the figure cannot use: a reason, no 500
        log.error("figures of job %s could not be drawn from its stored artifacts", job.id, exc_info=True)
        raise Conflict(f"the figures cannot be drawn from the stored results: {type(exc).__name__}: {exc}") from exc
    note = bounds_note(job)
    used = sum(a.size_bytes for a in job.artifacts)
    out: dict[str, Any] = {}
    for name, (png, title) in drawn.items():
        if by_name.get(f"{name}.png") is not None:
            out[name] = True
            continue
        if used + len(png) > JOB_ARTIFACT_MAX_BYTES:
            out[name] = f"it would take the job's artifacts beyond {JOB_ARTIFACT_MAX_BYTES // 2**20} MiB"
            continue
        stored = store.write(job.id, f"{name}.png", png, kind="figure", media_type="image/png",
                             description=title + (f" ({note})" if note else ""))
        try:
            add_artifacts(session, job.id, [stored])
            session.commit()
        except IntegrityError:  # another request stored it first (the same bytes, published atomically)
            session.rollback()
        used += len(png)
        out[name] = True
    _record_names(session, job, names)
    session.expire(job, ["artifacts"])
    return out


def _record_names(session: Session, job: Job, names: list[str]) -> None:
    """Keep the recorded names those ``figures()`` gave (when the names-only rules did not know them)."""
    record = (job.result or {}).get("figures") or {}
    if record.get("names") == names:
        return
    job.result = {**(job.result or {}), "figures": {**record, "names": names}}
    session.commit()
