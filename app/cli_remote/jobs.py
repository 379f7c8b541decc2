"""``attitude jobs ...``: submit (and watch), watch, list, result, cancel, report, artifacts."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from app.cli_remote.common import ProgressBar, UsageError, _client, _job_params, _params, _print, _size
from app.client import FINAL, Client


def _watch_job(client: Client, job_id: str, quiet: bool, poll_s: float = 0.5) -> dict[str, Any]:
    bar = ProgressBar(f"job {job_id[:8]}")
    try:
        while True:
            job: dict[str, Any] = client.get(f"/api/v1/jobs/{job_id}")
            if not quiet:
                bar.update(job["progress"], f"{job['status']}: {job['stage']}")
            if job["status"] in FINAL:
                return job
            time.sleep(poll_s)
    finally:
        bar.close()


def _headline_lines(report: dict[str, Any]) -> list[str]:
    head = report.get("headline") or {}
    verdict = head.get("verdict")
    lines = [f"verdict: {verdict.upper()}" if verdict != "none" else "verdict: none (no specification limit applies)"
             ] if verdict else []
    for r in head.get("rows", []):
        name = r["quantity"] + (f" {r['component']}" if r.get("component") not in (None, "") else "")
        unit = f" {r['unit']}" if r.get("unit") else ""
        frame = f" ({r['frame']})" if r.get("frame") else ""
        verdict = f"  {r['verdict']}" if r.get("verdict") else ""
        lines.append(f"  {name}: {r.get('text') or r.get('value')}{unit}{frame}{verdict}")
    return lines


def _job_outcome(args: argparse.Namespace, client: Client, job: dict[str, Any]) -> int:
    """The job's end: status, error, the report's headline and the warnings; exit 1 unless it succeeded."""
    text = f"job {job['id']} {job['status']}"
    if job.get("error"):
        text += f": {job['error']}"
    data: dict[str, Any] = dict(job)  # --json: the job, with the report's headline when it succeeded
    lines = [text]
    if job["status"] == "succeeded":
        report = client.report_data(job["id"])
        data["headline"] = report.get("headline")
        lines += _headline_lines(report)
    warnings = (job.get("result") or {}).get("warnings", [])
    lines += [f"WARNING {w['code']}: {w['message']}" for w in warnings]
    if job["status"] == "succeeded":
        lines.append(f"report: {args.url.rstrip('/')}{job['report_url']}")
    _print(args, data, "\n".join(lines))
    return 0 if job["status"] == "succeeded" else 1


def _jobs_submit(args: argparse.Namespace) -> int:
    client = _client(args)
    reference = dict(item.partition("=")[::2] for item in args.reference or [])
    accepted = client.submit_job(args.type, args.spacecraft, start=args.start, end=args.end,
                                 time_scale=args.time_scale, params=_params(args), reference=reference)
    if not args.wait:
        _print(args, accepted, accepted["id"])
        return 0
    return _job_outcome(args, client, _watch_job(client, accepted["id"], args.quiet))


def _jobs_watch(args: argparse.Namespace) -> int:
    client = _client(args)
    return _job_outcome(args, client, _watch_job(client, client.resolve_job(args.id), args.quiet))


def _jobs_result(args: argparse.Namespace) -> int:
    """A finished job's headline and warnings (``--json``: the job with its summary and the headline)."""
    client = _client(args)
    return _job_outcome(args, client, client.job(args.id))


def _jobs_cancel(args: argparse.Namespace) -> int:
    job = _client(args).cancel(args.id)
    _print(args, job, f"job {job['id']} {job['status']}" + (" (cancel requested)" if job["cancel_requested"]
                                                           and job["status"] not in FINAL else ""))
    return 0


def _jobs_report(args: argparse.Namespace) -> int:
    client = _client(args)
    path = client.report(args.id, args.output, format=args.format)
    _print(args, {"path": str(path), "size_bytes": path.stat().st_size}, f"report saved to {path}")
    return 0


