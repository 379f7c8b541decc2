"""``attitude spacecraft ...``: list, show, create, and ``spacecraft config get|set``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from app.cli_remote.common import _client, _print, _read_json_file


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


def add_spacecraft_commands(sub: Any, parent: argparse.ArgumentParser) -> None:
    """Register ``attitude spacecraft ...`` (``parent``: the connection options)."""
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
