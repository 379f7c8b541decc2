"""Command-line client of a running service: ``attitude upload``, ``attitude jobs ...``, ``attitude schedules ...``.

Every command talks HTTP to ``--url`` (or ``ATTITUDE_URL``, default http://127.0.0.1:8000) with the API key
``--token`` (or ``ATTITUDE_TOKEN``). Long uploads and jobs show a progress bar on stderr (a plain line
every 10 % when stderr is not a terminal); results go to stdout, as text or with ``--json`` as JSON.
Exit codes: 0 success, 1 a job that failed or was cancelled, 2 usage or HTTP errors.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any, TextIO

from app.client import FINAL, ApiClient, ApiError

DEFAULT_URL = "http://127.0.0.1:8000"


class ProgressBar:
    """A one-line progress bar: ``label [#####.....]  45%  detail``."""

    def __init__(self, label: str, stream: TextIO | None = None, width: int = 30) -> None:
        self.label = label
        self.stream = stream or sys.stderr
        self.width = width
        self.tty = self.stream.isatty()
        self._last_decile = -1
        self._last_text = ""

    def update(self, fraction: float, detail: str = "") -> None:
        fraction = min(max(fraction, 0.0), 1.0)
        filled = int(round(fraction * self.width))
        text = f"{self.label} [{'#' * filled}{'.' * (self.width - filled)}] {fraction * 100:5.1f}%  {detail}"
        if self.tty:
            if text != self._last_text:
                self.stream.write("\r" + text.ljust(len(self._last_text)))
                self.stream.flush()
        elif int(fraction * 10) > self._last_decile:
            self._last_decile = int(fraction * 10)
            self.stream.write(text.rstrip() + "\n")
            self.stream.flush()
        self._last_text = text

    def close(self) -> None:
        if self.tty and self._last_text:
            self.stream.write("\n")
            self.stream.flush()


def _client(args: argparse.Namespace) -> ApiClient:
    if not args.token:
        raise SystemExit("attitude: an API key is needed: --token or ATTITUDE_TOKEN")
    return ApiClient(args.url, args.token, timeout_s=args.timeout)


def _value(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def _params(args: argparse.Namespace) -> dict[str, Any]:
    params: dict[str, Any] = json.loads(args.params_json) if args.params_json else {}
    for item in args.param or []:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise SystemExit(f"attitude: --param expects key=value, got {item!r}")
        params[key] = _value(value)
    return params


def _print(args: argparse.Namespace, data: Any, text: str) -> None:
    print(json.dumps(data, indent=2, default=str) if args.json else text)


def _size(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1000
    return f"{n:.1f} GB"


# -- commands -------------------------------------------------------------------------------------
def _upload(args: argparse.Namespace) -> int:
    client = _client(args)
    bar = ProgressBar(f"upload {os.path.basename(args.file)}")
    t0 = time.monotonic()

    def on_progress(sent: int, total: int) -> None:
        rate = sent / max(time.monotonic() - t0, 1e-6)
        bar.update(sent / total if total else 1.0, f"{_size(sent)}/{_size(total)}  {_size(rate)}/s")

    try:
        result = client.upload_file(args.spacecraft, args.stream, args.file, content_type=args.content_type,
                                    on_progress=None if args.quiet else on_progress, time_scale=args.time_scale,
                                    sensor=args.sensor, quaternion_direction=args.quaternion_direction)
    finally:
        bar.close()
    _print(args, result, f"ingest {result['ingest_id']}: {result['rows']} rows, {result['inserted']} new, "
                         f"{result['duplicates']} duplicates, {result['start']} .. {result['end']}")
    return 0


def _watch_job(client: ApiClient, job_id: str, quiet: bool, poll_s: float = 0.5) -> dict[str, Any]:
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


def _job_outcome(args: argparse.Namespace, job: dict[str, Any]) -> int:
    text = f"job {job['id']} {job['status']}"
    if job.get("error"):
        text += f": {job['error']}"
    for w in (job.get("result") or {}).get("warnings", []):
        text += f"\nWARNING {w['code']}: {w['message']}"
    if job["status"] == "succeeded":
        text += f"\nreport: {args.url.rstrip('/')}{job['report_url']}"
    _print(args, job, text)
    return 0 if job["status"] == "succeeded" else 1


def _jobs_submit(args: argparse.Namespace) -> int:
    client = _client(args)
    reference = dict(item.partition("=")[::2] for item in args.reference or [])
    accepted = client.submit_job(args.type, args.spacecraft, start=args.start, end=args.end,
                                 time_scale=args.time_scale, params=_params(args), reference=reference)
    if not args.wait:
        _print(args, accepted, accepted["id"])
        return 0
    return _job_outcome(args, _watch_job(client, accepted["id"], args.quiet))


def _jobs_watch(args: argparse.Namespace) -> int:
    client = _client(args)
    return _job_outcome(args, _watch_job(client, args.id, args.quiet))


def _jobs_list(args: argparse.Namespace) -> int:
    jobs = _client(args).list_jobs(spacecraft=args.spacecraft, type=args.type, status=args.status, limit=args.limit)
    lines = [f"{'id':32}  {'type':24}  {'spacecraft':12}  {'status':9}  {'progress':>8}  created"]
    lines += [f"{j['id']:32}  {j['type']:24}  {j['spacecraft']:12}  {j['status']:9}  {j['progress'] * 100:7.0f}%  "
              f"{j['created_at']}" for j in jobs]
    _print(args, jobs, "\n".join(lines))
    return 0


def _schedules_create(args: argparse.Namespace) -> int:
    body = {"name": args.name, "cron": args.cron, "type": args.type, "spacecraft": args.spacecraft,
            "params": _params(args), "window": args.window, "window_s": args.window_s,
            "enabled": not args.disabled}
    s = _client(args).create_schedule(body)
    _print(args, s, f"schedule {s['name']} ({s['id']}): {s['cron']} UTC, next {s['next_fire_at']}")
    return 0


def _schedules_list(args: argparse.Namespace) -> int:
    items = _client(args).list_schedules()
    lines = [f"{'name':24}  {'cron':16}  {'type':24}  {'spacecraft':12}  {'window':20}  next"]
    for s in items:
        window = f"{s['window']} {s['window_s']} s" if s["window_s"] else s["window"]
        lines.append(f"{s['name']:24}  {s['cron']:16}  {s['type']:24}  {s['spacecraft']:12}  {window:20}  "
                     f"{s['next_fire_at']}")
    _print(args, items, "\n".join(lines))
    return 0


def _schedules_show(args: argparse.Namespace) -> int:
    client = _client(args)
    s = client.get(f"/api/v1/schedules/{args.name}")
    runs = client.get(f"/api/v1/schedules/{args.name}/runs", params={"limit": args.limit})
    lines = [f"schedule {s['name']} ({s['id']}): {s['cron']} UTC, {s['type']} on {s['spacecraft']}, "
             f"window {s['window']}" + (f" {s['window_s']} s" if s["window_s"] else "")
             + f", next {s['next_fire_at']}", f"{'fire time':26}  {'status':9}  {'missed':>6}  job / reason"]
    lines += [f"{r['fire_at']:26}  {r['status']:9}  {r['missed']:6d}  {r['job_id'] or r['message'] or ''}"
              for r in runs]
    _print(args, {"schedule": s, "runs": runs}, "\n".join(lines))
    return 0


def _schedules_delete(args: argparse.Namespace) -> int:
    _client(args).delete(f"/api/v1/schedules/{args.name}")
    _print(args, {"deleted": args.name}, f"schedule {args.name} deleted")
    return 0


# -- parser ---------------------------------------------------------------------------------------
def _remote_parent() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--url", default=os.environ.get("ATTITUDE_URL") or DEFAULT_URL,
                   help="service URL (ATTITUDE_URL; default %(default)s)")
    p.add_argument("--token", default=os.environ.get("ATTITUDE_TOKEN"), help="API key (ATTITUDE_TOKEN)")
    p.add_argument("--timeout", type=float, default=600.0, help="HTTP timeout in seconds")
    p.add_argument("--json", action="store_true", help="print the answer as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(remote=True)
    return p


def _job_params(p: argparse.ArgumentParser) -> None:
    p.add_argument("--param", action="append", metavar="KEY=VALUE", help="a job parameter (JSON value or text); "
                                                                         "repeatable")
    p.add_argument("--params-json", metavar="JSON", help="all job parameters as one JSON object")


def add_remote_commands(sub: Any) -> None:
    """Register upload, jobs and schedules on the ``attitude`` sub-command parser."""
    parent = _remote_parent()
    p = sub.add_parser("upload", parents=[parent], help="upload a telemetry file to a running service")
    p.add_argument("file", help="CSV, Parquet (.parquet), Arrow IPC stream (.arrow) or JSON file")
    p.add_argument("--spacecraft", required=True)
    p.add_argument("--stream", required=True, help="star_tracker, gyro, gnss, ...")
    p.add_argument("--time-scale", default="utc", choices=["utc", "tai", "gps", "tt"])
    p.add_argument("--sensor")
    p.add_argument("--quaternion-direction", choices=["sensor_to_inertial", "inertial_to_sensor"])
    p.add_argument("--content-type", help="media type (default: from the file extension)")
    p.set_defaults(func=_upload)

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

    sched = sub.add_parser("schedules", help="cron schedules of jobs").add_subparsers(dest="schedules_command",
                                                                                     required=True)
    p = sched.add_parser("create", parents=[parent], help="create a schedule")
    p.add_argument("name")
    p.add_argument("--cron", required=True, help="UTC cron expression, e.g. '0 2 * * *'")
    p.add_argument("--type", required=True, help="job type")
    p.add_argument("--spacecraft", required=True)
    p.add_argument("--window", default="previous", choices=["previous", "since_last_success"])
    p.add_argument("--window-s", type=int, help="window length in seconds (previous: default since the last tick)")
    p.add_argument("--disabled", action="store_true", help="create it paused")
    _job_params(p)
    p.set_defaults(func=_schedules_create)
    p = sched.add_parser("list", parents=[parent], help="list schedules")
    p.set_defaults(func=_schedules_list)
    p = sched.add_parser("show", parents=[parent], help="a schedule and its recent runs")
    p.add_argument("name")
    p.add_argument("--limit", type=int, default=20)
    p.set_defaults(func=_schedules_show)
    p = sched.add_parser("delete", parents=[parent], help="delete a schedule (its jobs stay)")
    p.add_argument("name")
    p.set_defaults(func=_schedules_delete)


def run_remote(func: Any, args: argparse.Namespace) -> int:
    """Run a remote command; HTTP and connection errors become a message and exit code 2."""
    try:
        return int(func(args))
    except ApiError as exc:
        detail = exc.body.get("detail", exc.body) if isinstance(exc.body, dict) else exc.body
        if isinstance(detail, bytes):
            detail = detail.decode(errors="replace")
        text = detail if isinstance(detail, str) else json.dumps(detail)
        print(f"attitude: the service answered {exc.status}: {text}", file=sys.stderr)
        return 2
    except (OSError, ValueError) as exc:
        print(f"attitude: {exc}", file=sys.stderr)
        return 2
