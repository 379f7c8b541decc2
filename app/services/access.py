"""The caller's identity: an API key's role and the spacecraft it is granted (the same for API and UI)."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.orm import Session

from storage.keys import find_active, granted_spacecraft


@dataclass(frozen=True)
class Principal:
    """The caller: its key, role and the spacecraft it may use (None: all)."""

    key_id: str
    name: str
    role: str
    spacecraft_ids: frozenset[int] | None = None

    def may_use(self, spacecraft_id: int) -> bool:
        return self.spacecraft_ids is None or spacecraft_id in self.spacecraft_ids


def identify(session: Session, secret: str) -> Principal | None:
    """The caller holding ``secret``; None for an unknown, expired or revoked key."""
    key = find_active(session, secret)
    if key is None:
        return None
    return Principal(key.id, key.name, key.role, granted_spacecraft(key))
