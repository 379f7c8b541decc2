"""API key management (admin only). The secret is shown once, at creation."""

from __future__ import annotations

import datetime as dt
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query, Request, Response, status
from pydantic import BaseModel, Field
from sqlalchemy import select
from sqlalchemy.orm import object_session

from app.api.deps import Admin, SessionDep
from app.api.pagination import MAX_LIMIT, announce_next, paginate
from storage.keys import ROLES, create_key
from storage.models import ApiKey, Spacecraft, utcnow

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


def _out(k: ApiKey) -> dict[str, object]:
    names = None
    if not k.all_spacecraft:
        session = object_session(k)
        ids = [g.spacecraft_id for g in k.grants]
        names = sorted(session.scalars(select(Spacecraft.name).where(Spacecraft.id.in_(ids)))) if session else []
    return {"id": k.id, "name": k.name, "role": k.role, "created_at": k.created_at,
            "expires_at": k.expires_at, "revoked_at": k.revoked_at, "spacecraft": names}


@router.post("", status_code=status.HTTP_201_CREATED, response_model=KeyCreated)
def create(body: KeyCreate, session: SessionDep, _: Admin) -> KeyCreated:
    if body.expires_at is not None and body.expires_at.tzinfo is None:
        raise HTTPException(422, "expires_at needs a time zone (e.g. a trailing Z)")
    ids = None
    if body.spacecraft is not None:
        if body.role == "admin":
            raise HTTPException(422, "admin keys manage every spacecraft; leave spacecraft out")
        found = dict(session.execute(select(Spacecraft.name, Spacecraft.id)
                                     .where(Spacecraft.name.in_(body.spacecraft))).all())
        missing = sorted(set(body.spacecraft) - set(found))
        if missing:
            raise HTTPException(422, f"unknown spacecraft: {', '.join(missing)}")
        ids = list(found.values())
    key, secret = create_key(session, name=body.name, role=body.role, expires_at=body.expires_at,
                             spacecraft_ids=ids)
    session.commit()
    return KeyCreated(**_out(key), secret=secret)  # type: ignore[arg-type]


@router.get("", response_model=list[KeyOut])
def list_keys(request: Request, response: Response, session: SessionDep, _: Admin,
              limit: Annotated[int, Query(ge=1, le=MAX_LIMIT)] = 100, cursor: str | None = None) -> list[KeyOut]:
    """Keys, newest first (never their secrets); more pages in ``X-Next-Cursor``/``Link``."""
    rows = list(session.scalars(paginate(select(ApiKey), ApiKey.created_at, ApiKey.id, cursor, limit)))
    rows = announce_next(request, response, rows, limit, lambda r: (r.created_at, r.id))
    return [KeyOut(**_out(k)) for k in rows]  # type: ignore[arg-type]


@router.delete("/{key_id}", response_model=KeyOut)
def revoke(key_id: str, session: SessionDep, _: Admin) -> KeyOut:
    key = session.get(ApiKey, key_id)
    if key is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"API key {key_id!r} not found")
    if key.revoked_at is None:
        key.revoked_at = utcnow()
        session.commit()
    return KeyOut(**_out(key))  # type: ignore[arg-type]
