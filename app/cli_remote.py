"""Command-line client of a running service: ``attitude spacecraft ...``, ``attitude upload``,
``attitude telemetry get``, ``attitude jobs ...``, ``attitude schedules ...``, ``attitude reference ...``.

Every command talks HTTP to ``--url`` (or ``ATTITUDE_URL``, default http://127.0.0.1:8000) with the API key
``--token`` (or ``ATTITUDE_TOKEN``) through :class:`app.client.Client`. Ids may be given as unique prefixes
(the 8 characters shown). Long uploads and jobs show a progress bar on stderr (a plain line every 10 % when
stderr is not a terminal); results go to stdout, as text or with ``--json`` as JSON. Errors go to stderr, every
row/column error of an upload listed (``--json``: the service's whole answer on stdout too).
Exit codes: 0 success, 1 a job that failed or was cancelled, 2 usage, connection or HTTP errors.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from app.client import FINAL, AmbiguousId, ApiError, Client, NotFound, ServiceUnreachable

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


class UsageError(Exception):
    """A mistake in the command line (exit code 2)."""


def _client(args: argparse.Namespace) -> Client:
    if not args.token:
        raise UsageError("an API key is needed: --token or ATTITUDE_TOKEN")
    return Client(args.url, args.token, timeout_s=args.timeout)


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
        items = [a for a in items if a["name"] in args.name]
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
    lines += [f"{a['name']:40}  {a['kind']:8}  {_size(a['size_bytes']):>10}  {a['description']}" for a in items]
    _print(args, items, "\n".join(lines))
    return 0


def _jobs_list(args: argparse.Namespace) -> int:
    jobs = _client(args).list_jobs(spacecraft=args.spacecraft, type=args.type, status=args.status, limit=args.limit)
    lines = [f"{'id':8}  {'type':24}  {'spacecraft':12}  {'status':9}  {'progress':>8}  created"]
    lines += [f"{j['id'][:8]:8}  {j['type']:24}  {j['spacecraft']:12}  {j['status']:9}  {j['progress'] * 100:7.0f}%  "
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
    name = client.resolve_schedule(args.name)
    s = client.get(f"/api/v1/schedules/{name}")
    runs = client.get(f"/api/v1/schedules/{name}/runs", params={"limit": args.limit})
    lines = [f"schedule {s['name']} ({s['id']}): {s['cron']} UTC, {s['type']} on {s['spacecraft']}, "
             f"window {s['window']}" + (f" {s['window_s']} s" if s["window_s"] else "")
             + f", next {s['next_fire_at']}", f"{'fire time':26}  {'status':9}  {'missed':>6}  job / reason"]
    lines += [f"{r['fire_at']:26}  {r['status']:9}  {r['missed']:6d}  {r['job_id'] or r['message'] or ''}"
              for r in runs]
    _print(args, {"schedule": s, "runs": runs}, "\n".join(lines))
    return 0


def _schedules_delete(args: argparse.Namespace) -> int:
    client = _client(args)
    client.delete(f"/api/v1/schedules/{client.resolve_schedule(args.name)}")
    _print(args, {"deleted": args.name}, f"schedule {args.name} deleted")
    return 0


def _read_json_file(path: str) -> Any:
    try:
        text = sys.stdin.read() if path == "-" else Path(path).read_text()
    except OSError as exc:
        raise UsageError(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise UsageError(f"{path} is not JSON: {exc}") from None


def _spacecraft_line(s: dict[str, Any]) -> str:
    cfg = s["config"]
    sensors = [f"star trackers {', '.join(cfg['star_trackers'])}" if cfg.get("star_trackers") else ""]
    sensors += [k.replace("_", " ") for k in ("gyro", "magnetometer", "sun_sensor") if cfg.get(k)]
    sensors += [f"{len(cfg['solar_panels'])} solar panels" if cfg.get("solar_panels") else ""]
    return (f"{s['name']:24}  v{s['config_version']:<4}  {s['config_created_at']}  "
            f"{'; '.join(x for x in sensors if x) or '(no sensors configured)'}")


def _spacecraft_list(args: argparse.Namespace) -> int:
    items = _client(args).spacecraft()
    lines = [f"{'name':24}  {'config':5}  {'configured at':32}  sensors"] + [_spacecraft_line(s) for s in items]
    _print(args, items, "\n".join(lines))
    return 0


def _spacecraft_show(args: argparse.Namespace) -> int:
    s = _client(args).spacecraft_info(args.name, args.version)
    text = (f"spacecraft {s['name']} (created {s['created_at']}), configuration version {s['config_version']} "
            f"of {s['config_created_at']}:\n{json.dumps(s['config'], indent=2)}")
    _print(args, s, text)
    return 0


def _spacecraft_create(args: argparse.Namespace) -> int:
    config = _read_json_file(args.config) if args.config else {}
    s = _client(args).create_spacecraft(args.name, config)
    _print(args, s, f"spacecraft {s['name']} created (configuration version {s['config_version']})")
    return 0


def _config_get(args: argparse.Namespace) -> int:
    s = _client(args).spacecraft_info(args.name, args.version)
    text = json.dumps(s["config"], indent=2)
    if args.output:
        Path(args.output).write_text(text + "\n")
        print(f"configuration version {s['config_version']} of {s['name']} saved to {args.output}")
    else:
        print(text)
    return 0


def _config_set(args: argparse.Namespace) -> int:
    s = _client(args).set_config(args.name, _read_json_file(args.file))
    _print(args, s, f"spacecraft {s['name']}: configuration version {s['config_version']} stored")
    return 0


def _telemetry_get(args: argparse.Namespace) -> int:
    binary = args.format in ("parquet", "arrow")
    if binary and not args.output and sys.stdout.isatty():
        raise UsageError(f"{args.format} is binary: give -o FILE (or redirect stdout)")
    raw = _client(args).get(f"/api/v1/spacecraft/{args.spacecraft}/telemetry/{args.stream}", params={
        "start": args.start, "end": args.end, "sensor": args.sensor, "format": args.format,
        "time_scale": args.time_scale, "time_format": args.time_format})
    content = raw if isinstance(raw, bytes) else json.dumps(raw).encode()
    if args.output:
        Path(args.output).write_bytes(content)
        print(f"saved {_size(len(content))} to {args.output}", file=sys.stderr)
    else:
        sys.stdout.flush()
        sys.stdout.buffer.write(content)
        sys.stdout.buffer.flush()
    return 0


def _reference_upload(args: argparse.Namespace) -> int:
    d = _client(args).upload_reference(args.kind, args.file, name=args.name)
    _print(args, d, f"reference {d['kind']} {d['id']} ({d['name']}): {d['rows']} rows, {d['start']} .. {d['end']}")
    return 0


def _reference_list(args: argparse.Namespace) -> int:
    items = _client(args).reference(args.kind)
    lines = [f"{'id':8}  {'kind':18}  {'name':32}  {'rows':>7}  window"]
    lines += [f"{d['id'][:8]:8}  {d['kind']:18}  {d['name'][:32]:32}  {d['rows']:7d}  {d['start']} .. {d['end']}"
              for d in items]
    _print(args, items, "\n".join(lines))
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
    """Register upload, jobs, schedules, spacecraft, telemetry and reference on the ``attitude`` parser."""
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
    p = jobs.add_parser("artifacts", parents=[parent], help="list a job's artifacts, or save them with --download")
    p.add_argument("id", help="job id or a unique prefix")
    p.add_argument("--kind", choices=["table", "figure", "file", "summary"])
    p.add_argument("--name", action="append", help="only this artifact; repeatable")
    p.add_argument("--download", metavar="DIR", help="save the (selected) artifacts into DIR")
    p.set_defaults(func=_jobs_artifacts)

    craft = sub.add_parser("spacecraft", help="spacecraft and their configuration").add_subparsers(
        dest="spacecraft_command", required=True)
    p = craft.add_parser("list", parents=[parent], help="spacecraft the key may see")
    p.set_defaults(func=_spacecraft_list)
    p = craft.add_parser("show", parents=[parent], help="a spacecraft and its configuration")
    p.add_argument("name")
    p.add_argument("--version", type=int, help="configuration version (default: the latest)")
    p.set_defaults(func=_spacecraft_show)
    p = craft.add_parser("create", parents=[parent], help="create a spacecraft (admin)")
    p.add_argument("name")
    p.add_argument("--config", metavar="FILE", help="configuration JSON file ('-': stdin; default: empty)")
    p.set_defaults(func=_spacecraft_create)
    config = craft.add_parser("config", help="read or store the configuration").add_subparsers(
        dest="config_command", required=True)
    p = config.add_parser("get", parents=[parent], help="print (or save) the configuration JSON")
    p.add_argument("name")
    p.add_argument("--version", type=int, help="configuration version (default: the latest)")
    p.add_argument("-o", "--output", metavar="FILE")
    p.set_defaults(func=_config_get)
    p = config.add_parser("set", parents=[parent], help="store a new configuration version (admin)")
    p.add_argument("name")
    p.add_argument("file", help="configuration JSON file ('-': stdin)")
    p.set_defaults(func=_config_set)

    tele = sub.add_parser("telemetry", help="read stored telemetry").add_subparsers(dest="telemetry_command",
                                                                                   required=True)
    p = tele.add_parser("get", parents=[parent], help="download stored samples of a window")
    p.add_argument("stream", help="star_tracker, gyro, gnss, ...")
    p.add_argument("--spacecraft", required=True)
    p.add_argument("--start", help="ISO 8601 or seconds on --time-scale (default: the first sample)")
    p.add_argument("--end", help="inclusive (default: the last sample)")
    p.add_argument("--sensor")
    p.add_argument("--format", default="csv", choices=["csv", "parquet", "arrow", "json"],
                   help="parquet/arrow: a timestamp time and time_tai_ns (default %(default)s)")
    p.add_argument("--time-scale", default="utc", choices=["utc", "tai", "gps", "tt"])
    p.add_argument("--time-format", default="iso", choices=["iso", "seconds", "tai_ns"],
                   help="csv/json times (tai_ns: ISO time and the exact time_tai_ns)")
    p.add_argument("-o", "--output", metavar="FILE", help="file to write (default: stdout)")
    p.set_defaults(func=_telemetry_get)

    ref = sub.add_parser("reference", help="reference data sets (EOP, RINEX navigation, ...)").add_subparsers(
        dest="reference_command", required=True)
    p = ref.add_parser("upload", parents=[parent], help="upload a reference file (parsed at once)")
    p.add_argument("kind", help="see GET /api/v1/reference/kinds")
    p.add_argument("file")
    p.add_argument("--name", help="a name for the data set (default: the file name)")
    p.set_defaults(func=_reference_upload)
    p = ref.add_parser("list", parents=[parent], help="reference data sets, newest first")
    p.add_argument("--kind")
    p.set_defaults(func=_reference_list)

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
    p.add_argument("name", help="name, id or a unique id prefix")
    p.add_argument("--limit", type=int, default=20)
    p.set_defaults(func=_schedules_show)
    p = sched.add_parser("delete", parents=[parent], help="delete a schedule (its jobs stay)")
    p.add_argument("name", help="name, id or a unique id prefix")
    p.set_defaults(func=_schedules_delete)


NOT_FOUND_NAME = re.compile(r"^(spacecraft|schedule) '([^']*)' not found$")


def _nearest(client: Client, exc: ApiError) -> str:
    """" (did you mean 'x'?)" for a 404 on a spacecraft or schedule name, from the names the key may see."""
    m = NOT_FOUND_NAME.match(str(exc.detail)) if isinstance(exc, NotFound) else None
    if m is None:
        return ""
    from app.services.suggest import did_you_mean

    try:
        names = [s["name"] for s in (client.spacecraft() if m.group(1) == "spacecraft" else client.schedules())]
    except (ApiError, OSError):
        return ""
    return did_you_mean(m.group(2), names)


def run_remote(func: Any, args: argparse.Namespace) -> int:
    """Run a remote command; usage, connection and HTTP errors become a message on stderr and exit code 2
    (with ``--json`` the service's whole error answer is printed on stdout too)."""
    try:
        return int(func(args))
    except ApiError as exc:
        text = exc.describe()
        if args.token:
            text += _nearest(Client(args.url, args.token, timeout_s=args.timeout), exc)
        print(f"attitude: {text}", file=sys.stderr)
        if getattr(args, "json", False):
            body = exc.body.decode(errors="replace") if isinstance(exc.body, bytes) else exc.body
            print(json.dumps({"status": exc.status, "url": exc.url, "error": body}, indent=2, default=str))
        return 2
    except (UsageError, AmbiguousId, ServiceUnreachable) as exc:
        print(f"attitude: {exc}", file=sys.stderr)
        return 2
    except (OSError, ValueError) as exc:
        print(f"attitude: {exc}", file=sys.stderr)
        return 2
