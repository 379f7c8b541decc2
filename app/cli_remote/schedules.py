"""``attitude schedules ...``: create, list, show (with the recent runs), delete."""

from __future__ import annotations

import argparse
from typing import Any

from app.cli_remote.common import _client, _job_params, _params, _print


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


def add_schedules_commands(sub: Any, parent: argparse.ArgumentParser) -> None:
    """Register ``attitude schedules ...`` (``parent``: the connection options)."""
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
