"""The FastAPI application: wiring of settings, catalog, telemetry store and routers."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.requests import Request
from fastapi.responses import JSONResponse
from sqlalchemy import text

from app.api.deps import RejectUnknownQuery
from app.api.errors import COMMON_ERRORS, handle_service_errors
from app.api.gate import ApiGateMiddleware, FailureThrottle
from app.api.middleware import BodyLimitMiddleware, RateLimiter, SecurityHeadersMiddleware
from app.api.routes import exports, ingests, jobs, keys, reference, schedules, spacecraft, telemetry
from app.api.schemas import install as typed_openapi
from app.jobs.dask_executor import make_executor
from app.jobs.scheduler import Scheduler
from app.settings import Settings
from app.version import __version__
from app.web import router as web_router
from storage.db import make_engine, session_factory, upgrade
from storage.errors import DamagedFileError, StorageFullError
from storage.keys import ensure_bootstrap_key
from storage.parquet_store import ParquetStore
from storage.telemetry import sweep_orphans

log = logging.getLogger("attitude")


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the app; start-up migrates the catalog, ensures the bootstrap key, removes orphan files."""
    settings = settings or Settings.from_env()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        engine = make_engine(settings.database_url)
        upgrade(engine)
        sessions = session_factory(engine)
        store = ParquetStore(settings.telemetry_url)
        with sessions.begin() as session:
            if settings.bootstrap_token:
                ensure_bootstrap_key(session, settings.bootstrap_token)
        removed = sweep_orphans(sessions, store)
        if removed:
            log.warning("removed %d unreferenced telemetry files left by an interrupted ingest", len(removed))
        app.state.settings = settings
        app.state.engine = engine
        app.state.sessions = sessions
        app.state.store = store
        executor = make_executor(settings, sessions)  # ATTITUDE_EXECUTOR=local|dask
        app.state.executor = executor
        executor.start()
        scheduler = Scheduler(settings, sessions, on_submit=executor.wake)
        app.state.scheduler = scheduler
        if settings.scheduler:
            scheduler.start()
        try:
            yield
        finally:
            scheduler.stop()
            executor.stop()
            engine.dispose()

    app = FastAPI(title="Attitude telemetry service", version=__version__, lifespan=lifespan,
                  description="Ingest spacecraft attitude telemetry; calibrations, reconstructed "
                              "attitude and accuracy reports.")

    app.state.rate_limiter = RateLimiter(settings.rate_limit_per_minute)
    app.state.auth_throttle = FailureThrottle(settings.auth_failures_per_minute)
    # outermost last: security headers -> CORS -> the API gate (authentication first) -> body limit -> routes
    app.add_middleware(BodyLimitMiddleware, limit=settings.max_upload_bytes)
    app.add_middleware(ApiGateMiddleware, sessions=lambda: app.state.sessions(), rate_limiter=app.state.rate_limiter,
                       throttle=app.state.auth_throttle, rate_limit_per_minute=settings.rate_limit_per_minute)
    if settings.cors_origins:  # off unless configured
        app.add_middleware(CORSMiddleware, allow_origins=list(settings.cors_origins),
                           allow_methods=["GET", "POST", "PUT", "DELETE"],
                           allow_headers=["Authorization", "Content-Type"])
    app.add_middleware(SecurityHeadersMiddleware)

    handle_service_errors(app)  # refusals of app/services (app/services/errors.py) -> 4xx

    @app.exception_handler(RequestValidationError)
    async def _validation(_: Request, exc: RequestValidationError) -> JSONResponse:
        errors = [{"row": None, "column": ".".join(str(p) for p in e.get("loc", ())[1:]) or None,
                   "message": e.get("msg", "invalid")} for e in exc.errors()]
        return JSONResponse(status_code=422, content={"detail": "invalid request", "errors": errors,
                                                      "error_count": len(errors)})

    @app.exception_handler(DamagedFileError)
    async def _damaged(_: Request, exc: DamagedFileError) -> JSONResponse:
        return JSONResponse(status_code=503, content={
            "detail": str(exc), "file": exc.path, "ingest_id": exc.ingest_id, "stream": exc.stream,
            "reason": exc.reason})

    @app.exception_handler(StorageFullError)
    async def _full(_: Request, exc: StorageFullError) -> JSONResponse:
        return JSONResponse(status_code=507, content={"detail": str(exc)})

    @app.exception_handler(Exception)
    async def _internal(request: Request, exc: Exception) -> JSONResponse:  # every 5xx body is JSON
        log.error("internal error on %s %s", request.method, request.url.path, exc_info=exc)
        return JSONResponse(status_code=500, content={
            "detail": f"internal error ({type(exc).__name__}); the server log has the details"})

    @app.get("/healthz", tags=["health"])
    def healthz(request: Request) -> dict[str, str]:
        with request.app.state.engine.connect() as conn:
            conn.execute(text("SELECT 1"))
        return {"status": "ok", "version": __version__}

    app.include_router(spacecraft.router, responses=COMMON_ERRORS, dependencies=[RejectUnknownQuery])
    app.include_router(telemetry.router, responses=COMMON_ERRORS, dependencies=[RejectUnknownQuery])
    app.include_router(ingests.router, responses=COMMON_ERRORS, dependencies=[RejectUnknownQuery])
    app.include_router(telemetry.formats_router, responses=COMMON_ERRORS, dependencies=[RejectUnknownQuery])
    app.include_router(keys.router, responses=COMMON_ERRORS, dependencies=[RejectUnknownQuery])
    app.include_router(jobs.router, responses=COMMON_ERRORS, dependencies=[RejectUnknownQuery])
    app.include_router(reference.router, responses=COMMON_ERRORS, dependencies=[RejectUnknownQuery])
    app.include_router(exports.router, responses=COMMON_ERRORS, dependencies=[RejectUnknownQuery])
    app.include_router(schedules.router, responses=COMMON_ERRORS, dependencies=[RejectUnknownQuery])
    app.include_router(web_router)  # the web UI under /ui (cookie sessions; app/web)
    typed_openapi(app)  # params/result unions on the job type, enums, examples, per-route errors
    return app
