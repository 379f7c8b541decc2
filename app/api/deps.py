"""Request dependencies: the catalog session, the telemetry store, the settings, the authenticated caller
(:class:`app.services.access.Principal`)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Annotated, Any

from fastapi import Depends, HTTPException, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session

from app.api.gate import PRINCIPAL_KEY
from app.api.middleware import retry_after_header
from app.services.access import Principal, identify
from app.settings import Settings
from storage.keys import role_at_least
from storage.parquet_store import ParquetStore


def get_session(request: Request) -> Iterator[Session]:
    with request.app.state.sessions() as session:
        yield session


def get_store(request: Request) -> ParquetStore:
    store: ParquetStore = request.app.state.store
    return store


def get_settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


SessionDep = Annotated[Session, Depends(get_session)]
StoreDep = Annotated[ParquetStore, Depends(get_store)]
SettingsDep = Annotated[Settings, Depends(get_settings)]

_bearer = HTTPBearer(auto_error=False, description="API key: `Authorization: Bearer <key>`")


def _authenticate(request: Request,
                  credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]) -> Principal:
    """The caller the API gate (app/api/gate.py) authenticated before routing; the checks below only
    serve an app mounted without the gate."""
    gated: Principal | None = request.scope.get(PRINCIPAL_KEY)
    if gated is not None:
        return gated
    if credentials is None or credentials.scheme.lower() != "bearer" or not credentials.credentials:
        raise HTTPException(status.HTTP_401_UNAUTHORIZED, "missing API key (Authorization: Bearer <key>)",
                            headers={"WWW-Authenticate": "Bearer"})
    with request.app.state.sessions() as session:
        principal = identify(session, credentials.credentials)
    if principal is None:
        raise HTTPException(status.HTTP_401_UNAUTHORIZED, "invalid, expired or revoked API key",
                            headers={"WWW-Authenticate": "Bearer"})
    wait = request.app.state.rate_limiter.acquire(principal.key_id)
    if wait > 0:
        raise HTTPException(status.HTTP_429_TOO_MANY_REQUESTS,
                            f"rate limit of {request.app.state.settings.rate_limit_per_minute} requests per "
                            f"minute exceeded for this key; retry in {wait:.1f} s", headers=retry_after_header(wait))
    return principal


def require(role: str) -> Callable[[Principal], Principal]:
    """Dependency factory: the caller's key must have at least ``role``."""

    def check(principal: Annotated[Principal, Depends(_authenticate)]) -> Principal:
        if not role_at_least(principal.role, role):
            raise HTTPException(status.HTTP_403_FORBIDDEN,
                                f"this needs the {role} role; your key has {principal.role}")
        return principal

    return check


Viewer = Annotated[Principal, Depends(require("viewer"))]
Operator = Annotated[Principal, Depends(require("operator"))]
Admin = Annotated[Principal, Depends(require("admin"))]


def _query_names(dependant: Any) -> set[str]:
    names = {p.alias for p in dependant.query_params}
    for sub in dependant.dependencies:
        names |= _query_names(sub)
    return names


def reject_unknown_query(request: Request) -> None:
    """422 for query parameters the route does not define: a misspelt ``strat=`` must not be ignored."""
    route = request.scope.get("route")
    dependant = getattr(route, "dependant", None)
    if dependant is None:
        return
    allowed = _query_names(dependant)
    unknown = sorted(k for k in request.query_params if k not in allowed)
    if unknown:
        hint = f"; this route takes {', '.join(sorted(allowed))}" if allowed else "; this route takes none"
        raise HTTPException(422, f"unknown query parameter(s): {', '.join(map(repr, unknown))}{hint}")


RejectUnknownQuery = Depends(reject_unknown_query)
