"""API key management (admin only; app/services/keys.py). The secret is shown once, at creation."""

from __future__ import annotations

import dataclasses
import datetime as dt
from typing import Annotated

from fastapi import APIRouter, Query, Request, Response, status
from pydantic import BaseModel, Field

from app.api.deps import Admin, SessionDep
from app.api.pagination import MAX_LIMIT, announce_next
from app.services import keys as service
from app.services.keys import KeyInfo
from storage.keys import ROLES

router = APIRouter(prefix="/api/v1/keys", tags=["keys"])


class KeyCreate(BaseModel):
    name: str = Field(min_length=1, max_length=100)
    role: str = Field(pattern="^(" + "|".join(ROLES) + ")$")
    expires_at: dt.datetime | None = None
    spacecraft: list[str] | None = Field(None, description="names of the spacecraft the key may use; "
                                                          "null: all (admin keys always have all)")


class KeyOut(BaseModel):
    id: str
    name: str
    role: str
    created_at: dt.datetime
    expires_at: dt.datetime | None
    revoked_at: dt.datetime | None
    spacecraft: list[str] | None


class KeyCreated(KeyOut):
    secret: str = Field(description="shown only in this response")


def _out(k: KeyInfo) -> KeyOut:
    return KeyOut(**dataclasses.asdict(k))


@router.post("", status_code=status.HTTP_201_CREATED, response_model=KeyCreated)
def create(body: KeyCreate, session: SessionDep, _: Admin) -> KeyCreated:
    key, secret = service.create(session, body.name, body.role, body.expires_at, body.spacecraft)
    return KeyCreated(**dataclasses.asdict(key), secret=secret)


@router.get("", response_model=list[KeyOut])
def list_keys(request: Request, response: Response, session: SessionDep, _: Admin,
              limit: Annotated[int, Query(ge=1, le=MAX_LIMIT)] = 100, cursor: str | None = None) -> list[KeyOut]:
    """Keys, newest first (never their secrets); more pages in ``X-Next-Cursor``/``Link``."""
    return [_out(k) for k in announce_next(request, response, service.list_keys(session, cursor, limit), limit)]


@router.delete("/{key_id}", response_model=KeyOut)
def revoke(key_id: str, session: SessionDep, _: Admin) -> KeyOut:
    return _out(service.revoke(session, key_id))
