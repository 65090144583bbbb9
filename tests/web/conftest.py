"""A print server on 127.0.0.1 with the embedded simulated device, and Debian's chromium
driven headless by Playwright's Python API (no browser download). Without playwright or a
chromium the browser tests skip and say why. Every wait is bounded; nothing asserts a
duration but the issue's own bound (a state change seen in the page within 0.5 s)."""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from cdprhost.job.state import Event, StateChanged
from cdprhost.profile import load_profile
from cdprhost.server.apikey import KeyFile
from cdprhost.server.app import create_app
from cdprhost.server.headless import HeadlessPrinter
from cdprhost.server.listen import ServerThread
from cdprhost.server.uploads import UploadFolder
from cdprhost.sim.embedded import open_embedded
from tests.server.conftest import multipart, small_part

PROFILE = "paper-prototype"
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
    "--disable-sync",
]


def chromium_path() -> str | None:
    found = os.environ.get("CDPRHOST_CHROMIUM") or shutil.which("chromium")
    if found:
        return found
    return "/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None


def part(layers: int = 6, side: float = 20.0) -> str:
    return small_part(layers=layers, side=side)


@dataclass
class WebServer:
    url: str
    key: str
    uploads: Path
    printer: HeadlessPrinter
    thread: ServerThread
    links: list[Any]
    #: wall-clock time (epoch s) each job state was last entered, from the printer's events
    reached: dict[str, float] = field(default_factory=dict)

    def device(self) -> Any:
        """The embedded device's machine model (estopped, enabled_mask, heaters)."""
        return self.links[-1].device.machine

    def state(self) -> str:
        return self.printer.status().job.state.value

    def wait_state(self, *states: str, timeout: float = 60.0) -> str:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.state() in states:
                return self.state()
            time.sleep(0.02)
        raise AssertionError(f"the job did not reach {states} within {timeout:g} s: {self.state()}")

    def job_command(self, command: dict[str, str]) -> int:
        import http.client
        import json

        conn = http.client.HTTPConnection("127.0.0.1", self.thread.port, timeout=60)
        try:
            headers = {"X-Api-Key": self.key, "Content-Type": "application/json"}
            conn.request("POST", "/api/job", json.dumps(command), headers)
            reply = conn.getresponse()
            reply.read()
            return reply.status
        finally:
            conn.close()

    def upload(self, name: str, text: str, start: bool = False) -> int:
        import http.client

        body, kind = multipart([("print", "true")] if start else [], (name, text.encode()))
        conn = http.client.HTTPConnection("127.0.0.1", self.thread.port, timeout=60)
        try:
            conn.request(
                "POST", "/api/files/local", body, {"X-Api-Key": self.key, "Content-Type": kind}
            )
            reply = conn.getresponse()
            text = reply.read()
            assert reply.status < 300 or reply.status == 409, text
            return reply.status
        finally:
            conn.close()


@pytest.fixture
def web_server(tmp_path, monkeypatch) -> Iterator[Callable[..., WebServer]]:
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    monkeypatch.setenv("CDPRHOST_STATE", str(tmp_path / "state"))
    made: list[WebServer] = []

    def make(speedup: float | None = 4.0, camera: Any = None) -> WebServer:
        links: list[Any] = []
        reached: dict[str, float] = {}

        def open_device() -> Any:
            link = open_embedded(speedup=speedup)
            links.append(link)
            return link

        def on_event(event: Event) -> None:
            if isinstance(event, StateChanged):
                reached[event.state.value] = time.time()

        printer = HeadlessPrinter(load_profile(PROFILE), open_device, on_event=on_event)
        keys = KeyFile()
        uploads = UploadFolder(tmp_path / f"uploads{len(made)}")
        app = create_app(printer, uploads, keys.current, max_upload_bytes=5_000_000, camera=camera)
        thread = ServerThread(app, "127.0.0.1", 0)
        thread.start()
        made.append(WebServer(thread.url, keys.key, uploads.root, printer, thread, links, reached))
        return made[-1]

    yield make
    for s in made:
        s.printer.shutdown("test over", timeout_s=30)
        s.thread.stop()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    sync_api = pytest.importorskip(
        "playwright.sync_api", reason="playwright is not installed (pip install -e '.[test]')"
    )
    path = chromium_path()
    if path is None:
        pytest.skip("no chromium here (apt-get install chromium): the browser tests need one")
    pw = sync_api.sync_playwright().start()
    try:
        b = pw.chromium.launch(executable_path=path, headless=True, args=CHROMIUM_ARGS)
    except sync_api.Error as exc:
        pw.stop()
        pytest.skip(f"chromium at {path} does not start headless: {exc}")
    yield b
    b.close()
    pw.stop()


@pytest.fixture
def page(browser) -> Iterator[Any]:
    """A fresh page (its own storage) at desktop size; dialogs (cancel's confirm) accepted.
    bypass_csp: Playwright's waits evaluate their expressions, which the page's policy forbids."""
    context = browser.new_context(viewport={"width": 1280, "height": 800}, bypass_csp=True)
    pg = context.new_page()
    pg.on("dialog", lambda d: d.accept())
    pg.set_default_timeout(20_000)
    yield pg
    context.close()


def unlock(pg: Any, server: WebServer) -> None:
    """Open the page and enter the key as a person would."""
    pg.goto(server.url + "/")
    pg.fill("#key", server.key)
    pg.click("#key-form button[type=submit]")
    pg.wait_for_function("window.cdpr && window.cdpr.doc !== null")
