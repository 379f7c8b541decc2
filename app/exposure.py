"""No default credentials: the service refuses to listen beyond loopback without an API key."""

from __future__ import annotations

import ipaddress

from sqlalchemy import select

from app.settings import Settings
from storage.db import make_engine, session_factory, upgrade
from storage.models import ApiKey, utcnow


class UnprotectedBind(RuntimeError):
    pass


def is_loopback(host: str) -> bool:
    if host in ("localhost", "localhost.localdomain"):
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False  # a host name other than localhost may resolve anywhere


def check_bind(settings: Settings, host: str) -> None:
    """Raise UnprotectedBind when ``host`` is reachable from other machines and no usable key exists
    (neither ATTITUDE_BOOTSTRAP_TOKEN nor an active key in the catalog)."""
    if is_loopback(host) or settings.bootstrap_token:
        return
    engine = make_engine(settings.database_url)
    try:
        upgrade(engine)
        with session_factory(engine)() as session:
            now = utcnow()
            keys = session.scalars(select(ApiKey).where(ApiKey.revoked_at.is_(None))).all()
            if any(k.expires_at is None or k.expires_at > now for k in keys):
                return
    finally:
        engine.dispose()
    raise UnprotectedBind(
        f"refusing to listen on {host}: no API key is configured, so anyone who reaches this address "
        "could not be told apart from an admin later. Set ATTITUDE_BOOTSTRAP_TOKEN or create a key with "
        "`attitude create-key --role admin --name ...`, or listen on 127.0.0.1.")
