"""API keys (admin only): create (the secret is returned once), list, revoke."""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

from sqlalchemy import delete, select
from sqlalchemy.orm import Session, object_session

from app.names import has_control_characters
from app.services.errors import Invalid, NotFound
from app.services.pages import Page, page_of, paginate
from storage.keys import create_key
from storage.models import ApiKey, Spacecraft, UiSession, utcnow


@dataclass(frozen=True)
class KeyInfo:
    """A key as shown to admins (never its secret); ``spacecraft`` None: all."""

    id: str
    name: str
    role: str
    created_at: dt.datetime
    expires_at: dt.datetime | None
    revoked_at: dt.datetime | None
    spacecraft: list[str] | None


def describe(k: ApiKey) -> KeyInfo:
    names = None
    if not k.all_spacecraft:
        session = object_session(k)
        ids = [g.spacecraft_id for g in k.grants]
        names = sorted(session.scalars(select(Spacecraft.name).where(Spacecraft.id.in_(ids)))) if session else []
    return KeyInfo(k.id, k.name, k.role, k.created_at, k.expires_at, k.revoked_at, names)


def create(session: Session, name: str, role: str, expires_at: dt.datetime | None,
           spacecraft: list[str] | None) -> tuple[KeyInfo, str]:
    """A new key and its secret; ``spacecraft`` names the spacecraft it may use (None: all)."""
    if has_control_characters(name) or not name.strip():
        raise Invalid("the key name must be visible text without control characters (newlines, tabs, ...)")
    if expires_at is not None and expires_at.tzinfo is None:
        raise Invalid("expires_at needs a time zone (e.g. a trailing Z)")
    ids = None
    if spacecraft is not None:
        if role == "admin":
            raise Invalid("admin keys manage every spacecraft; leave spacecraft out")
        found = dict(session.execute(select(Spacecraft.name, Spacecraft.id)
                                     .where(Spacecraft.name.in_(spacecraft))).all())
        missing = sorted(set(spacecraft) - set(found))
        if missing:
            raise Invalid(f"unknown spacecraft: {', '.join(missing)}")
        ids = list(found.values())
    key, secret = create_key(session, name=name, role=role, expires_at=expires_at, spacecraft_ids=ids)
    session.commit()
    return describe(key), secret


def list_keys(session: Session, cursor: str | None, limit: int) -> Page[KeyInfo]:
    """Keys, newest first."""
    rows = list(session.scalars(paginate(select(ApiKey), ApiKey.created_at, ApiKey.id, cursor, limit)))
    page = page_of(rows, limit, lambda r: (r.created_at, r.id))
    return Page([describe(k) for k in page.items], page.next_cursor)


def revoke(session: Session, key_id: str) -> KeyInfo:
    """Revoke the key (at once: its sessions and requests end); revoking twice changes nothing."""
    key = session.get(ApiKey, key_id)
    if key is None:
        raise NotFound(f"API key {key_id!r} not found")
    if key.revoked_at is None:
        key.revoked_at = utcnow()
        session.execute(delete(UiSession).where(UiSession.key_id == key.id))  # its UI sessions end with it
        session.commit()
    return describe(key)
