"""The TUI as a client of the printer service (the service in a thread of this process,
the embedded device, accelerated): the device session between prints (status, console,
jog, heaters, e-stop and M999), a print that writes its JSON-lines log, a second front end
that sees the same print, and a UI that attaches to a print already running and shows it."""

from __future__ import annotations

import json
import queue
import shutil
import tempfile
import threading
import time

import pytest

from cdprhost.errors import CdprError
from cdprhost.job.state import JobSnapshot, JobState, reduce
from cdprhost.service import client as service_client
from cdprhost.service import wire
from cdprhost.tui.control.backend import EMBEDDED
from cdprhost.tui.control.service_backend import ServiceBackend
from tests.e2e.processes import square_part, wait_until
from tests.service.inprocess import serve_in_thread

from .conftest import make_app, wait_for

SPEEDUP = 40.0


@pytest.fixture
def run_dir(monkeypatch, tmp_path):
    """A short private run folder (a socket's path is at most 107 bytes) and state."""
    folder = tempfile.mkdtemp(prefix="svc-", dir="/tmp")
    monkeypatch.setenv("CDPRHOST_RUN", folder)
    monkeypatch.setenv("CDPRHOST_STATE", str(tmp_path / "state"))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture
def backend(run_dir, monkeypatch):
    serve_in_thread(monkeypatch, idle_s=0.5)
    b = ServiceBackend("paper-prototype", speedup=SPEEDUP)
    yield b
    b.close()


def _folded(events: list) -> JobSnapshot:
    snap = JobSnapshot()
    for event in events:
        snap = reduce(snap, event)
    return snap


def test_the_device_between_prints_goes_through_the_service(backend):
    rows = dict(backend.connect(EMBEDDED, 250000))
    assert rows["port"].startswith("embedded") and backend.connected()
    status = backend.device_status()
    assert status is not None and not status.homed
    assert "not homed" in backend.console("G1 X10")[-1].text
    homed = backend.home()
    assert homed.homed and homed.motors_on and homed.position is not None
    target = (homed.position[0] + 2.0, homed.position[1], homed.position[2] - 5.0)
    moved = backend.jog_to(target)
    assert moved.position == pytest.approx(target, abs=0.05)
    with pytest.raises(CdprError, match="refused, nothing moved"):  # checked by the service
        backend.jog_to((homed.position[0] + 5000.0, homed.position[1], homed.position[2]))
    with pytest.raises(CdprError, match="hotend target 900"):
        backend.set_heaters(900.0, 0.0)
    heated = backend.set_heaters(40.0, 0.0)
    assert heated.hotend_target == 40.0 and heated.bed_target == 0.0
    replies = [line.text for line in backend.console("M114")]
    assert any(text.startswith("position X") for text in replies), replies
    assert any("firmware" in t for t in (line.text for line in backend.console("M115")))
    assert backend.emergency_stop()  # no print: the service's session stops the device
    said = [line.text for line in backend.console("G1 X10")]  # faulted: refused, with M999
    assert any("refused, nothing sent" in t and "M999" in t for t in said), said
    assert any("ok cleared" in line.text for line in backend.console("M999"))
    cleared = backend.device_status()
    assert cleared is not None and not cleared.fault and cleared.hotend_target == 0.0
    # the poll keeps the status coming while nobody asks
    wait_until(lambda: backend.link_health() is not None, 10, "a broadcast status")
    assert backend.status_while_busy() is not None


def test_a_tui_print_runs_in_the_service_and_writes_its_json_lines_log(backend, tmp_path):
    backend.connect(EMBEDDED, 250000)
    gcode = square_part(tmp_path / "part.gcode", layers=3)
    events: list = []
    job = backend.make_job(str(gcode), events.append)
    log_path = job.start.job.log_path
    result = job.run()
    assert result["status"] == "completed" and result["last_layer"] == 3
    assert _folded(events).state is JobState.DONE
    lines = [json.loads(line) for line in open(log_path, encoding="utf-8")]
    assert lines and str(tmp_path / "state") in log_path
    assert any("completed" in json.dumps(line) for line in lines[-3:])
    # the link stays held between prints: the device still answers
    status = backend.device_status()
    assert status is not None and status.homed


