"""``attitude reference ...``: upload and list reference data sets."""

from __future__ import annotations

import argparse
from typing import Any

from app.cli_remote.common import _client, _print


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


def add_reference_commands(sub: Any, parent: argparse.ArgumentParser) -> None:
    """Register ``attitude reference ...`` (``parent``: the connection options)."""
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
