"""Web UI sign-in: the API key in a session cookie, the same roles and grants as the API.

The cookie holds the key's secret (HttpOnly, SameSite=Lax, Secure over https, path /ui, no expiry
date: it ends with the browser session). Every request looks the key up again with
``storage.keys.find_active``, so revoking or expiring a key signs its sessions out at once; the caller
becomes the same :class:`app.services.access.Principal` the API builds, and is held to the same per-key rate
limit. Forms that change something carry a token derived from the secret (checked with
``hmac.compare_digest``), and requests a browser marks as cross-site (``Sec-Fetch-Site``) are refused.
"""

from __future__ import annotations

import hashlib
import hmac
from collections.abc import Callable
from typing import Annotated

from fastapi import Depends, HTTPException, Request, status

from app.api.middleware import retry_after_header
from app.services.access import Principal, identify
from storage.keys import role_at_least

COOKIE = "attitude_session"
COOKIE_PATH = "/ui"


class LoginRequired(Exception):
    """No valid session: the page answers with a redirect to the sign-in form."""


def session_secret(request: Request) -> str | None:
    return request.cookies.get(COOKIE) or None


def principal_from_secret(request: Request, secret: str) -> Principal | None:
    with request.app.state.sessions() as session:
        return identify(session, secret)


def current_principal(request: Request) -> Principal | None:
    """The signed-in caller, or None; 429 when the key is over its rate limit (as in the API)."""
    secret = session_secret(request)
    if secret is None:
        return None
    principal = principal_from_secret(request, secret)
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
    """The form token of a session: an HMAC of a fixed label under the key's secret."""
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