def test_a_second_front_end_sees_the_same_print(backend, tmp_path):
    backend.connect(EMBEDDED, 250000)
    gcode = square_part(tmp_path / "part.gcode", layers=4)
    events: list = []
    job = backend.make_job(str(gcode), events.append)
    client = backend._client
    assert client is not None
    result_box: list = []
    runner = threading.Thread(target=lambda: result_box.append(job.run()), daemon=True)
    runner.start()
    wait_until(lambda: _folded(list(events)).segments_done > 20, 60, "printing")
    watcher = service_client.connect(client.files, "print --attach", replay=True)
    try:
        snap, seen = JobSnapshot(), None
        end = time.monotonic() + 120
        while seen is None and time.monotonic() < end:
            try:
                message = watcher.inbox.get(timeout=1)
            except queue.Empty:
                continue
            if isinstance(message, wire.EventMsg):
                snap = reduce(snap, wire.event_from_json(message.event))
            elif isinstance(message, wire.ResultMsg):
                seen = message.result
    finally:
        watcher.close()
    runner.join(60)
    assert seen is not None and result_box and result_box[0] == seen
    mine = _folded(events)
    assert snap.state is mine.state is JobState.DONE
    assert (snap.layer, snap.line, snap.segments_done) == (
        mine.layer,
        mine.line,
        mine.segments_done,
    )


async def test_a_tui_attached_mid_print_shows_it_to_its_end(backend, tmp_path):
    backend.connect(EMBEDDED, 250000)
    files = backend._client.files
    gcode = square_part(tmp_path / "part.gcode", layers=6)
    events: list = []
    job = backend.make_job(str(gcode), events.append)
    threading.Thread(target=job.run, daemon=True).start()
    wait_until(lambda: _folded(list(events)).segments_done > 20, 60, "printing")
    backend._client.sock.close()  # the first UI is gone without a word (killed)

    def attach(port, who, replay):
        return service_client.connect(files, who, replay=replay)

    second = ServiceBackend("paper-prototype", speedup=SPEEDUP, attach=attach)
    app = make_app(second)
    try:
        async with app.run_test(size=(100, 32)) as pilot:
            state = await wait_for(
                pilot, lambda s: s.job.state is JobState.PRINTING, timeout=30, what="the print"
            )
            assert state.job_path == str(gcode) and state.job.segments_done > 20
            state = await wait_for(
                pilot, lambda s: s.job.state is JobState.DONE, timeout=120, what="its end"
            )
            assert state.job.layer + 1 == 6
            state = await wait_for(pilot, lambda s: s.history, timeout=30, what="its record")
            assert state.history[0].status == "done" and state.history[0].file == str(gcode)
    finally:
        second.close()


def test_the_in_process_backend_refuses_a_port_its_service_holds(run_dir, monkeypatch, tmp_path):
    from cdprhost.service.paths import files_for_port
    from cdprhost.service.printer_service import PrinterService
    from cdprhost.tui.control.live import LiveBackend

    port = str(tmp_path / "ttyFAKE")
    service = PrinterService(files_for_port(port), port, idle_s=0.5)
    service.bind()
    try:
        with pytest.raises(CdprError, match="held by its printer service"):
            LiveBackend("paper-prototype").connect(port, 250000)
    finally:
        service.close()


def test_a_reconnect_is_not_undone_by_the_old_connection_closing(backend):
    backend.connect(EMBEDDED, 250000)
    backend.connect(EMBEDDED, 250000)  # the link screen's reconnect
    time.sleep(1.0)  # the old connection's reader has seen its end by now
    assert backend.connected() and backend.device_status() is not None


def test_a_device_that_stops_answering_is_said_once_not_every_second(backend):
    for _ in range(3):  # as the service broadcasts it, once a second
        backend._take(wire.DeviceMsg(connected=True, error="no word from the device"))
    backend._take(wire.DeviceMsg(connected=True, status=None))
    backend._take(wire.DeviceMsg(connected=True, error="no word from the device"))
    said = [line.text for line in backend.device_log()]
    assert said == ["the device does not answer: no word from the device"] * 2


