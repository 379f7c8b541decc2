"""Command line: ``attitude serve``, ``attitude migrate``, ``attitude create-key`` on this machine;
``attitude spacecraft|upload|telemetry|jobs|schedules|reference ...`` against a running
service (``--url``/``ATTITUDE_URL``, ``--token``/``ATTITUDE_TOKEN``; see app/cli_remote/)."""

from __future__ import annotations

import argparse
import sys

from app.cli_remote import add_remote_commands, run_remote
from app.settings import Settings


def _serve(args: argparse.Namespace) -> int:
    from app.exposure import UnprotectedBind, check_bind
    from app.main import create_app
    from app.server import serve

    settings = Settings.from_env()
    try:
        check_bind(settings, args.host)
    except UnprotectedBind as exc:
        print(f"attitude serve: {exc}", file=sys.stderr)
        return 2
    serve(create_app(settings), settings, host=args.host, port=args.port, log_level=args.log_level)
    return 0


def _migrate(_: argparse.Namespace) -> int:
    from storage.db import make_engine, upgrade

    settings = Settings.from_env()
    upgrade(make_engine(settings.database_url))
    print(f"catalog at {settings.database_url} is up to date")
    return 0


def _create_key(args: argparse.Namespace) -> int:
    from storage.db import make_engine, session_factory, upgrade
    from storage.keys import create_key

    settings = Settings.from_env()
    engine = make_engine(settings.database_url)
    upgrade(engine)
    with session_factory(engine).begin() as session:
        key, secret = create_key(session, name=args.name, role=args.role)
        print(f"created {args.role} key {key.id} ({args.name}); secret (shown once):")
        print(secret)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="attitude", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("serve", help="run the HTTP service")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--log-level", default="info")
    p.set_defaults(func=_serve)
    p = sub.add_parser("migrate", help="apply catalog migrations and exit")
    p.set_defaults(func=_migrate)
    p = sub.add_parser("create-key", help="create an API key and print its secret")
    p.add_argument("--name", required=True)
    p.add_argument("--role", choices=["viewer", "operator", "admin"], default="operator")
    p.set_defaults(func=_create_key)
    add_remote_commands(sub)
    args = parser.parse_args(argv)
    if getattr(args, "remote", False):
        return run_remote(args.func, args)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
