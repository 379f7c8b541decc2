"""The gate every ``/api/`` request passes before routing: authentication first, then bounds on what the
request may make the service parse.

In this order, before FastAPI looks at the route, the path parameters, the content type or the body:

1. the query string is at most :data:`MAX_QUERY_BYTES` (414 beyond);
2. a client address that failed authentication too often is throttled (429 with ``Retry-After``,
   ``ATTITUDE_AUTH_FAILURES_PER_MINUTE``), before its credentials are even looked at;
3. ``Authorization: Bearer <key>`` must name an active key, exactly (401 otherwise: a key with a stray
   space, a missing character or another scheme is not "nearly" valid); the key's request rate is
   limited (429, ``ATTITUDE_RATE_LIMIT_PER_MINUTE``); the caller (:class:`app.services.access.Principal`)
   is handed to the route's dependencies in the ASGI scope;
4. a body of a route that takes JSON (every route but the telemetry and reference uploads, which parse
   their own formats in bounded ways) is at most :data:`MAX_JSON_BODY_BYTES` (413) and nested at most
   :data:`MAX_JSON_DEPTH` levels (422), checked by a vectorised scan of the bytes before any parser
   recurses into them.

Every refusal is JSON ``{"detail": ...}``.
"""

from __future__ import annotations

import math
import re
import threading
import time
from typing import Any

import anyio
import numpy as np

from app.api.middleware import ASGIApp, Message, RateLimiter, Receive, Scope, Send, _send_json
from app.services.access import Principal, identify

PRINCIPAL_KEY = "attitude.principal"
MAX_QUERY_BYTES = 8192
MAX_JSON_BODY_BYTES = 1 << 20
MAX_JSON_DEPTH = 32
_TOKEN = re.compile(r"[\x21-\x7e]+")  # visible ASCII, no space (our keys are RFC 6750 b64tokens)
_UPLOADS = (re.compile(r"^/api/v1/spacecraft/[^/]+/telemetry/[^/]+/?$"), re.compile(r"^/api/v1/reference/[^/]+/?$"))
_BODY_METHODS = ("POST", "PUT", "PATCH", "DELETE")


class FailureThrottle:
    """Failed authentications per client address: ``per_minute`` failures, then refusals until the
    bucket refills (one failure's worth every ``60 / per_minute`` s). Process-local, like the rate limit.
    """

    def __init__(self, per_minute: int, max_addresses: int = 100_000) -> None:
        self.rate = per_minute / 60.0
        self.capacity = float(per_minute)
        self.max_addresses = max_addresses
        self._buckets: dict[str, tuple[float, float]] = {}
        self._lock = threading.Lock()

    def _level(self, address: str, now: float) -> float:
        tokens, last = self._buckets.get(address, (self.capacity, now))
        return min(self.capacity, tokens + (now - last) * self.rate)

    def wait(self, address: str) -> float:
        """0 if ``address`` may try to authenticate now, else the seconds until it may."""
        now = time.monotonic()
        with self._lock:
            tokens = self._level(address, now)
        return 0.0 if tokens >= 1.0 else (1.0 - tokens) / self.rate

    def failed(self, address: str) -> None:
        now = time.monotonic()
        with self._lock:
            if len(self._buckets) >= self.max_addresses:  # bounded memory: forget the fully refilled ones
                self._buckets = {a: (t, s) for a, (t, s) in self._buckets.items()
                                 if t + (now - s) * self.rate < self.capacity}
            self._buckets[address] = (max(0.0, self._level(address, now) - 1.0), now)


def json_depth(body: bytes) -> int:
    """Deepest nesting of ``[``/``{`` outside JSON strings (vectorised; the body need not be valid JSON)."""
    b = np.frombuffer(body, dtype=np.uint8)
    if b.size == 0:
        return 0
    pos = np.arange(b.size)
    backslash = b == ord("\\")
    last_other = np.maximum.accumulate(np.where(backslash, -1, pos))  # last non-backslash at or before i
    run_before = np.empty(b.size, dtype=np.int64)  # backslashes immediately before i
    run_before[0] = 0
    run_before[1:] = pos[:-1] - last_other[:-1]
    quote = (b == ord('"')) & (run_before % 2 == 0)
    in_string = np.cumsum(quote) % 2 == 1
    step = (np.isin(b, (ord("["), ord("{"))).astype(np.int64) - np.isin(b, (ord("]"), ord("}"))))
    step[in_string] = 0
    return int(np.cumsum(step).max(initial=0))


