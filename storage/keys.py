"""API keys: creation, lookup by secret, revocation. Only SHA-256 digests are stored.

Secrets are 256-bit random tokens, so a fast hash is enough (no password stretching needed).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import secrets

from sqlalchemy import delete, select
from sqlalchemy.orm import Session

from storage.models import ApiKey, ApiKeyGrant, UiSession, utcnow

ROLES = ("viewer", "operator", "admin")
KEY_PREFIX = "att_"


def digest(secret: str) -> str:
    return hashlib.sha256(secret.encode()).hexdigest()


def new_secret() -> str:
    return KEY_PREFIX + secrets.token_urlsafe(32)


def create_key(session: Session, *, name: str, role: str, secret: str | None = None,
               expires_at: dt.datetime | None = None,
               spacecraft_ids: list[int] | None = None) -> tuple[ApiKey, str]:
    """Create a key; ``spacecraft_ids`` None grants every spacecraft, a list only those (admins: all)."""
    if role not in ROLES:
        raise ValueError(f"role must be one of {', '.join(ROLES)}, got {role!r}")
    if role == "admin" and spacecraft_ids is not None:
        raise ValueError("admin keys manage every spacecraft; give no spacecraft list")
    secret = secret or new_secret()
    key = ApiKey(name=name, role=role, secret_sha256=digest(secret), expires_at=expires_at,
                 all_spacecraft=spacecraft_ids is None)
    key.grants = [ApiKeyGrant(spacecraft_id=i) for i in sorted(set(spacecraft_ids or []))]
    session.add(key)
    session.flush()
    return key, secret


def granted_spacecraft(key: ApiKey) -> frozenset[int] | None:
    """The spacecraft ids a key may use, or None for all."""
    return None if key.all_spacecraft else frozenset(g.spacecraft_id for g in key.grants)


def find_active(session: Session, secret: str) -> ApiKey | None:
    key = session.scalar(select(ApiKey).where(ApiKey.secret_sha256 == digest(secret)))
    if key is None or key.revoked_at is not None:
        return None
    if key.expires_at is not None and key.expires_at <= utcnow():
        return None
    return key


def start_session(session: Session, key: ApiKey, ttl_s: float) -> str:
    """A new UI session of ``key`` ending after ``ttl_s``; returns its token (only the digest is stored)."""
    token = secrets.token_urlsafe(32)
    now = utcnow()
    session.execute(delete(UiSession).where(UiSession.expires_at <= now))  # forget the expired ones
    session.add(UiSession(token_sha256=digest(token), key_id=key.id, created_at=now,
                          expires_at=now + dt.timedelta(seconds=ttl_s)))
    session.flush()
    return token


def find_session_key(session: Session, token: str) -> ApiKey | None:
    """The active key of an unexpired UI session; None when the session, or its key, ended."""
    row = session.get(UiSession, digest(token))
    if row is None or row.expires_at <= utcnow():
        return None
    key = session.get(ApiKey, row.key_id)
    if key is None or key.revoked_at is not None or (key.expires_at is not None and key.expires_at <= utcnow()):
        return None
    return key


def end_session(session: Session, token: str) -> None:
    session.execute(delete(UiSession).where(UiSession.token_sha256 == digest(token)))


def ensure_bootstrap_key(session: Session, secret: str) -> ApiKey:
    """Make sure an admin key with this secret exists (and is not revoked)."""
    key = session.scalar(select(ApiKey).where(ApiKey.secret_sha256 == digest(secret)))
    if key is None:
        key, _ = create_key(session, name="bootstrap", role="admin", secret=secret)
    elif key.revoked_at is not None or key.role != "admin":
        key.revoked_at = None
        key.role = "admin"
    return key


def role_at_least(role: str, needed: str) -> bool:
    return ROLES.index(role) >= ROLES.index(needed)
