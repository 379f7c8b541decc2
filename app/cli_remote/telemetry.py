"""``attitude telemetry get``: stored samples of a window to a file or stdout."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from app.cli_remote.common import UsageError, _client, _size


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


def add_telemetry_commands(sub: Any, parent: argparse.ArgumentParser) -> None:
    """Register ``attitude telemetry get`` (``parent``: the connection options)."""
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
