"""Catalog ORM models (SQLAlchemy 2).

Times of telemetry are int64 TAI nanoseconds (``*_tai_ns``); wall-clock bookkeeping times
(created_at, ...) are timezone-aware UTC datetimes.
"""

from __future__ import annotations

import datetime as dt
import uuid
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Date,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.engine import Dialect
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship
from sqlalchemy.types import TypeDecorator


def utcnow() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def new_id() -> str:
    return uuid.uuid4().hex


class UTCDateTime(TypeDecorator[dt.datetime]):
    """Timezone-aware UTC datetimes on every backend (SQLite stores them naive)."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: dt.datetime | None, dialect: Dialect) -> dt.datetime | None:
        if value is None:
            return None
        if value.tzinfo is None:
            raise ValueError("naive datetime given to a UTC column")
        return value.astimezone(dt.UTC)

    def process_result_value(self, value: dt.datetime | None, dialect: Dialect) -> dt.datetime | None:
        if value is None:
            return None
        return value.replace(tzinfo=dt.UTC) if value.tzinfo is None else value.astimezone(dt.UTC)


class Base(DeclarativeBase):
    type_annotation_map = {dict[str, Any]: JSON, dt.datetime: UTCDateTime()}


class Spacecraft(Base):
    __tablename__ = "spacecraft"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)

    configs: Mapped[list[SpacecraftConfig]] = relationship(
        back_populates="spacecraft", order_by="SpacecraftConfig.version"
    )


class SpacecraftConfig(Base):
    """One version of a spacecraft's sensor configuration (DESIGN.md JSON shape)."""

    __tablename__ = "spacecraft_config"
    __table_args__ = (UniqueConstraint("spacecraft_id", "version"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    spacecraft_id: Mapped[int] = mapped_column(ForeignKey("spacecraft.id", ondelete="CASCADE"))
    version: Mapped[int] = mapped_column(Integer)
    config: Mapped[dict[str, Any]]
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    created_by: Mapped[str | None] = mapped_column(String(32), nullable=True)

    spacecraft: Mapped[Spacecraft] = relationship(back_populates="configs")


class Ingest(Base):
    """One accepted upload: what came, what was stored and where."""

    __tablename__ = "ingest"
    __table_args__ = (Index("ix_ingest_sc_stream", "spacecraft_id", "stream", "created_at"),)

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    spacecraft_id: Mapped[int] = mapped_column(ForeignKey("spacecraft.id", ondelete="CASCADE"))
    stream: Mapped[str] = mapped_column(String(32))
    sensor: Mapped[str] = mapped_column(String(200))
    rows: Mapped[int] = mapped_column(Integer)
    inserted: Mapped[int] = mapped_column(Integer)
    duplicates: Mapped[int] = mapped_column(Integer)
    start_tai_ns: Mapped[int] = mapped_column(BigInteger)
    end_tai_ns: Mapped[int] = mapped_column(BigInteger)
    filename: Mapped[str | None] = mapped_column(String(255), nullable=True)
    content_type: Mapped[str] = mapped_column(String(100))
    size_bytes: Mapped[int] = mapped_column(BigInteger)
    checksum_sha256: Mapped[str] = mapped_column(String(64))
    time_scale: Mapped[str] = mapped_column(String(8))
    status: Mapped[str] = mapped_column(String(16))  # stored | duplicate
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    api_key_id: Mapped[str | None] = mapped_column(String(32), nullable=True)

    files: Mapped[list[TelemetryFile]] = relationship(back_populates="ingest", cascade="all, delete-orphan")


class TelemetryFile(Base):
    """A published Parquet file. Readers see exactly the files that have a row here."""

    __tablename__ = "telemetry_file"
    __table_args__ = (
        Index("ix_tfile_window", "spacecraft_id", "stream", "t_min_tai_ns", "t_max_tai_ns"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    ingest_id: Mapped[str] = mapped_column(ForeignKey("ingest.id", ondelete="CASCADE"))
    spacecraft_id: Mapped[int] = mapped_column(ForeignKey("spacecraft.id", ondelete="CASCADE"))
    stream: Mapped[str] = mapped_column(String(32))
    day: Mapped[dt.date] = mapped_column(Date)
    path: Mapped[str] = mapped_column(Text, unique=True)
    rows: Mapped[int] = mapped_column(Integer)
    t_min_tai_ns: Mapped[int] = mapped_column(BigInteger)
    t_max_tai_ns: Mapped[int] = mapped_column(BigInteger)
    sensors: Mapped[str] = mapped_column(String(200))
    quarantined: Mapped[str | None] = mapped_column(Text, nullable=True)  # why it cannot be read; None: healthy
    quarantined_at: Mapped[dt.datetime | None] = mapped_column(nullable=True)

    ingest: Mapped[Ingest] = relationship(back_populates="files")


class ApiKey(Base):
    """An API key: only the SHA-256 of the secret is stored."""

    __tablename__ = "api_key"

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    name: Mapped[str] = mapped_column(String(100))
    secret_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    role: Mapped[str] = mapped_column(String(16))  # admin | operator | viewer
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    expires_at: Mapped[dt.datetime | None] = mapped_column(nullable=True)
    revoked_at: Mapped[dt.datetime | None] = mapped_column(nullable=True)
    all_spacecraft: Mapped[bool] = mapped_column(default=True)  # False: only the granted spacecraft

    grants: Mapped[list[ApiKeyGrant]] = relationship(cascade="all, delete-orphan")


class ApiKeyGrant(Base):
    """A spacecraft an API key without ``all_spacecraft`` may see and act on."""

    __tablename__ = "api_key_grant"

    key_id: Mapped[str] = mapped_column(ForeignKey("api_key.id", ondelete="CASCADE"), primary_key=True)
    spacecraft_id: Mapped[int] = mapped_column(ForeignKey("spacecraft.id", ondelete="CASCADE"), primary_key=True)


class UiSession(Base):
    """A signed-in web UI session: the cookie holds the random token, the catalog its SHA-256."""

    __tablename__ = "ui_session"
    __table_args__ = (Index("ix_ui_session_key", "key_id"),)

    token_sha256: Mapped[str] = mapped_column(String(64), primary_key=True)
    key_id: Mapped[str] = mapped_column(ForeignKey("api_key.id", ondelete="CASCADE"))
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    expires_at: Mapped[dt.datetime]


class Job(Base):
    """A batch job: the catalog row is the source of truth of its state."""

    __tablename__ = "job"
    __table_args__ = (Index("ix_job_status", "status", "created_at"),
                      Index("ix_job_sc_type", "spacecraft_id", "type", "created_at"))

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    type: Mapped[str] = mapped_column(String(64))
    spacecraft_id: Mapped[int] = mapped_column(ForeignKey("spacecraft.id", ondelete="CASCADE"))
    config_version: Mapped[int] = mapped_column(Integer)
    start_tai_ns: Mapped[int] = mapped_column(BigInteger)
    end_tai_ns: Mapped[int] = mapped_column(BigInteger)
    params: Mapped[dict[str, Any]]
    status: Mapped[str] = mapped_column(String(16), default="queued")
    progress: Mapped[float] = mapped_column(Float, default=0.0)
    stage: Mapped[str] = mapped_column(String(200), default="queued")
    result: Mapped[dict[str, Any] | None] = mapped_column(nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    cancel_requested: Mapped[bool] = mapped_column(default=False)
    software_version: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    started_at: Mapped[dt.datetime | None] = mapped_column(nullable=True)
    finished_at: Mapped[dt.datetime | None] = mapped_column(nullable=True)
    heartbeat_at: Mapped[dt.datetime | None] = mapped_column(nullable=True)
    api_key_id: Mapped[str | None] = mapped_column(String(32), nullable=True)
    reference: Mapped[dict[str, Any]] = mapped_column(default=dict)  # kind -> reference dataset id used

    artifacts: Mapped[list[Artifact]] = relationship(back_populates="job", order_by="Artifact.name")


class Artifact(Base):
    """A file produced by a job (table, figure, summary), stored under the data directory."""

    __tablename__ = "artifact"
    __table_args__ = (UniqueConstraint("job_id", "name"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    job_id: Mapped[str] = mapped_column(ForeignKey("job.id", ondelete="CASCADE"))
    name: Mapped[str] = mapped_column(String(200))
    kind: Mapped[str] = mapped_column(String(16))  # table | figure | summary | report
    media_type: Mapped[str] = mapped_column(String(100))
    path: Mapped[str] = mapped_column(Text)
    size_bytes: Mapped[int] = mapped_column(BigInteger)
    checksum_sha256: Mapped[str] = mapped_column(String(64))
    description: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)

    job: Mapped[Job] = relationship(back_populates="artifacts")


class ReferenceDataset(Base):
    """An uploaded reference file (Earth orientation, GNSS navigation, reference orbit, ...):
    the raw file as received and its parsed columns, both kept under the data directory."""

    __tablename__ = "reference_dataset"
    __table_args__ = (Index("ix_reference_kind", "kind", "created_at"),
                      Index("ix_reference_sc_kind", "spacecraft_id", "kind"))

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    kind: Mapped[str] = mapped_column(String(64))
    name: Mapped[str] = mapped_column(String(255))
    filename: Mapped[str | None] = mapped_column(String(255), nullable=True)
    size_bytes: Mapped[int] = mapped_column(BigInteger)
    checksum_sha256: Mapped[str] = mapped_column(String(64))
    raw_path: Mapped[str] = mapped_column(Text)
    parsed_path: Mapped[str] = mapped_column(Text)
    rows: Mapped[int] = mapped_column(Integer)
    start_tai_ns: Mapped[int | None] = mapped_column(BigInteger, nullable=True)
    end_tai_ns: Mapped[int | None] = mapped_column(BigInteger, nullable=True)
    details: Mapped[dict[str, Any]]
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    api_key_id: Mapped[str | None] = mapped_column(String(32), nullable=True)
    # the spacecraft whose jobs may use it; None: shared by every spacecraft (uploaded by an admin)
    spacecraft_id: Mapped[int | None] = mapped_column(ForeignKey("spacecraft.id", ondelete="CASCADE"), nullable=True)
    spacecraft: Mapped[Spacecraft | None] = relationship(lazy="joined")


class Schedule(Base):
    """A cron schedule (UTC) that submits one job per tick from a template and a relative window."""

    __tablename__ = "schedule"
    __table_args__ = (Index("ix_schedule_due", "enabled", "next_fire_at"),)

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    name: Mapped[str] = mapped_column(String(100), unique=True)
    cron: Mapped[str] = mapped_column(String(120))
    job_type: Mapped[str] = mapped_column(String(64))
    spacecraft_id: Mapped[int] = mapped_column(ForeignKey("spacecraft.id", ondelete="CASCADE"))
    params: Mapped[dict[str, Any]]
    reference: Mapped[dict[str, Any]] = mapped_column(default=dict)
    window: Mapped[str] = mapped_column(String(32))  # previous | since_last_success
    window_s: Mapped[int | None] = mapped_column(BigInteger, nullable=True)
    enabled: Mapped[bool] = mapped_column(default=True)
    next_fire_at: Mapped[dt.datetime | None] = mapped_column(nullable=True)
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    api_key_id: Mapped[str | None] = mapped_column(String(32), nullable=True)


class ScheduleRun(Base):
    """One tick of a schedule; the unique (schedule, fire time) makes each tick fire exactly once."""

    __tablename__ = "schedule_run"
    __table_args__ = (UniqueConstraint("schedule_id", "fire_at", name="uq_schedule_run_tick"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    schedule_id: Mapped[str] = mapped_column(ForeignKey("schedule.id", ondelete="CASCADE"))
    fire_at: Mapped[dt.datetime]
    status: Mapped[str] = mapped_column(String(16))  # submitted | skipped
    job_id: Mapped[str | None] = mapped_column(ForeignKey("job.id", ondelete="SET NULL"), nullable=True)
    missed: Mapped[int] = mapped_column(Integer, default=0)  # earlier ticks coalesced into this one
    message: Mapped[str | None] = mapped_column(Text, nullable=True)
    fired_by: Mapped[str] = mapped_column(String(100))
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)


class Calibration(Base):
    """A calibration version of one of a spacecraft's sensors (e.g. the gyro: mounting, scale factor,
    drift), produced by a job; later jobs apply the latest unless told not to."""

    __tablename__ = "calibration"
    __table_args__ = (UniqueConstraint("spacecraft_id", "kind", "version"),)

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    spacecraft_id: Mapped[int] = mapped_column(ForeignKey("spacecraft.id", ondelete="CASCADE"))
    kind: Mapped[str] = mapped_column(String(32))  # gyro
    version: Mapped[int] = mapped_column(Integer)
    values: Mapped[dict[str, Any]]
    job_id: Mapped[str | None] = mapped_column(ForeignKey("job.id", ondelete="SET NULL"), nullable=True)
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)


class IngestRetraction(Base):
    """The log of a retracted ingest: what it had stored, who retracted it, when and why."""

    __tablename__ = "ingest_retraction"
    __table_args__ = (Index("ix_retraction_sc", "spacecraft_id", "retracted_at"),)

    id: Mapped[str] = mapped_column(String(32), primary_key=True, default=new_id)
    spacecraft_id: Mapped[int] = mapped_column(ForeignKey("spacecraft.id", ondelete="CASCADE"))
    ingest_id: Mapped[str] = mapped_column(String(32))  # the ingest row is gone; its id stays here
    stream: Mapped[str] = mapped_column(String(32))
    sensor: Mapped[str] = mapped_column(String(200))
    rows: Mapped[int] = mapped_column(Integer)
    inserted: Mapped[int] = mapped_column(Integer)  # samples it had stored (now removed)
    start_tai_ns: Mapped[int] = mapped_column(BigInteger)
    end_tai_ns: Mapped[int] = mapped_column(BigInteger)
    filename: Mapped[str | None] = mapped_column(String(255), nullable=True)
    checksum_sha256: Mapped[str] = mapped_column(String(64))
    uploaded_at: Mapped[dt.datetime]
    files_removed: Mapped[int] = mapped_column(Integer)
    reason: Mapped[str] = mapped_column(Text)
    retracted_by: Mapped[str | None] = mapped_column(String(32), nullable=True)  # API key id
    retracted_by_name: Mapped[str | None] = mapped_column(String(100), nullable=True)
    retracted_at: Mapped[dt.datetime] = mapped_column(default=utcnow)


class JobRetraction(Base):
    """A job that had read samples of a retracted ingest: its results rest on retracted data."""

    __tablename__ = "job_retraction"

    job_id: Mapped[str] = mapped_column(ForeignKey("job.id", ondelete="CASCADE"), primary_key=True)
    retraction_id: Mapped[str] = mapped_column(ForeignKey("ingest_retraction.id", ondelete="CASCADE"),
                                               primary_key=True)
