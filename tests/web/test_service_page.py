"""The web page served by a client of the printer service (what `cdprhost serve` runs): its
home, jog, heaters-off and e-stop buttons reach the device the service owns, and a print
started by the page runs in the service. (The service runs in a thread of the test, so the
test can look at its embedded device.)"""

from __future__ import annotations

import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from cdprhost.profile import load_profile
from cdprhost.server.apikey import KeyFile
from cdprhost.server.app import create_app
from cdprhost.server.listen import ServerThread
from cdprhost.server.service_printer import ServicePrinter
from cdprhost.server.uploads import UploadFolder
from tests.service.inprocess import serve_in_thread
from tests.web.conftest import PROFILE, WebServer, part, unlock

STATE_TEXT = "document.getElementById('state').textContent.toLowerCase()"


@pytest.fixture
def service_server(tmp_path, monkeypatch) -> Iterator[Callable[..., tuple[WebServer, Any]]]:
    folder = tempfile.mkdtemp(prefix="websvc-", dir="/tmp")  # a socket's path is short
    monkeypatch.setenv("CDPRHOST_RUN", folder)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    monkeypatch.setenv("CDPRHOST_STATE", str(tmp_path / "state"))
    services = serve_in_thread(monkeypatch, idle_s=30.0)
    made: list[tuple[WebServer, ServicePrinter]] = []

    def make(speedup: float = 10.0) -> tuple[WebServer, Any]:
        printer = ServicePrinter(load_profile(PROFILE), speedup=speedup)
        printer.connect()
        keys = KeyFile()
        uploads = UploadFolder(tmp_path / f"uploads{len(made)}")
        app = create_app(printer, uploads, keys.current, max_upload_bytes=5_000_000)
        thread = ServerThread(app, "127.0.0.1", 0)
        thread.start()
        server = WebServer(thread.url, keys.key, uploads.root, printer, thread, [])  # type: ignore[arg-type]
        made.append((server, printer))
        return server, services[-1]

    yield make
    for server, printer in made:
        printer.shutdown("test over", timeout_s=30)
        server.thread.stop()
    for service in services:
        service.shutdown_job("test over")
    shutil.rmtree(folder, ignore_errors=True)


def _idle_machine(service: Any) -> Any:
    """The embedded device of the service's device session."""
    link = service.session._link
    assert link is not None, "the service has no device session"
    return link.device.machine


def _wait(cond: Callable[[], object], what: str, timeout: float = 60.0) -> Any:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = cond()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"{what} did not happen within {timeout:g} s")


def _message(page: Any) -> str:
    return str(page.text_content("#message") or "")


def test_the_page_homes_jogs_and_e_stops_the_services_device(service_server, page):
    server, service = service_server()
    unlock(page, server)
    page.click("#home")
    page.wait_for_function("document.getElementById('message').textContent === 'home: asked'")
    machine = _idle_machine(service)
    assert machine.homed_mask == 0b111
    before = list(machine.pos)
    page.select_option("#jog-step", "5")
    page.click("[data-jog='1,0,0']")
    page.wait_for_function("document.getElementById('message').textContent === 'jog: asked'")
    _wait(lambda: list(machine.pos) != before, "the jog reaching the motors")
    page.click("#heaters-off")
    page.wait_for_function(
        "document.getElementById('message').textContent === 'heaters off: asked'"
    )
    page.click("#estop")
    page.wait_for_function("document.getElementById('message').textContent === 'e-stop: asked'")
    assert machine.estopped and machine.enabled_mask  # stopped, the motors kept
    page.click("#home")  # a stopped device refuses, and the page says why
    page.wait_for_function("document.getElementById('message').className === 'error'")
    assert "home" in _message(page)


def test_a_print_started_by_the_page_runs_in_the_service_and_its_e_stop_is_the_jobs(
    service_server, page
):
    server, service = service_server()
    server.upload("listed.gcode", part(layers=30))
    unlock(page, server)
    page.click("#home")
    page.wait_for_function("document.getElementById('message').textContent === 'home: asked'")
    homed = service.session._link
    page.click("#files button[data-path='listed.gcode']")
    _wait(lambda: service.job_running and server.state() == "printing", "printing")
    page.wait_for_function(f"{STATE_TEXT}.startsWith('printing')")
    job = service._job
    assert job.link is homed  # the job took the device session's link: one device, homed
    page.click("#estop")
    server.wait_state("failed")
    machine = job.link.device.machine
    assert machine.estopped and machine.enabled_mask  # motors kept: the effector does not drop
    page.wait_for_function(f"{STATE_TEXT}.startsWith('failed')")
    assert Path(server.printer.status().file or "").name == "listed.gcode"


def test_under_tui_listen_the_ui_and_the_page_are_two_clients_of_one_service(service_server, page):
    """What `cdprhost tui --listen` builds (cli/commands/tui.py): the UI's ServiceBackend
    and the page's ServicePrinter on the same service; the page's home, jog and e-stop
    reach the device the UI sees, and a print started by the page is one the UI adopts."""
    from cdprhost.job.state import JobSnapshot, JobState, reduce
    from cdprhost.tui.control.backend import EMBEDDED
    from cdprhost.tui.control.service_backend import ServiceBackend

    server, service = service_server()
    ui = ServiceBackend(PROFILE, speedup=10.0)
    try:
        ui.connect(EMBEDDED, 250000)
        assert len(service._clients) == 2  # the page's printer and the UI: one service
        server.upload("both.gcode", part(layers=30))
        unlock(page, server)
        page.click("#home")
        page.wait_for_function("document.getElementById('message').textContent === 'home: asked'")
        assert _idle_machine(service).homed_mask == 0b111
        seen = _wait(
            lambda: (st := ui.device_status()) is not None and st.homed and st,
            "the page's homing seen by the UI",
            timeout=10.0,
        )
        assert seen.position is not None
        page.select_option("#jog-step", "5")
        page.click("[data-jog='1,0,0']")
        page.wait_for_function("document.getElementById('message').textContent === 'jog: asked'")
        moved = _wait(
            lambda: (st := ui.device_status()) is not None and st.position != seen.position and st,
            "the page's jog seen by the UI",
        )
        assert moved.position[0] == pytest.approx(seen.position[0] + 5.0, abs=0.05)
        page.click("#files button[data-path='both.gcode']")
        events: list = []
        found = _wait(lambda: ui.running_job(events.append), "the page's print offered to the UI")
        path, _, _ = found
        assert Path(path).name == "both.gcode"
        page.click("#estop")
        server.wait_state("failed")
        machine = _idle_machine(
            service
        )  # the job's link is the session's (none yet in its preflight)
        assert machine.estopped and machine.enabled_mask  # motors kept

        def folded() -> JobSnapshot:
            snap = JobSnapshot()
            for event in events:
                snap = reduce(snap, event)
            return snap

        _wait(lambda: folded().state is JobState.FAILED, "the page's e-stop seen by the UI")
    finally:
        ui.close()
