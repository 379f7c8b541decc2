"""Spacecraft and their versioned configurations."""

from __future__ import annotations

import datetime as dt
from typing import Any

from fastapi import APIRouter, HTTPException, status
from pydantic import BaseModel, Field
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from app.api.deps import Admin, Principal, SessionDep, Viewer
from app.config_schema import NAME, SpacecraftConfig
from storage import calibrations
from storage.models import Spacecraft
from storage.models import SpacecraftConfig as ConfigRow

router = APIRouter(prefix="/api/v1/spacecraft", tags=["spacecraft"])


class SpacecraftCreate(BaseModel):
    name: str = Field(pattern=NAME.pattern, description="1-64 letters, digits, _ . -")
    config: SpacecraftConfig = Field(default_factory=SpacecraftConfig)


class SpacecraftOut(BaseModel):
    name: str
    created_at: dt.datetime
    config_version: int
    config: dict[str, Any]
    config_created_at: dt.datetime


def get_spacecraft(session: Session, name: str, who: Principal) -> Spacecraft:
    """The named spacecraft if the caller may use it; 404 otherwise (also when it exists but is not
    granted to the caller's key, so that keys cannot probe other spacecraft)."""
    sc = session.scalar(select(Spacecraft).where(Spacecraft.name == name))
    if sc is None or not who.may_use(sc.id):
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"spacecraft {name!r} not found")
    return sc


def latest_config(session: Session, sc: Spacecraft) -> ConfigRow:
    row = session.scalar(select(ConfigRow).where(ConfigRow.spacecraft_id == sc.id)
                         .order_by(ConfigRow.version.desc()).limit(1))
    assert row is not None, "every spacecraft has a configuration version"
    return row


def _out(sc: Spacecraft, cfg: ConfigRow) -> SpacecraftOut:
    return SpacecraftOut(name=sc.name, created_at=sc.created_at, config_version=cfg.version,
                         config=cfg.config, config_created_at=cfg.created_at)


def _dump(config: SpacecraftConfig) -> dict[str, Any]:
    return config.model_dump(mode="json", exclude_none=True)


@router.post("", status_code=status.HTTP_201_CREATED, response_model=SpacecraftOut)
def create_spacecraft(body: SpacecraftCreate, session: SessionDep, who: Admin) -> SpacecraftOut:
    if session.scalar(select(Spacecraft.id).where(Spacecraft.name == body.name)) is not None:
        raise HTTPException(status.HTTP_409_CONFLICT, f"spacecraft {body.name!r} already exists")
    sc = Spacecraft(name=body.name)
    session.add(sc)
    session.flush()
    cfg = ConfigRow(spacecraft_id=sc.id, version=1, config=_dump(body.config), created_by=who.key_id)
    session.add(cfg)
    try:
        session.commit()
    except IntegrityError:
        session.rollback()
        raise HTTPException(status.HTTP_409_CONFLICT, f"spacecraft {body.name!r} already exists") from None
    return _out(sc, cfg)


@router.get("", response_model=list[SpacecraftOut])
def list_spacecraft(session: SessionDep, who: Viewer) -> list[SpacecraftOut]:
    out = []
    for sc in session.scalars(select(Spacecraft).order_by(Spacecraft.name)):
        if who.may_use(sc.id):
            out.append(_out(sc, latest_config(session, sc)))
    return out


@router.get("/{name}", response_model=SpacecraftOut)
def read_spacecraft(name: str, session: SessionDep, who: Viewer, version: int | None = None) -> SpacecraftOut:
    sc = get_spacecraft(session, name, who)
    if version is None:
        return _out(sc, latest_config(session, sc))
    cfg = session.scalar(select(ConfigRow).where(ConfigRow.spacecraft_id == sc.id,
                                                 ConfigRow.version == version))
    if cfg is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"spacecraft {name!r} has no configuration "
                                                       f"version {version}")
    return _out(sc, cfg)


@router.put("/{name}/config", response_model=SpacecraftOut)
def update_config(name: str, config: SpacecraftConfig, session: SessionDep, who: Admin) -> SpacecraftOut:
    """Store a new configuration version; earlier versions stay readable (``?version=``)."""
    sc = get_spacecraft(session, name, who)
    version = (session.scalar(select(func.max(ConfigRow.version))
                              .where(ConfigRow.spacecraft_id == sc.id)) or 0) + 1
    cfg = ConfigRow(spacecraft_id=sc.id, version=version, config=_dump(config), created_by=who.key_id)
    session.add(cfg)
    try:
        session.commit()
    except IntegrityError:
        session.rollback()
        raise HTTPException(status.HTTP_409_CONFLICT, "configuration changed concurrently; retry") from None
    return _out(sc, cfg)


class CalibrationOut(BaseModel):
    id: str
    kind: str
    version: int
    values: dict[str, Any]
    job_id: str | None
    created_at: dt.datetime


@router.get("/{name}/calibrations", response_model=list[CalibrationOut])
def list_calibrations(name: str, session: SessionDep, who: Viewer, kind: str | None = None) -> list[CalibrationOut]:
    """Calibration versions of the spacecraft's sensors, newest first per kind (jobs apply the latest)."""
    sc = get_spacecraft(session, name, who)
    return [CalibrationOut(id=c.id, kind=c.kind, version=c.version, values=c.values, job_id=c.job_id,
                           created_at=c.created_at) for c in calibrations.versions(session, sc.id, kind)]
