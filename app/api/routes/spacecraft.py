"""Spacecraft and their versioned configurations (app/services/spacecraft.py)."""

from __future__ import annotations

import datetime as dt
from typing import Any

from fastapi import APIRouter, status
from pydantic import BaseModel, Field

from app.api.deps import Admin, SessionDep, Viewer
from app.config_schema import SpacecraftConfig
from app.names import NAME
from app.services import spacecraft as service
from app.services.spacecraft import Configured

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


def _out(c: Configured) -> SpacecraftOut:
    return SpacecraftOut(name=c.spacecraft.name, created_at=c.spacecraft.created_at, config_version=c.config.version,
                         config=c.config.config, config_created_at=c.config.created_at)


@router.post("", status_code=status.HTTP_201_CREATED, response_model=SpacecraftOut)
def create_spacecraft(body: SpacecraftCreate, session: SessionDep, who: Admin) -> SpacecraftOut:
    return _out(service.create(session, body.name, body.config, who))


@router.get("", response_model=list[SpacecraftOut])
def list_spacecraft(session: SessionDep, who: Viewer) -> list[SpacecraftOut]:
    return [_out(c) for c in service.list_configured(session, who)]


@router.get("/{name}", response_model=SpacecraftOut)
def read_spacecraft(name: str, session: SessionDep, who: Viewer, version: int | None = None) -> SpacecraftOut:
    return _out(service.read(session, name, who, version))


@router.put("/{name}/config", response_model=SpacecraftOut)
def update_config(name: str, config: SpacecraftConfig, session: SessionDep, who: Admin) -> SpacecraftOut:
    """Store a new configuration version; earlier versions stay readable (``?version=``)."""
    return _out(service.update_config(session, name, config, who))


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
    return [CalibrationOut(id=c.id, kind=c.kind, version=c.version, values=c.values, job_id=c.job_id,
                           created_at=c.created_at) for c in service.list_calibrations(session, name, who, kind)]
