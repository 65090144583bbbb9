"""Helpers for the headless UI tests: an app on the fake backend and waiting on its state."""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import signal
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import pytest

from cdprhost.tui.app import CdprApp
from cdprhost.tui.state import UiState

from .fakes import FakeBackend


@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem):
    """Run ``async def`` tests in a fresh event loop (no asyncio plugin needed)."""
    if inspect.iscoroutinefunction(pyfuncitem.obj):
        args = {name: pyfuncitem.funcargs[name] for name in pyfuncitem._fixtureinfo.argnames}
        asyncio.run(pyfuncitem.obj(**args))
        return True
    return None


async def wait_for(
    pilot, predicate: Callable[[UiState], bool], timeout: float = 10.0, what: str = ""
) -> UiState:
    """Let the app run until ``predicate(app.state)`` holds (fails the test after ``timeout`` s)."""
    app = pilot.app
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not predicate(app.state):
        if loop.time() > deadline:
            raise AssertionError(
                f"timed out waiting for {what or predicate}: state is {app.state.job.state}, "
                f"connection {app.state.connection.status}"
            )
        await pilot.pause(0.01)
    return app.state


@pytest.fixture
def fake_backend() -> FakeBackend:
    return FakeBackend()


def make_app(backend, **kw) -> CdprApp:
    """The app on ``backend``, without timers, keeping its recent files and history in a
    folder of its own."""
    kw.setdefault("status_interval_s", 0)
    kw.setdefault("health_interval_s", 0)
    kw.setdefault("state_folder", Path(tempfile.mkdtemp(prefix="cdpr-tui-")))
    return CdprApp(backend, **kw)


async def pick_file(pilot, path) -> None:
    """o, then the picker's path field (its own key), type the path, Enter."""
    await pilot.press("o")
    await wait_for(pilot, lambda s: pilot.app.screen.query("#file-input"), what="the picker")
    await pilot.press("ctrl+o")
    pilot.app.screen.query_one("#file-input").value = str(path)
    await pilot.press("enter")


@pytest.fixture
def gcode_file(tmp_path):
    path = tmp_path / "part.gcode"
    path.write_text(
        "".join(f"G1 X{i} Y{i} E{0.1 * i:.2f} ; move {i}\n" for i in range(1, 60)), encoding="utf-8"
    )
    return path


def screen_text(app) -> str:
    """The current screen as plain text, one line per terminal row."""
    strips = app.screen._compositor.render_strips()
    return "\n".join("".join(segment.text for segment in strip) for strip in strips)


async def shown(pilot) -> str:
    """Screen text after the pending repaint."""
    await pilot.pause()
    return screen_text(pilot.app)


@contextlib.contextmanager
def sim_device(*options: str):
    """``cdprhost sim-device`` in its own process; yields (pty path, process)."""
    cmd = [sys.executable, "-m", "cdprhost", "sim-device", *options]
    dev = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        path = dev.stdout.readline().strip()
        if not path.startswith("/dev/"):
            err = dev.stderr.read() if dev.poll() is not None else ""
            raise AssertionError(f"sim-device printed {path!r}: {err}")
        yield path, dev
    finally:
        if dev.poll() is None:
            dev.send_signal(signal.SIGTERM)
            try:
                dev.wait(timeout=20)
            except subprocess.TimeoutExpired:
                dev.kill()
                dev.wait()


@pytest.fixture
def run_dir(monkeypatch, tmp_path):
    """A short private run folder for printer services (a socket's path is at most 107
    bytes) and a state folder of the test's own."""
    import shutil

    folder = tempfile.mkdtemp(prefix="svc-", dir="/tmp")
    monkeypatch.setenv("CDPRHOST_RUN", folder)
    monkeypatch.setenv("CDPRHOST_STATE", str(tmp_path / "state"))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)
