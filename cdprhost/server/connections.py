"""Connection limits and timeouts: no client can hold the server by opening connections.

uvicorn keeps every accepted connection open until the client speaks, however slowly, and
accepts until the process runs out of descriptors; then nobody, not even a client with the
key, gets in. :class:`ConnectionLimits` bounds that, enforced by the HTTP protocol of
:func:`limited_protocol` (uvicorn's h11 protocol with a watch of its own):

- at most ``max_connections`` open (by default at most a quarter of the descriptors the
  process may open), and at most as many accepted at once (the listen backlog) as the
  descriptors left allow; one more arriving closes the connection that has waited longest for a
  request's headers (it has sent no key yet), or, when every connection is busy with a
  request, the newcomer itself;
- a request's headers must be complete within ``header_timeout_s`` of the connection (or of
  the previous response): an idle or slow-header client is closed;
- a body must keep coming: at least ``min_body_bytes`` in every ``body_window_s`` while the
  server is reading it (a client that trickles its upload is closed; time the server spends
  not reading, e.g. while it checks a file, is not held against it).
"""

from __future__ import annotations

import asyncio
import resource
import time
from typing import Any

from pydantic import BaseModel, ConfigDict, Field
from uvicorn.protocols.http.h11_impl import H11Protocol

WATCH_PERIOD_S = 0.25  # how often each connection's deadlines are looked at


RESERVED_FDS = 64  # descriptors kept for files, the device, logs


def _fd_limit() -> int:
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    return int(soft) if soft != resource.RLIM_INFINITY else 4096


def default_max_connections() -> int:
    return max(8, min(256, _fd_limit() // 4))


def default_backlog() -> int:
    """asyncio accepts up to the backlog in one go, and may do it again before the connections
    it accepted are seen (and evictions closed): the connections kept plus three such bursts
    stay inside the descriptors the process may open."""
    spare = _fd_limit() - RESERVED_FDS - default_max_connections()
    return max(8, min(512, spare // 3))


class ConnectionLimits(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")
    max_connections: int = Field(default_factory=default_max_connections, ge=2)
    header_timeout_s: float = Field(default=10.0, gt=0)
    body_window_s: float = Field(default=10.0, gt=0)
    min_body_bytes: int = Field(default=1024, ge=1)
    backlog: int = Field(default_factory=default_backlog, ge=1)


class BodyWindow:
    """Whether a body keeps coming: at least ``min_bytes`` in every ``window_s`` of the time the
    server waits on the client. Time it does not wait (the app busy, or not yet scheduled to
    take what came, as on a loaded machine) pauses the window; it never restarts it, so a
    trickle cannot hide behind a busy server."""

    def __init__(self, window_s: float, min_bytes: int, now: float) -> None:
        self.window_s, self.min_bytes = window_s, min_bytes
        self.last_check, self.waited, self.bytes = now, 0.0, 0

    def restart(self, now: float) -> None:
        self.last_check, self.waited, self.bytes = now, 0.0, 0

    def received(self, n: int) -> None:
        self.bytes += n

    def too_slow(self, now: float, waiting_on_client: bool) -> bool:
        """Look at the window at ``now``: True when the client is too slow."""
        elapsed, self.last_check = now - self.last_check, now
        if not waiting_on_client:
            return False
        self.waited += elapsed
        if self.waited < self.window_s:
            return False
        if self.bytes < self.min_bytes:
            return True
        self.waited, self.bytes = 0.0, 0
        return False


class _Registry:
    """The open connections of one server, oldest first (dicts keep insertion order)."""

    def __init__(self) -> None:
        self.open: dict[Any, None] = {}


def limited_protocol(limits: ConnectionLimits) -> type[H11Protocol]:
    """uvicorn's h11 protocol class with ``limits`` (pass it as ``uvicorn.Config(http=...)``)."""
    registry = _Registry()

    class LimitedH11Protocol(H11Protocol):
        def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
            super().connection_made(transport)
            now = time.monotonic()
            self._waiting_since = now  # waiting for a request's headers since
            self._body = BodyWindow(limits.body_window_s, limits.min_body_bytes, now)
            if len(registry.open) >= limits.max_connections and not _evict_one(registry):
                transport.close()
                return
            registry.open[self] = None
            self._watch = self.loop.call_later(WATCH_PERIOD_S, self._check)

        def connection_lost(self, exc: Exception | None) -> None:
            registry.open.pop(self, None)
            watch = getattr(self, "_watch", None)
            if watch is not None:
                watch.cancel()
            super().connection_lost(exc)

        def handle_websocket_upgrade(self, event: Any) -> None:
            # the connection becomes a WebSocket (its own protocol, its own life): not ours
            registry.open.pop(self, None)
            watch = getattr(self, "_watch", None)
            if watch is not None:
                watch.cancel()
            super().handle_websocket_upgrade(event)

        def data_received(self, data: bytes) -> None:
            self._body.received(len(data))
            super().data_received(data)

        def on_response_complete(self) -> None:
            super().on_response_complete()
            self._waiting_since = time.monotonic()  # the next request's headers from now

        def waiting_for_headers(self) -> bool:
            cycle = self.cycle
            return cycle is None or cycle.response_complete

        def _reading_body(self) -> bool:
            cycle = self.cycle
            return (
                cycle is not None
                and not cycle.response_complete
                and cycle.more_body
                and not self.flow.read_paused
                and not cycle.body  # the app has taken what came: it waits for more
            )

        def _check(self) -> None:
            if self.transport.is_closing():
                return
            now = time.monotonic()
            if self.waiting_for_headers():
                if now - self._waiting_since > limits.header_timeout_s:
                    self.transport.close()
                    return
                self._body.restart(now)
            elif self._body.too_slow(now, self._reading_body()):
                self.transport.close()
                return
            self._watch = self.loop.call_later(WATCH_PERIOD_S, self._check)

    return LimitedH11Protocol


def _evict_one(registry: _Registry) -> bool:
    """Close the connection that has waited longest for a request (True), if there is one."""
    waiting = [c for c in registry.open if c.waiting_for_headers()]
    if not waiting:
        return False
    oldest = min(waiting, key=lambda c: c._waiting_since)
    registry.open.pop(oldest)
    oldest.transport.close()
    return True