def bearer_secret(scope: Scope) -> tuple[str | None, bool]:
    """(the key, whether an Authorization header was given); the key None when absent or malformed."""
    values = [v for k, v in scope.get("headers", []) if k == b"authorization"]
    if not values:
        return None, False
    if len(values) > 1:
        return None, True
    try:
        text = values[0].decode("ascii")
    except UnicodeDecodeError:
        return None, True
    scheme, sep, token = text.partition(" ")
    if scheme.lower() != "bearer" or not sep or not _TOKEN.fullmatch(token) or len(token) > 512:
        return None, True
    return token, True


def client_address(scope: Scope) -> str:
    client = scope.get("client")
    return str(client[0]) if client else "unknown"


class ApiGateMiddleware:
    """Authentication and request bounds for ``/api/`` before anything else (module docstring)."""

    def __init__(self, app: ASGIApp, *, sessions: Any, rate_limiter: RateLimiter, throttle: FailureThrottle,
                 rate_limit_per_minute: int) -> None:
        self.app = app
        self.sessions = sessions  # callable: the app state's session factory (set at start-up)
        self.rate_limiter = rate_limiter
        self.throttle = throttle
        self.rate_limit_per_minute = rate_limit_per_minute

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if len(scope.get("query_string", b"")) > MAX_QUERY_BYTES:
            await _send_json(send, 414, {"detail": f"query string of {len(scope['query_string'])} bytes exceeds "
                                                   f"the limit of {MAX_QUERY_BYTES}"})
            return
        path: str = scope.get("path", "")
        if not path.startswith("/api/"):
            await self.app(scope, receive, send)
            return
        refusal = await self._authenticate(scope)
        if refusal is not None:
            status, body, headers = refusal
            await _send_json(send, status, body, headers)
            return
        if scope.get("method") in _BODY_METHODS and not any(p.match(path) for p in _UPLOADS):
            body_or_refusal = await _read_json_body(receive)
            if isinstance(body_or_refusal, tuple):
                await _send_json(send, *body_or_refusal)
                return
            receive = _replay(body_or_refusal, receive)
        await self.app(scope, receive, send)

    async def _authenticate(self, scope: Scope) -> tuple[int, dict[str, Any], list[tuple[bytes, bytes]]] | None:
        address = client_address(scope)
        wait = self.throttle.wait(address)
        if wait > 0:
            return 429, {"detail": f"too many failed authentications from {address}; retry in {math.ceil(wait)} s"}, \
                _retry_after(wait)
        secret, given = bearer_secret(scope)
        challenge = [(b"www-authenticate", b"Bearer")]
        if secret is None:
            if given:
                self.throttle.failed(address)
                return 401, {"detail": "malformed Authorization header; expected exactly 'Bearer <api key>'"}, challenge
            return 401, {"detail": "missing API key (Authorization: Bearer <key>)"}, challenge
        principal = await anyio.to_thread.run_sync(self._identify, secret)
        if principal is None:
            self.throttle.failed(address)
            return 401, {"detail": "invalid, expired or revoked API key"}, challenge
        wait = self.rate_limiter.acquire(principal.key_id)
        if wait > 0:
            return 429, {"detail": f"rate limit of {self.rate_limit_per_minute} requests per minute exceeded for "
                                   f"this key; retry in {wait:.1f} s"}, _retry_after(wait)
        scope[PRINCIPAL_KEY] = principal
        return None

    def _identify(self, secret: str) -> Principal | None:
        with self.sessions() as session:
            return identify(session, secret)


def _retry_after(wait_s: float) -> list[tuple[bytes, bytes]]:
    return [(b"retry-after", str(max(1, math.ceil(wait_s))).encode())]


async def _read_json_body(receive: Receive) -> bytes | tuple[int, dict[str, Any]]:
    chunks: list[bytes] = []
    size = 0
    while True:
        message = await receive()
        if message["type"] != "http.request":
            break
        chunk = message.get("body", b"")
        size += len(chunk)
        if size > MAX_JSON_BODY_BYTES:
            return 413, {"detail": f"request body exceeds the limit of {MAX_JSON_BODY_BYTES} bytes for this route"}
        chunks.append(chunk)
        if not message.get("more_body", False):
            break
    body = b"".join(chunks)
    depth = json_depth(body)
    if depth > MAX_JSON_DEPTH:
        return 422, {"detail": f"JSON body nested {depth} levels deep; at most {MAX_JSON_DEPTH}"}
    return body


def _replay(body: bytes, receive: Receive) -> Receive:
    sent = False

    async def replay() -> Message:
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()

    return replay
