"""``attitude upload``: a telemetry file streamed to the service with a progress bar."""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

from app.cli_remote.common import ProgressBar, _client, _print, _size


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


def add_upload_commands(sub: Any, parent: argparse.ArgumentParser) -> None:
    """Register ``attitude upload`` (``parent``: the connection options)."""
    p = sub.add_parser("upload", parents=[parent], help="upload a telemetry file to a running service")
    p.add_argument("file", help="CSV, Parquet (.parquet), Arrow IPC stream (.arrow) or JSON file")
    p.add_argument("--spacecraft", required=True)
    p.add_argument("--stream", required=True, help="star_tracker, gyro, gnss, ...")
    p.add_argument("--time-scale", default="utc", choices=["utc", "tai", "gps", "tt"])
    p.add_argument("--sensor")
    p.add_argument("--quaternion-direction", choices=["sensor_to_inertial", "inertial_to_sensor"])
    p.add_argument("--content-type", help="media type (default: from the file extension)")
    p.set_defaults(func=_upload)