def _jobs_artifacts(args: argparse.Namespace) -> int:
    client = _client(args)
    full = client.resolve_job(args.id)
    items = [a for a in client.artifacts(full) if args.kind is None or a["kind"] == args.kind]
    if args.name:
        listed = {a["name"]: a for a in items}
        for name in args.name:  # a long table is stored as Parquet only; the service makes its CSV on request
            stem = name[:-4] if name.endswith(".csv") else None
            if name not in listed and stem is not None and f"{stem}.parquet" in listed:
                listed[name] = {**listed[f"{stem}.parquet"], "name": name, "media_type": "text/csv",
                                "description": f"{listed[f'{stem}.parquet']['description']} (CSV made on request)"}
        items = [listed[n] for n in dict.fromkeys(args.name) if n in listed]
        missing = sorted(set(args.name) - {a["name"] for a in items})
        if missing:
            raise UsageError(f"job {full[:8]} has no artifact {', '.join(map(repr, missing))}")
    if args.download:
        folder = Path(args.download)
        folder.mkdir(parents=True, exist_ok=True)
        saved = [client.download_artifact(full, a["name"], folder / a["name"]) for a in items]
        _print(args, [str(p) for p in saved], "\n".join(f"saved {p}" for p in saved))
        return 0
    lines = [f"{'name':40}  {'kind':8}  {'size':>10}  description"]
    lines += [f"{a['name']:40}  {a['kind']:8}  {_listed_size(a):>10}  {a['description']}" for a in items]
    _print(args, items, "\n".join(lines))
    return 0


def _listed_size(a: dict[str, Any]) -> str:
    """An artifact's size, or "on request" for a figure the service draws when it is first downloaded."""
    return "on request" if a.get("on_request") or a.get("size_bytes") is None else _size(a["size_bytes"])


def _jobs_list(args: argparse.Namespace) -> int:
    jobs = _client(args).list_jobs(spacecraft=args.spacecraft, type=args.type, status=args.status, limit=args.limit)
    lines = [f"{'id':8}  {'type':24}  {'spacecraft':12}  {'status':9}  {'progress':>8}  created"]
    lines += [f"{j['id'][:8]:8}  {j['type']:24}  {j['spacecraft']:12}  {j['status']:9}  {j['progress'] * 100:7.0f}%  "
              f"{j['created_at']}" for j in jobs]
    _print(args, jobs, "\n".join(lines))
    return 0


def add_jobs_commands(sub: Any, parent: argparse.ArgumentParser) -> None:
    """Register ``attitude jobs ...`` (``parent``: the connection options)."""
    jobs = sub.add_parser("jobs", help="submit, watch and list jobs").add_subparsers(dest="jobs_command",
                                                                                    required=True)
    p = jobs.add_parser("submit", parents=[parent], help="submit a job (and watch it with --wait)")
    p.add_argument("type")
    p.add_argument("--spacecraft", required=True)
    p.add_argument("--start", help="ISO 8601 or seconds on --time-scale (default: the data's extent)")
    p.add_argument("--end")
    p.add_argument("--time-scale", default="utc", choices=["utc", "tai", "gps", "tt"])
    p.add_argument("--reference", action="append", metavar="KIND=ID", help="reference data set to use; repeatable")
    _job_params(p)
    p.add_argument("--wait", action="store_true", help="watch the job to its end (exit 1 if it fails)")
    p.set_defaults(func=_jobs_submit)
    p = jobs.add_parser("watch", parents=[parent], help="show a job's progress until it ends")
    p.add_argument("id")
    p.set_defaults(func=_jobs_watch)
    p = jobs.add_parser("list", parents=[parent], help="list jobs, newest first")
    p.add_argument("--spacecraft")
    p.add_argument("--type")
    p.add_argument("--status", choices=["queued", "running", "succeeded", "failed", "cancelled"])
    p.add_argument("--limit", type=int, default=50)
    p.set_defaults(func=_jobs_list)
    p = jobs.add_parser("result", parents=[parent], help="a job's status, headline and warnings")
    p.add_argument("id", help="job id or a unique prefix")
    p.set_defaults(func=_jobs_result)
    p = jobs.add_parser("cancel", parents=[parent], help="cancel a queued or running job")
    p.add_argument("id", help="job id or a unique prefix")
    p.set_defaults(func=_jobs_cancel)
    p = jobs.add_parser("report", parents=[parent], help="save a job's report (HTML, PDF or JSON)")
    p.add_argument("id", help="job id or a unique prefix")
    p.add_argument("-o", "--output", help="file (default report_<id>.<format>); its extension sets the format")
    p.add_argument("--format", choices=["html", "pdf", "json"])
    p.set_defaults(func=_jobs_report)
    p = jobs.add_parser("artifacts", parents=[parent], help="list a job's artifacts (figures not drawn yet: 'on "
                        "request', drawn when downloaded), or save them with --download")
    p.add_argument("id", help="job id or a unique prefix")
    p.add_argument("--kind", choices=["table", "figure", "file", "summary"])
    p.add_argument("--name", action="append", help="only this artifact; repeatable (a table stored as Parquet only: "
                   "<table>.csv is made on request)")
    p.add_argument("--download", metavar="DIR", help="save the (selected) artifacts into DIR")
    p.set_defaults(func=_jobs_artifacts)
