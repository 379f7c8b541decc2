"""Service settings from ``ATTITUDE_*`` environment variables (documented in README.md)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit, urlunsplit


def _int_env(env: dict[str, str], name: str, default: int) -> int:
    raw = env.get(name)
    if raw is None or raw == "":
        return default
    try:
        value = int(raw)
    except ValueError:
        raise ValueError(f"{name} must be an integer, got {raw!r}") from None
    if value <= 0:
        raise ValueError(f"{name} must be positive, got {value}")
    return value


@dataclass(frozen=True)
class Settings:
    """Resolved settings; build with :meth:`from_env`."""

    data_dir: Path
    database_url: str
    bootstrap_token: str | None = None
    max_upload_bytes: int = 1 << 30
    max_error_rows: int = 100
    max_jobs: int = 2
    job_timeout_s: int = 3600
    heartbeat_timeout_s: int = 60
    max_upload_rows: int = 20_000_000
    max_upload_days: int = 1000  # distinct TAI days (one Parquet file each) per upload
    ingest_batch_rows: int = 1_000_000  # rows per decoded, validated and written batch of an upload
    max_read_rows: int = 20_000_000  # rows one telemetry read (GET) may return as Parquet (or read whole)
    stream_read_rows: int = 1_000_000  # CSV/JSON/Arrow reads of windows holding more are streamed in chunks
    rate_limit_per_minute: int = 1200
    auth_failures_per_minute: int = 20  # failed authentications per client address before 429
    cors_origins: tuple[str, ...] = ()
    executor: str = "local"  # local | dask
    dask_address: str | None = None  # scheduler address, e.g. tcp://10.0.0.5:8786
    dask_retries: int = 1  # re-submissions of a job whose Dask worker died
    data_url: str | None = None  # fsspec/pyarrow URL for Parquet and artifacts, e.g. s3://bucket/prefix
    scheduler: bool = True  # run the cron scheduler in this instance
    scheduler_poll_s: float = 1.0
    min_schedule_period_s: int = 60  # closest allowed ticks of a schedule's cron
    # the HTTP server (app/server.py)
    header_timeout_s: int = 10  # request line and headers complete within this
    body_timeout_s: int = 60  # longest pause between two chunks of a request body
    keep_alive_s: int = 5  # an idle keep-alive connection is closed after this
    max_connections: int = 512  # connections (or running requests) beyond this get 503
    forwarded_allow_ips: str | None = None  # proxies whose X-Forwarded-For is trusted (comma-separated)
    max_jobs_per_key: int | None = None  # jobs of one API key running at once; None: max(1, max_jobs - 1)
    max_queued_jobs_per_key: int = 100  # queued jobs of one API key; more submissions get 429
    ui_session_s: int = 43200  # a web UI session ends this long after sign-in
    figures: str = "lazy"  # lazy: a job's figures are drawn on first request (app.jobs.figures); eager: at job end

    @classmethod
    def from_env(cls, env: dict[str, str] | None = None) -> Settings:
        env = dict(os.environ if env is None else env)
        data_dir = Path(env.get("ATTITUDE_DATA_DIR") or "./var").resolve()
        database_url = env.get("ATTITUDE_DATABASE_URL") or f"sqlite:///{data_dir / 'catalog.db'}"
        token = env.get("ATTITUDE_BOOTSTRAP_TOKEN") or None
        return cls(
            data_dir=data_dir,
            database_url=database_url,
            bootstrap_token=token,
            max_upload_bytes=_int_env(env, "ATTITUDE_MAX_UPLOAD_BYTES", 1 << 30),
            max_jobs=_int_env(env, "ATTITUDE_MAX_JOBS", max(1, min(4, os.cpu_count() or 1))),
            job_timeout_s=_int_env(env, "ATTITUDE_JOB_TIMEOUT_S", 3600),
            heartbeat_timeout_s=_int_env(env, "ATTITUDE_JOB_HEARTBEAT_TIMEOUT_S", 60),
            max_upload_rows=_int_env(env, "ATTITUDE_MAX_UPLOAD_ROWS", 20_000_000),
            max_upload_days=_int_env(env, "ATTITUDE_MAX_UPLOAD_DAYS", 1000),
            ingest_batch_rows=_int_env(env, "ATTITUDE_INGEST_BATCH_ROWS", 1_000_000),
            max_read_rows=_int_env(env, "ATTITUDE_MAX_READ_ROWS", 20_000_000),
            stream_read_rows=_int_env(env, "ATTITUDE_STREAM_READ_ROWS", 1_000_000),
            rate_limit_per_minute=_int_env(env, "ATTITUDE_RATE_LIMIT_PER_MINUTE", 1200),
            auth_failures_per_minute=_int_env(env, "ATTITUDE_AUTH_FAILURES_PER_MINUTE", 20),
            min_schedule_period_s=_int_env(env, "ATTITUDE_MIN_SCHEDULE_PERIOD_S", 60),
            header_timeout_s=_int_env(env, "ATTITUDE_HEADER_TIMEOUT_S", 10),
            body_timeout_s=_int_env(env, "ATTITUDE_BODY_TIMEOUT_S", 60),
            keep_alive_s=_int_env(env, "ATTITUDE_KEEP_ALIVE_S", 5),
            max_connections=_int_env(env, "ATTITUDE_MAX_CONNECTIONS", 512),
            forwarded_allow_ips=(env.get("ATTITUDE_FORWARDED_ALLOW_IPS") or "").strip() or None,
            max_jobs_per_key=_int_env(env, "ATTITUDE_MAX_JOBS_PER_KEY", 0) or None,
            max_queued_jobs_per_key=_int_env(env, "ATTITUDE_MAX_QUEUED_JOBS_PER_KEY", 100),
            ui_session_s=_int_env(env, "ATTITUDE_UI_SESSION_S", 43200),
            cors_origins=tuple(o.strip() for o in (env.get("ATTITUDE_CORS_ORIGINS") or "").split(",") if o.strip()),
            figures=_figures_env(env),
            **_scale_out_env(env),
        )

    @property
    def jobs_per_key(self) -> int:
        """Jobs of one API key running at once: by default one slot stays free for the other keys."""
        return self.max_jobs_per_key or max(1, self.max_jobs - 1)

    @property
    def telemetry_dir(self) -> Path:
        return self.data_dir / "telemetry"

    @property
    def artifacts_dir(self) -> Path:
        return self.data_dir / "artifacts"

    def _data_location(self, name: str) -> str:
        if self.data_url:  # the name goes into the URL's path, before any ?query options
            url = urlsplit(self.data_url)
            return urlunsplit(url._replace(path=f"{url.path.rstrip('/')}/{name}"))
        return str(self.data_dir / name)

    @property
    def telemetry_url(self) -> str:
        """Root of the Parquet store: ``<data_url>/telemetry`` or the local ``telemetry_dir``."""
        return self._data_location("telemetry")

    @property
    def artifacts_url(self) -> str:
        return self._data_location("artifacts")

    @property
    def reference_url(self) -> str:
        return self._data_location("reference")


def _figures_env(env: dict[str, str]) -> str:
    """``ATTITUDE_FIGURES``: lazy (default; figures drawn from the stored artifacts on first request) or eager
    (drawn and stored by the job)."""
    mode = (env.get("ATTITUDE_FIGURES") or "lazy").strip().lower()
    if mode not in ("lazy", "eager"):
        raise ValueError(f"ATTITUDE_FIGURES must be lazy or eager, got {mode!r}")
    return mode


def _scale_out_env(env: dict[str, str]) -> dict[str, Any]:
    """Executor, Dask, object-store and scheduler settings (README "Scaling out")."""
    executor = (env.get("ATTITUDE_EXECUTOR") or "local").strip().lower()
    if executor not in ("local", "dask"):
        raise ValueError(f"ATTITUDE_EXECUTOR must be local or dask, got {executor!r}")
    address = env.get("ATTITUDE_DASK_ADDRESS") or None
    if executor == "dask" and not address:
        raise ValueError("ATTITUDE_EXECUTOR=dask needs ATTITUDE_DASK_ADDRESS (e.g. tcp://scheduler:8786)")
    scheduler = (env.get("ATTITUDE_SCHEDULER") or "1").strip().lower()
    if scheduler not in ("0", "1", "true", "false", "yes", "no", "on", "off"):
        raise ValueError(f"ATTITUDE_SCHEDULER must be 1 or 0, got {scheduler!r}")
    retries = env.get("ATTITUDE_DASK_RETRIES")
    return {"executor": executor, "dask_address": address,
            "dask_retries": _int_env(env, "ATTITUDE_DASK_RETRIES", 1) if retries != "0" else 0,
            "data_url": (env.get("ATTITUDE_DATA_URL") or "").rstrip("/") or None,
            "scheduler": scheduler in ("1", "true", "yes", "on")}
