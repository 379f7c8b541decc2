"""What every remote command shares: the connection options, the client, ``--param`` parsing, the output
(text or ``--json``), sizes, the progress bar and the usage error."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any, TextIO

from app.client import Client

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


def _read_json_file(path: str) -> Any:
    try:
        text = sys.stdin.read() if path == "-" else Path(path).read_text()
    except OSError as exc:
        raise UsageError(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise UsageError(f"{path} is not JSON: {exc}") from None


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
