"""An e-stop sent to the service while its job is still in the preflight (no link of its
own yet) stops the device through the device session too: the job alone would only end
itself, and a device left heating or moving by the session would not stop."""

from __future__ import annotations

import threading

import pytest

from cdprhost.service import wire
from cdprhost.service.paths import ServiceFiles
from cdprhost.service.printer_service import PrinterService


class _Session:
    open = True

    def __init__(self) -> None:
        self.stops: list[int] = []

    def emergency_stop(self, request_id: int) -> wire.Answer:
        self.stops.append(request_id)
        return wire.Answer(id=request_id, ok=True, confirmed=True)


class _Job:
    finished = False

    def __init__(self, link: object) -> None:
        self.link = link
        self.stopped = threading.Event()

    def emergency_stop(self) -> bool:
        self.stopped.set()
        return self.link is not None


class _Client:
    number = 1

    def __init__(self) -> None:
        self.sent: list = []

    def send(self, message: object) -> None:
        self.sent.append(message)


@pytest.mark.parametrize("job_link", [None, object()], ids=["preflight", "printing"])
def test_an_estop_reaches_the_device_whether_or_not_the_job_holds_it(tmp_path, job_link):
    service = PrinterService(ServiceFiles(tmp_path, "svc"), None)
    session, job, client = _Session(), _Job(job_link), _Client()
    service.session = session  # type: ignore[assignment]
    service._job = job  # type: ignore[assignment]
    running = threading.Event()
    service._job_thread = threading.Thread(target=running.wait, daemon=True)
    service._job_thread.start()
    try:
        request = wire.Estop(id=7)
        service.handle(client, request)  # type: ignore[arg-type]
        assert job.stopped.wait(5.0)  # the job ends either way (FAILED, runner.py)
        # the job's own link stops the device when it has one; before, the session's does
        assert session.stops == ([7] if job_link is None else [])
        assert [type(m) for m in client.sent] == [wire.Reply] and client.sent[0].ok
    finally:
        running.set()
