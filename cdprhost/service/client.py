"""A front end's side of the printer service: find it (or start it), say hello, send
commands, receive its messages.

:func:`attach` connects to the service of a device and starts one, detached in its own
session, when none listens. This is the one rule every front end (``print``, ``tui``,
``serve``) follows: a device's port has one shared service; the embedded simulated device
has one service per state folder (``$CDPRHOST_STATE``), so a front end started again (after
a crash, a kill) finds the print another one started. Messages arrive through a reader thread into :attr:`ServiceClient.inbox` (``None``
once the service has gone), so a front end waits on it with a timeout and stays free to
handle its own signals and screen. This is the API the TUI, the upload server and a web
page use alike.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import os
import queue
import socket
import subprocess
import sys
import threading
import time
from typing import Any

from pydantic import BaseModel

from cdprhost.errors import CdprError
from cdprhost.service import wire
from cdprhost.service.paths import ServiceFiles, files_for_port, read_key

log = logging.getLogger(__name__)

START_TIMEOUT_S = 60.0  # a loaded machine may take long to import numpy and friends
#: a service stays this long after its last client and job
SHARED_IDLE_S = 30.0


class ServiceError(CdprError):
    """The printer service cannot be reached, refused us, or went away."""


class ServiceClient:
    def __init__(self, sock: socket.socket, files: ServiceFiles):
        self.sock = sock
        self.files = files
        self.inbox: queue.Queue[Any] = queue.Queue()
        self.welcome: wire.Welcome | None = None
        self._ids = itertools.count(1)
        self._write = threading.Lock()
        self._reader = sock.makefile("rb")

    def hello(self, who: str, *, replay: bool, timeout_s: float = 30.0) -> wire.Welcome:
        key = read_key(self.files.key)
        self.send(wire.Hello(v=wire.VERSION, key=key, client=who, replay=replay))
        self.sock.settimeout(timeout_s)
        first = self._read()
        if isinstance(first, wire.Reply) and not first.ok:
            raise ServiceError(f"the printer service refused us: {first.error}")
        if not isinstance(first, wire.Welcome):
            raise ServiceError("the printer service did not welcome us")
        self.sock.settimeout(None)
        self.welcome = first
        threading.Thread(target=self._read_loop, name="service-in", daemon=True).start()
        return first

    def _read(self) -> Any:
        try:
            line = self._reader.readline(wire.MAX_LINE + 1)
        except OSError as exc:
            raise ServiceError(f"the printer service does not answer: {exc}") from None
        if not line:
            raise ServiceError("the printer service closed the connection")
        return wire.decode_reply(line)

    def _read_loop(self) -> None:
        try:
            while True:
                try:
                    self.inbox.put(self._read())
                except wire.UnknownMessage as exc:  # a newer service's: not ours to read
                    log.debug("skipped: %s", exc)
        except (ServiceError, wire.WireError) as exc:
            self.inbox.put(None)
            self.gone = str(exc)

    gone = ""

    def send(self, message: BaseModel) -> int:
        """Send a command (its ``id`` is filled in when it has one); the id."""
        number = 0
        if "id" in type(message).model_fields:  # commands are numbered 1, 2, ... (hello: none)
            number = next(self._ids)
            message = message.model_copy(update={"id": number})
        with self._write:
            try:
                self.sock.sendall(wire.encode(message))
            except OSError as exc:
                raise ServiceError(f"the printer service went away: {exc}") from None
        return number

    def command(self, message: BaseModel) -> None:
        """Send and forget (a reply comes through the inbox); a service gone is ignored:
        the front end learns it from the inbox."""
        with contextlib.suppress(ServiceError):
            self.send(message)

    def close(self) -> None:
        with contextlib.suppress(OSError, ServiceError):
            self.send(wire.Bye())
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        with contextlib.suppress(OSError):
            self.sock.close()


def _connect(files: ServiceFiles) -> socket.socket | None:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.connect(str(files.socket))
    except (FileNotFoundError, ConnectionRefusedError):
        sock.close()
        return None
    except OSError as exc:
        sock.close()
        raise ServiceError(f"cannot reach the printer service at {files.socket}: {exc}") from None
    return sock


def spawn(files: ServiceFiles, port: str | None, idle_s: float) -> subprocess.Popen[bytes]:
    """Start a service detached (its own session: a closed terminal does not reach it)."""
    args = [sys.executable, "-m", "cdprhost.service", "--name", files.name, "--idle-s", str(idle_s)]
    if port is not None:
        args += ["--port", port]
    fd = os.open(files.log, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
    try:
        return subprocess.Popen(
            args,
            stdin=subprocess.DEVNULL,
            stdout=fd,
            stderr=fd,
            start_new_session=True,
            close_fds=True,
        )
    finally:
        os.close(fd)


def embedded_files() -> ServiceFiles:
    """The service of the embedded simulated device for this state folder."""
    return files_for_port(None)


def attach(
    port: str | None,
    who: str,
    *,
    replay: bool,
    start: bool = True,
    files: ServiceFiles | None = None,
) -> ServiceClient:
    """A client of the service of ``port`` (None: the embedded device's of this
    state folder), started first when none listens and ``start``; ServiceError
    when none can be reached."""
    files = files or files_for_port(port)
    with contextlib.suppress(ServiceError):
        return connect(files, who, replay=replay)
    if not start:
        where = port or "the embedded device"
        raise ServiceError(f"no printer service runs for {where}: no print to watch")
    proc = spawn(files, port, SHARED_IDLE_S)
    end = time.monotonic() + START_TIMEOUT_S
    while True:
        if files.key.exists():
            with contextlib.suppress(ServiceError):
                return connect(files, who, replay=replay)
        code = proc.poll()
        if code is not None and code != 0:
            raise ServiceError(f"the printer service failed to start (its log: {files.log})")
        if code == 0 and not files.key.exists():  # another held the device, then left
            proc = spawn(files, port, SHARED_IDLE_S)
        if time.monotonic() > end:
            raise ServiceError(f"the printer service did not start (its log: {files.log})")
        time.sleep(0.02)


def connect(files: ServiceFiles, who: str, *, replay: bool = True) -> ServiceClient:
    """A client of the running service ``files`` names (a second front end of a given
    service, the upload server); ServiceError when none listens."""
    sock = _connect(files)
    if sock is None:
        raise ServiceError(f"no printer service listens at {files.socket}")
    return _hello(ServiceClient(sock, files), who, replay)


def _hello(client: ServiceClient, who: str, replay: bool) -> ServiceClient:
    try:
        client.hello(who, replay=replay)
    except BaseException:
        client.close()
        raise
    return client