async def test_a_print_started_by_another_front_end_is_shown_by_the_ui(backend, tmp_path):
    """`tui --listen`: the page (another client) starts a print; the UI, idle and connected,
    shows it at its next status refresh and follows it to the end."""
    app = make_app(backend, port=EMBEDDED, status_interval_s=0.2)
    other = ServiceBackend("paper-prototype", speedup=SPEEDUP)
    try:
        async with app.run_test(size=(100, 32)) as pilot:
            await wait_for(pilot, lambda s: s.connected, timeout=60, what="the UI connected")
            gcode = square_part(tmp_path / "part.gcode", layers=6)

            def start_elsewhere() -> None:  # off the UI's event loop (blocking calls)
                other.connect(EMBEDDED, 250000)  # the same state folder: the same service
                other.make_job(str(gcode), lambda _event: None).run()

            threading.Thread(target=start_elsewhere, daemon=True).start()
            state = await wait_for(
                pilot, lambda s: s.job_path == str(gcode), timeout=30, what="the other's print"
            )
            state = await wait_for(
                pilot, lambda s: s.job.state is JobState.DONE, timeout=120, what="its end"
            )
            assert state.job.layer + 1 == 6
    finally:
        other.close()


def test_a_speed_override_reaches_the_print_in_the_service(backend, tmp_path):
    """M220 from the TUI goes over the wire to the job in the service, which applies it
    (its Overrides event comes back); an out-of-range one is refused before anything is sent."""
    from cdprhost.job.state import Overrides

    backend.connect(EMBEDDED, 250000)
    gcode = square_part(tmp_path / "part.gcode", layers=4)
    events: list = []
    job = backend.make_job(str(gcode), events.append)
    runner = threading.Thread(target=job.run, daemon=True)
    runner.start()
    wait_until(lambda: _folded(list(events)).segments_done > 20, 60, "printing")
    with pytest.raises(ValueError, match="out of range"):
        job.request_speed(9999)
    job.request_speed(200)
    wait_until(
        lambda: any(isinstance(e, Overrides) and e.speed_pct == 200 for e in list(events)),
        60,
        "the service's Overrides event",
    )
    runner.join(120)
    assert _folded(events).state is JobState.DONE


def test_a_print_this_ui_started_is_not_adopted_a_second_time(backend, tmp_path):
    """The UI's status refresh looks for a print running in the service (started elsewhere)
    while the state of its own, just started, still reads idle (its first event on the way;
    seconds on a loaded machine): its own print is not adopted again. Before, a second
    follower took the print's events and end, and the first waited forever."""
    backend.connect(EMBEDDED, 250000)
    gcode = square_part(tmp_path / "part.gcode", layers=3)
    events: list = []
    job = backend.make_job(str(gcode), events.append)
    result: dict = {}
    runner = threading.Thread(target=lambda: result.update(job.run()), daemon=True)
    runner.start()
    wait_until(lambda: events, 60, "the print's first event")
    assert backend.running_job(lambda _event: None) is None  # it is this UI's own
    runner.join(120)
    assert result.get("status") == "completed", result
    assert _folded(events).state is JobState.DONE


class _Unanswering:
    """A connection to a service that takes every request and answers none."""

    def __init__(self) -> None:
        self.sent: list = []

    def send(self, message) -> int:
        self.sent.append(message)
        return len(self.sent)

    def close(self) -> None:
        pass


def test_a_request_waiting_for_its_answer_ends_when_the_ui_disconnects():
    """The UI lets go of the service (it quits, or picks another port) while a status
    request is out: the request ends with the reason, not after its 15 s timeout (the
    UI's closing waits for it)."""
    b = ServiceBackend("paper-prototype")
    b._client = _Unanswering()  # type: ignore[assignment]
    outcome: queue.Queue = queue.Queue()

    def status() -> None:
        try:
            outcome.put(b.operate(wire.Status()))
        except CdprError as exc:
            outcome.put(exc)

    threading.Thread(target=status, daemon=True).start()
    wait_until(lambda: b._client is not None and b._client.sent, 10, "the request sent")
    b.disconnect()
    ended = outcome.get(timeout=60)
    # (a request that waited out its 15 s would say the service did not answer)
    assert isinstance(ended, CdprError), ended
    assert "the connection to the printer service was closed" in str(ended)
