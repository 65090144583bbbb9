"""The gate in front of every route: the Host name, the API key, and the cap on a request's size.

A plain ASGI middleware, so it runs before any route and before a byte of the body is read:
a request whose ``Host`` is not a name of this server (:mod:`cdprhost.server.hosts`) is
answered 400 and closed; a request without the right key is answered 401 (no key, or an empty one) or 403 (a wrong
key) and nothing behind it runs. A body announced larger than the cap is answered 413 at
once; a body that grows past it while it streams (chunked) is cut: answered 413, and the
connection closed (nothing more of it is read).
No CORS headers are ever added: a browser page on another origin cannot read a reply.
"""

from __future__ import annotations

import json
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any
from urllib.parse import parse_qs

from cdprhost.server.apikey import key_matches
from cdprhost.server.hosts import HostNames

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]


DRAIN_BYTES = 1 << 20


class BodyTooLarge(Exception):
    pass


def given_key(scope: Scope) -> str | None:
    """The key in ``X-Api-Key`` (first), else in the ``apikey`` query parameter."""
    for name, value in scope.get("headers", ()):
        if name == b"x-api-key":
            return str(value.decode("latin-1")).strip()
    query = parse_qs(scope.get("query_string", b"").decode("latin-1"), keep_blank_values=True)
    values = query.get("apikey")
    return values[0].strip() if values else None


def given_host(scope: Scope) -> str | None:
    for name, value in scope.get("headers", ()):
        if name == b"host":
            return str(value.decode("latin-1"))
    return None


async def send_error(send: Send, status: int, text: str) -> None:
    body = json.dumps({"error": text}).encode()
    await send(
        {
            "type": "http.response.start",
            "status": status,
            "headers": [
                (b"content-type", b"application/json"),
                (b"content-length", str(len(body)).encode()),
                (b"connection", b"close"),
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})


class KeyGuard:
    def __init__(
        self,
        app: ASGIApp,
        key: Callable[[], str],
        max_body_bytes: int,
        hosts: HostNames | None = None,
    ):
        """``key`` returns the key in force (read per request: a rotation applies at once);
        ``hosts``: the names answered to (default: the loopback names)."""
        self.app = app
        self.key = key
        self.max_body_bytes = max_body_bytes
        self.hosts = hosts or HostNames.for_listen("127.0.0.1")

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            if scope["type"] == "websocket":
                await send({"type": "websocket.close", "code": 1008})
                return
            await self.app(scope, receive, send)
            return
        length = _content_length(scope)
        host = given_host(scope)
        if not self.hosts.allows(host):
            shown = "".join(c for c in (host or "") if c.isprintable())[:80]
            await send_error(
                send,
                400,
                f"Host {shown!r} is not a name of this server (a page on another site?); "
                "start the server with --allow-host NAME to answer to that name",
            )
            return
        given = given_key(scope)
        if not given or not key_matches(self.key(), given):
            # a small body is read and dropped first, so that the client reads the refusal
            # instead of a connection reset; a large one is not read at all
            if length is not None and 0 < length <= DRAIN_BYTES:
                await _drain(receive)
            if not given:
                await send_error(send, 401, "an API key is required (X-Api-Key header)")
            else:
                await send_error(send, 403, "invalid API key")
            return
        if length is not None and length > self.max_body_bytes:
            await send_error(send, 413, _too_large(self.max_body_bytes))
            return
        await self._capped(scope, receive, send)

    async def _capped(self, scope: Scope, receive: Receive, send: Send) -> None:
        seen = 0
        started = False
        over = False

        async def counted_receive() -> Message:
            nonlocal seen, over
            if over:  # never read on past the cap, whatever the route does
                raise BodyTooLarge
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.max_body_bytes:
                    over = True
                    raise BodyTooLarge
            return message

        async def watched_send(message: Message) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
                if over:  # the rest of the body is not read: the connection ends here
                    headers = [(k, v) for k, v in message.get("headers", ()) if k != b"connection"]
                    message = {**message, "headers": [*headers, (b"connection", b"close")]}
            await send(message)

        try:
            await self.app(scope, counted_receive, watched_send)
        except BodyTooLarge:
            if not started:
                await send_error(send, 413, _too_large(self.max_body_bytes))


async def _drain(receive: Receive) -> None:
    for _ in range(DRAIN_BYTES // 1024 + 2):  # bounded: at most DRAIN_BYTES announced
        message = await receive()
        if message["type"] != "http.request" or not message.get("more_body", False):
            return


def _content_length(scope: Scope) -> int | None:
    for name, value in scope.get("headers", ()):
        if name == b"content-length":
            try:
                return int(value)
            except ValueError:
                return None
    return None


def _too_large(cap: int) -> str:
    return f"request larger than the upload cap ({cap / 1e6:g} MB; serve --max-upload-mb)"
