"""How a remote command ends on an error: usage, connection and HTTP errors as a message on stderr and exit
code 2, a 404 on a name with the nearest name the key may see."""

from __future__ import annotations

import argparse
import json
import re
import sys
from typing import Any

from app.cli_remote.common import UsageError
from app.client import AmbiguousId, ApiError, Client, NotFound, ServiceUnreachable

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
