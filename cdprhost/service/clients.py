"""The service's end of one connected front end: its reader thread hands each request to
the service, and its bounded outgoing queue with its own sender thread keeps a front end that
stops reading (hung, stopped) from ever blocking the service: once it falls
``MAX_BACKLOG`` messages behind it is hung up on."""

from __future__ import annotations

import contextlib
import logging
import queue
import socket
import threading
from typing import Any, Protocol

from pydantic import BaseModel

from cdprhost.service import wire

log = logging.getLogger(__name__)

#: messages a client may fall behind by before it is dropped (a stopped front end)
MAX_BACKLOG = 20_000
#: the kernel's share of a client's backlog (bytes); the rest waits in its queue
SEND_BUFFER = 64 * 1024
HELLO_TIMEOUT_S = 5.0


class ClientHost(Protocol):
    """What a client asks of the service that accepted it (``printer_service``)."""

    def admit(self, client: Client, hello: wire.Hello) -> bool: ...

    def handle(self, client: Client, request: Any) -> None: ...

    def forget(self, client: Client) -> None: ...


class Client:
    """One connected front end: a reader (in its own thread) and a bounded sender."""

    def __init__(self, conn: socket.socket, service: ClientHost, number: int):
        self.conn = conn
        self.service = service
        self.number = number
        self.who = "?"
        self.out: queue.Queue[bytes | None] = queue.Queue()
        self.closed = threading.Event()
        self._sender = threading.Thread(target=self._send_loop, name=f"client-{number}-out")
        self._sender.daemon = True

    def start(self) -> None:
        with contextlib.suppress(OSError):
            self.conn.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER)
        self._sender.start()
        name = f"client-{self.number}-in"
        threading.Thread(target=self._read_loop, name=name, daemon=True).start()

    def send(self, message: BaseModel | bytes) -> None:
        """Queue a message (or its encoded line); never blocks. A client too far behind is
        dropped."""
        if self.closed.is_set():
            return
        if self.out.qsize() >= MAX_BACKLOG:
            log.warning("client %d (%s) stopped reading: disconnected", self.number, self.who)
            self.close(now=True)
            return
        self.out.put(message if isinstance(message, bytes) else wire.encode(message))

    def close(self, now: bool = False) -> None:
        """Hang up once what is queued is sent (``now``: at once, for a client too far
        behind to be worth waiting for)."""
        if self.closed.is_set():
            return
        self.closed.set()
        self.out.put(None)
        if now:
            self._hang_up()
        self.service.forget(self)

    def _hang_up(self) -> None:
        with contextlib.suppress(OSError):
            self.conn.shutdown(socket.SHUT_RDWR)

    def _send_loop(self) -> None:
        try:
            while True:
                data = self.out.get()
                if data is None:
                    break
                self.conn.sendall(data)
        except OSError:
            pass
        finally:
            self.close(now=True)
            self._hang_up()
            with contextlib.suppress(OSError):
                self.conn.close()

    def _read_loop(self) -> None:
        try:
            reader = self.conn.makefile("rb")
            self.conn.settimeout(HELLO_TIMEOUT_S)
            first = reader.readline(wire.MAX_LINE + 1)
            hello = wire.decode_request(first) if first else None
            if not isinstance(hello, wire.Hello) or not self.service.admit(self, hello):
                return
            self.conn.settimeout(None)
            for line in iter(lambda: reader.readline(wire.MAX_LINE + 1), b""):
                request = wire.decode_request(line)
                if isinstance(request, wire.Bye):
                    break
                self.service.handle(self, request)
        except wire.WireError as exc:
            self.send(wire.Reply(ok=False, error=f"refused: {exc}"))
            log.warning("client %d sent a bad message: %s", self.number, exc)
        except OSError:
            pass
        finally:
            self.close()
