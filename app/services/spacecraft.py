"""Spacecraft, their versioned configurations and calibrations, and the overview of what is stored."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from app.config_schema import SpacecraftConfig
from app.names import valid_name
from app.services.access import Principal
from app.services.errors import Conflict, Invalid, NotFound
from storage import calibrations
from storage.models import Calibration, Job, Spacecraft, TelemetryFile
from storage.models import SpacecraftConfig as ConfigRow


@dataclass(frozen=True)
class Configured:
    """A spacecraft with one version of its configuration."""

    spacecraft: Spacecraft
    config: ConfigRow


@dataclass(frozen=True)
class StreamExtent:
    stream: str
    first: int  # TAI ns
    last: int
    rows: int


@dataclass(frozen=True)
class Overview:
    """What the catalog holds for one spacecraft: configuration version, telemetry, jobs."""

    name: str
    config_version: int
    streams: list[StreamExtent]
    n_jobs: int
    last_job: Job | None


def get_spacecraft(session: Session, name: str, who: Principal) -> Spacecraft:
    """The named spacecraft if the caller may use it; NotFound otherwise (also when it exists but is
    not granted to the caller's key, so that keys cannot probe other spacecraft)."""
    sc = session.scalar(select(Spacecraft).where(Spacecraft.name == name))
    if sc is None or not who.may_use(sc.id):
        raise NotFound(f"spacecraft {name!r} not found")
    return sc


def latest_config(session: Session, sc: Spacecraft) -> ConfigRow:
    row = session.scalar(select(ConfigRow).where(ConfigRow.spacecraft_id == sc.id)
                         .order_by(ConfigRow.version.desc()).limit(1))
    assert row is not None, "every spacecraft has a configuration version"
    return row


def visible_spacecraft(session: Session, who: Principal) -> list[Spacecraft]:
    """The spacecraft the caller may use, by name."""
    return [sc for sc in session.scalars(select(Spacecraft).order_by(Spacecraft.name)) if who.may_use(sc.id)]


def _dump(config: SpacecraftConfig) -> dict[str, Any]:
    return config.model_dump(mode="json", exclude_none=True)


def create(session: Session, name: str, config: SpacecraftConfig, who: Principal) -> Configured:
    """A new spacecraft with configuration version 1; Invalid for a name that is not one
    (:func:`app.config_schema.valid_name`), Conflict when the name is taken."""
    if not valid_name(name):
        raise Invalid(f"spacecraft name {name!r} must be 1-64 letters, digits, _ . - and not only dots")
    if session.scalar(select(Spacecraft.id).where(Spacecraft.name == name)) is not None:
        raise Conflict(f"spacecraft {name!r} already exists")
    sc = Spacecraft(name=name)
    session.add(sc)
    session.flush()
    cfg = ConfigRow(spacecraft_id=sc.id, version=1, config=_dump(config), created_by=who.key_id)
    session.add(cfg)
    try:
        session.commit()
    except IntegrityError:
        session.rollback()
        raise Conflict(f"spacecraft {name!r} already exists") from None
    return Configured(sc, cfg)


def list_configured(session: Session, who: Principal) -> list[Configured]:
    """The caller's spacecraft with their latest configurations, by name."""
    return [Configured(sc, latest_config(session, sc)) for sc in visible_spacecraft(session, who)]


def read(session: Session, name: str, who: Principal, version: int | None = None) -> Configured:
    """The spacecraft with its latest configuration, or with configuration ``version``."""
    sc = get_spacecraft(session, name, who)
    if version is None:
        return Configured(sc, latest_config(session, sc))
    cfg = session.scalar(select(ConfigRow).where(ConfigRow.spacecraft_id == sc.id, ConfigRow.version == version))
    if cfg is None:
        raise NotFound(f"spacecraft {name!r} has no configuration version {version}")
    return Configured(sc, cfg)


def update_config(session: Session, name: str, config: SpacecraftConfig, who: Principal) -> Configured:
    """Store a new configuration version; earlier versions stay readable."""
    sc = get_spacecraft(session, name, who)
    version = (session.scalar(select(func.max(ConfigRow.version)).where(ConfigRow.spacecraft_id == sc.id)) or 0) + 1
    cfg = ConfigRow(spacecraft_id=sc.id, version=version, config=_dump(config), created_by=who.key_id)
    session.add(cfg)
    try:
        session.commit()
    except IntegrityError:
        session.rollback()
        raise Conflict("configuration changed concurrently; retry") from None
    return Configured(sc, cfg)


def list_calibrations(session: Session, name: str, who: Principal, kind: str | None = None) -> list[Calibration]:
    """Calibration versions of the spacecraft's sensors, newest first per kind (jobs apply the latest)."""
    sc = get_spacecraft(session, name, who)
    return list(calibrations.versions(session, sc.id, kind))


def overview(session: Session, who: Principal) -> list[Overview]:
    """Per spacecraft the caller may use: configuration version, stored streams, jobs and the latest job."""
    out = []
    for sc in visible_spacecraft(session, who):
        streams = session.execute(
            select(TelemetryFile.stream, func.min(TelemetryFile.t_min_tai_ns), func.max(TelemetryFile.t_max_tai_ns),
                   func.sum(TelemetryFile.rows)).where(TelemetryFile.spacecraft_id == sc.id)
            .group_by(TelemetryFile.stream).order_by(TelemetryFile.stream)).all()
        last_job = session.scalar(select(Job).where(Job.spacecraft_id == sc.id)
                                  .order_by(Job.created_at.desc()).limit(1))
        n_jobs = session.scalar(select(func.count(Job.id)).where(Job.spacecraft_id == sc.id)) or 0
        out.append(Overview(sc.name, latest_config(session, sc).version,
                            [StreamExtent(s, int(a), int(b), int(n or 0)) for s, a, b, n in streams], n_jobs, last_job))
    return out
