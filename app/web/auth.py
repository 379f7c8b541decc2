"""Web UI sign-in: an API key opens a server-side session; the same roles and grants as the API.

Signing in with a key creates a session (:func:`storage.keys.start_session`): the cookie holds only its
random id (HttpOnly, SameSite=Lax, Secure over https, path /ui, no expiry date: it ends with the browser
session), the catalog the id's SHA-256, the key and an expiry (``ATTITUDE_UI_SESSION_S``, default 12 h).
The key itself never leaves the sign-in form. Every request looks the session and its key up again, so
an expired session, signing out, or revoking or expiring the key ends it at once; the caller becomes the
same :class:`app.services.access.Principal` the API builds, and is held to the same per-key rate limit.
Forms that change something carry a token derived from the session id (checked with
``hmac.compare_digest``), and requests a browser marks as cross-site (``Sec-Fetch-Site``) are refused.
"""

from __future__ import annotations

import hashlib
import hmac
from collections.abc import Callable
from typing import Annotated

from fastapi import Depends, HTTPException, Request, status

from app.api.middleware import retry_after_header
from app.services.access import Principal
from storage.keys import end_session, find_active, find_session_key, granted_spacecraft, role_at_least, start_session

COOKIE = "attitude_session"
COOKIE_PATH = "/ui"


class LoginRequired(Exception):
    """No valid session: the page answers with a redirect to the sign-in form."""


def session_secret(request: Request) -> str | None:
    """The session id in the cookie (not a key: a key there opens nothing)."""
    return request.cookies.get(COOKIE) or None


def start_ui_session(request: Request, secret: str) -> str | None:
    """Sign in with the API key ``secret``: a new session id, or None for a key that is not active."""
    with request.app.state.sessions.begin() as session:
        key = find_active(session, secret)
        if key is None:
            return None
        return start_session(session, key, request.app.state.settings.ui_session_s)


def end_ui_session(request: Request) -> None:
    token = session_secret(request)
    if token is not None:
        with request.app.state.sessions.begin() as session:
            end_session(session, token)


def principal_from_session(request: Request, token: str) -> Principal | None:
    with request.app.state.sessions() as session:
        key = find_session_key(session, token)
        return None if key is None else Principal(key.id, key.name, key.role, granted_spacecraft(key))


def current_principal(request: Request) -> Principal | None:
    """The signed-in caller, or None; 429 when the key is over its rate limit (as in the API)."""
    token = session_secret(request)
    if token is None:
        return None
    principal = principal_from_session(request, token)
    if principal is None:
        return None
    wait = request.app.state.rate_limiter.acquire(principal.key_id)
    if wait > 0:
        raise HTTPException(status.HTTP_429_TOO_MANY_REQUESTS,
                            f"rate limit of {request.app.state.settings.rate_limit_per_minute} requests per "
                            f"minute exceeded for this key; retry in {wait:.1f} s", headers=retry_after_header(wait))
    request.state.principal = principal
    return principal


def require(role: str) -> Callable[[Request], Principal]:
    """Dependency factory: a signed-in caller whose key has at least ``role`` (else sign-in or 403)."""

    def check(request: Request) -> Principal:
        principal = current_principal(request)
        if principal is None:
            raise LoginRequired()
        if not role_at_least(principal.role, role):
            raise HTTPException(status.HTTP_403_FORBIDDEN,
                                f"this needs the {role} role; your key has {principal.role}")
        return principal

    return check


WebViewer = Annotated[Principal, Depends(require("viewer"))]
WebOperator = Annotated[Principal, Depends(require("operator"))]
WebAdmin = Annotated[Principal, Depends(require("admin"))]


def csrf_token(secret: str) -> str:
    """The form token of a session: an HMAC of a fixed label under the session id."""
    return hmac.new(secret.encode(), b"attitude-web-form", hashlib.sha256).hexdigest()


def check_same_site(request: Request) -> None:
    """Refuse state-changing requests a browser marks as coming from another site."""
    site = request.headers.get("sec-fetch-site")
    if site is not None and site not in ("same-origin", "none"):
        raise HTTPException(status.HTTP_403_FORBIDDEN, "cross-site form submissions are refused")


def check_form(request: Request, token: str | None) -> None:
    """A state-changing form of a signed-in session: same site and the session's form token."""
    check_same_site(request)
    secret = session_secret(request)
    if secret is None or not token or not hmac.compare_digest(token, csrf_token(secret)):
        raise HTTPException(status.HTTP_403_FORBIDDEN, "the form has expired or did not come from this site; "
                                                       "reload the page and try again")
