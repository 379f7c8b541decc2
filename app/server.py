"""The HTTP server of ``attitude serve``: uvicorn with deadlines on reading a request and a connection limit.

Uvicorn closes idle keep-alive connections (``timeout_keep_alive``) and answers 503 beyond
``limit_concurrency`` connections or tasks, but it never closes a connection that sends its request
headers slowly (a "slowloris": every byte cancels the keep-alive timer), so a few hundred such connections
hold the file descriptors. :class:`DeadlineProtocol` adds, per connection:

- a **header deadline**: the request line and headers must be complete ``header_timeout_s`` after the
  connection opened or the request's first byte arrived; otherwise 408 and the connection is closed;
- a **body idle deadline**: while a request body is being received, no more than ``body_timeout_s``
  between two chunks (unless the application itself stopped reading); otherwise the connection is closed
  and the application sees a disconnect.

Settings: ``ATTITUDE_HEADER_TIMEOUT_S`` (10), ``ATTITUDE_BODY_TIMEOUT_S`` (60), ``ATTITUDE_KEEP_ALIVE_S``
(5), ``ATTITUDE_MAX_CONNECTIONS`` (512). Behind a reverse proxy the proxy's own limits come first
(README "Security").
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from app.settings import Settings

_TIMEOUT_408 = (b"HTTP/1.1 408 Request Timeout\r\ncontent-type: application/json\r\nconnection: close\r\n"
                b"content-length: 56\r\n\r\n" + b'{"detail": "the request headers did not arrive in time"}')
assert len(b'{"detail": "the request headers did not arrive in time"}') == 56


class DeadlineProtocol(HttpToolsProtocol):
    """HttpToolsProtocol with a header deadline and a body idle deadline (module docstring)."""

    header_timeout_s: float = 10.0
    body_timeout_s: float = 60.0

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._header_timer: asyncio.TimerHandle | None = None
        self._body_timer: asyncio.TimerHandle | None = None
        self._last_body_at = 0.0

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm_header_deadline()

    def connection_lost(self, exc: Exception | None) -> None:
        self._cancel_timers()
        super().connection_lost(exc)

    def _cancel_timers(self) -> None:
        for timer in (self._header_timer, self._body_timer):
            if timer is not None:
                timer.cancel()
        self._header_timer = self._body_timer = None

    def _arm_header_deadline(self) -> None:
        if self._header_timer is not None:
            self._header_timer.cancel()
        self._header_timer = self.loop.call_later(self.header_timeout_s, self._header_deadline_passed)

    def _header_deadline_passed(self) -> None:
        self._header_timer = None
        if not self.transport.is_closing():
            self.transport.write(_TIMEOUT_408)
            self.transport.close()

    def on_message_begin(self) -> None:
        super().on_message_begin()
        self._arm_header_deadline()

    def on_headers_complete(self) -> None:
        if self._header_timer is not None:
            self._header_timer.cancel()
            self._header_timer = None
        self._last_body_at = time.monotonic()
        self._body_timer = self.loop.call_later(self.body_timeout_s, self._body_deadline_check)
        super().on_headers_complete()

    def on_body(self, body: bytes) -> None:
        self._last_body_at = time.monotonic()
        super().on_body(body)

    def on_message_complete(self) -> None:
        if self._body_timer is not None:
            self._body_timer.cancel()
            self._body_timer = None
        super().on_message_complete()

    def _body_deadline_check(self) -> None:
        self._body_timer = None
        if self.transport.is_closing():
            return
        idle = time.monotonic() - self._last_body_at
        if self.flow.read_paused or idle < self.body_timeout_s:  # the application is not reading, or data came
            wait = self.body_timeout_s if self.flow.read_paused else self.body_timeout_s - idle
            self._body_timer = self.loop.call_later(wait, self._body_deadline_check)
            return
        self.transport.close()  # the application's receive() sees http.disconnect


def protocol_class(settings: Settings) -> type[DeadlineProtocol]:
    """The protocol with this service's deadlines."""
    return type("ServiceProtocol", (DeadlineProtocol,), {"header_timeout_s": float(settings.header_timeout_s),
                                                         "body_timeout_s": float(settings.body_timeout_s)})


def serve(app: Any, settings: Settings, host: str, port: int, log_level: str = "info") -> None:
    """Run ``app`` under uvicorn with the service's deadlines and connection limit until stopped."""
    import uvicorn

    uvicorn.run(app, host=host, port=port, log_level=log_level, http=protocol_class(settings),
                timeout_keep_alive=settings.keep_alive_s, limit_concurrency=settings.max_connections,
                forwarded_allow_ips=settings.forwarded_allow_ips,
                proxy_headers=settings.forwarded_allow_ips is not None)
