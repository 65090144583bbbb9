"""A printer service in a thread of the test process, for tests that reach into the job
(monkeypatched modules) and so cannot let it run in a process of its own."""

from __future__ import annotations

import threading
from typing import Any

import pytest

from cdprhost.service import client as service_client
from cdprhost.service.paths import ServiceFiles
from cdprhost.service.printer_service import PrinterService


class _Thread:
    """What :func:`cdprhost.service.client.attach` asks of a started service."""

    def __init__(self, service: PrinterService):
        self.service = service
        self.thread = threading.Thread(target=service.serve, name="test-service", daemon=True)
        self.thread.start()
        _RUNNING.append(self)

    def poll(self) -> int | None:
        return None if self.thread.is_alive() else 0


_RUNNING: list[_Thread] = []  # the services started here that may still run


def end_services(timeout_s: float = 30.0) -> None:
    """End every service started here (its print cancelled as the operator would, its
    threads joined): a test's service must not go on printing, and logging, after the test
    (an e-stop logged to a closed capture, "Logging error ... EstopFlag", once)."""
    while _RUNNING:
        started = _RUNNING.pop()
        started.service.shutdown_job("the test ended")  # joins the job's thread, then stops
        started.thread.join(timeout_s)


def serve_in_thread(monkeypatch: pytest.MonkeyPatch, idle_s: float = 0.5) -> list[Any]:
    """From now on, ``attach`` starts its services as threads here; the services started."""
    started: list[Any] = []

    def spawn(files: ServiceFiles, port: str | None, idle: float) -> _Thread:
        service = PrinterService(files, port, idle_s=idle_s)
        service.bind()
        started.append(service)
        return _Thread(service)

    monkeypatch.setattr(service_client, "spawn", spawn)
    return started
