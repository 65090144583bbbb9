"""Where the server listens, and the server itself running in a thread of its own.

``[HOST:]PORT`` is checked at parse time. The socket is bound in the caller's thread, so a
port in use or an address that is not this machine's is a clear error before anything
starts; uvicorn then serves it from a daemon thread with its own event loop (beside the
terminal UI's loop, or the main thread of ``cdprhost serve`` that waits for a signal).
"""

from __future__ import annotations

import ipaddress
import logging
import socket
import threading
from typing import TYPE_CHECKING, Any

from cdprhost.errors import InputError

if TYPE_CHECKING:
    from cdprhost.server.connections import ConnectionLimits

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 5000
LISTEN_QUEUE = 4096  # the kernel caps it (net.core.somaxconn)
LOOPBACK_NAMES = ("localhost", "localhost.localdomain", "ip6-localhost")

log = logging.getLogger(__name__)


def parse_listen(text: str) -> tuple[str, int]:
    """``PORT``, ``HOST:PORT`` or ``[IPv6]:PORT`` -> (host, port)."""
    text = text.strip()
    host, _, port_text = text.rpartition(":")
    if text.startswith("[") and "]" in text:
        inner, _, rest = text[1:].partition("]")
        host, port_text = inner, rest.removeprefix(":")
    elif host.count(":") > 0:
        raise ValueError(f"{text!r}: write an IPv6 address in brackets, e.g. [::1]:5000")
    try:
        port = int(port_text)
    except ValueError:
        raise ValueError(f"{text!r}: the port must be a whole number") from None
    if not 0 <= port <= 65535:
        raise ValueError(f"{text!r}: the port must be 0..65535")
    return (host or DEFAULT_HOST), port


def is_loopback(host: str) -> bool:
    if host in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def exposure_warning(host: str, port: int) -> str:
    return (
        f"warning: listening on {host}:{port}, not only on this machine: anyone who can reach "
        "it and holds the API key can upload files and start prints. Keep the key secret, "
        "and prefer a trusted network or an SSH tunnel to 127.0.0.1."
    )


def bind(host: str, port: int) -> socket.socket:
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise InputError(
            f"cannot listen on {host}:{port}: {exc.strerror}", source="--listen"
        ) from None
    family, kind, proto, _, address = infos[0]
    sock = socket.socket(family, kind, proto)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        sock.listen(64)
    except OSError as exc:
        sock.close()
        raise InputError(
            f"cannot listen on {host}:{port}: {exc.strerror or exc}", source="--listen"
        ) from None
    sock.set_inheritable(True)
    return sock


class ServerThread:
    """uvicorn serving ``app`` on a bound socket from a daemon thread, within ``limits``
    (connections, header and body timeouts: :mod:`cdprhost.server.connections`)."""

    def __init__(self, app: Any, host: str, port: int, limits: ConnectionLimits | None = None):
        import uvicorn

        from cdprhost.server.connections import ConnectionLimits, limited_protocol

        limits = limits or ConnectionLimits()

        self.sock = bind(host, port)
        self.host = host
        self.port = int(self.sock.getsockname()[1])
        config = uvicorn.Config(
            app,
            log_level="warning",
            access_log=False,
            server_header=False,
            lifespan="off",
            http=limited_protocol(limits),
            backlog=limits.backlog,
            timeout_graceful_shutdown=3,
        )
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self._serve, name="upload-api", daemon=True)
        self.error: BaseException | None = None

    def _serve(self) -> None:
        try:
            self.server.run(sockets=[self.sock])
        except BaseException as exc:  # reported by start()/stop(), never silently lost
            self.error = exc
            log.exception("the upload API stopped")

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}"

    def start(self, timeout_s: float = 10.0) -> None:
        self.thread.start()
        for _ in range(int(timeout_s / 0.02)):  # bounded: the server starts in a moment
            if self.server.started or not self.thread.is_alive():
                break
            threading.Event().wait(0.02)
        if not self.server.started:
            raise InputError(f"the upload API did not start on {self.url}: {self.error}")
        # the kernel's queue of connections not yet accepted: long, so that a crowd of idle
        # clients does not make a newcomer's handshake wait for a retry (asyncio set it to
        # the accept batch, which the limits keep short)
        self.sock.listen(LISTEN_QUEUE)

    def stop(self, timeout_s: float = 5.0) -> None:
        self.server.should_exit = True
        if self.thread.is_alive():
            self.thread.join(timeout_s)
        self.sock.close()
