"""Quitting a UI whose print runs in the printer service (issue 32: a front end that goes
away never stops a print). ``ctrl+q`` while printing asks: leave it printing (the default),
cancel it, or stay; SIGHUP and SIGTERM leave the print to the service and say so in the
log. In-process (``--in-process``) the print dies with the process, so they still stop it
like a cancel. (Fake backend; the real service on a pty: test_service_pty.py.)"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from cdprhost.job.state import JobState
from cdprhost.tui.app import CdprApp
from cdprhost.tui.screens.dialogs import ConfirmScreen

from .conftest import make_app, shown, wait_for
from .fakes import FakeBackend
from .test_stop import start_print


@dataclass
class Quitting:
    """A UI about to quit while it prints: its backend (the print's steps held by ``gate``),
    the app, and the app's state folder."""

    backend: FakeBackend
    gate: threading.Semaphore
    app: CdprApp
    state: Path
    gcode: Path

    @contextlib.asynccontextmanager
    async def printing(self) -> AsyncIterator:
        """The app running, its print started; yields the pilot."""
        async with self.app.run_test(size=(100, 32)) as pilot:
            await start_print(pilot, self.gcode)
            yield pilot


@pytest.fixture
def quitting(request, gcode_file, tmp_path) -> Quitting:
    """A print in the printer service (as ServiceBackend says); ``in-process`` (indirect
    parameter): one that dies with the UI's process."""
    gate = threading.Semaphore(0)
    backend = FakeBackend(gate=gate, segments=40)
    if getattr(request, "param", "service") == "service":
        backend.print_outlives_ui = True
    state = tmp_path / "state"
    return Quitting(backend, gate, make_app(backend, state_folder=state), state, gcode_file)


async def _until_closed(pilot, app) -> None:
    for _ in range(200):
        if not app.is_running:
            return
        await pilot.pause(0.05)


async def test_quit_while_a_service_print_runs_asks_and_leaving_is_the_default(quitting):
    app = quitting.app
    async with quitting.printing() as pilot:
        quitting.gate.release()
        await pilot.press("ctrl+q")
        await wait_for(pilot, lambda s: isinstance(app.screen, ConfirmScreen), what="question")
        text = await shown(pilot)
        assert "Leave it printing" in text and "Cancel the print" in text
        assert "Stop it (like a cancel" not in text  # the in-process question
        await pilot.press("enter")  # the focused, primary button: leave it printing
        await _until_closed(pilot, app)
    job = quitting.backend.jobs[0]
    assert not app.is_running
    assert not job.finished and job.reason == "" and job.estops == 0  # never asked to stop
    assert not (quitting.state / "history.jsonl").exists()  # not recorded as ended
    quitting.gate.release(100)
    assert job.wait(10)


async def test_staying_keeps_the_ui_and_the_print(quitting):
    app = quitting.app
    async with quitting.printing() as pilot:
        await pilot.press("ctrl+q")
        await wait_for(pilot, lambda s: isinstance(app.screen, ConfirmScreen), what="question")
        await pilot.press("n")
        await pilot.pause(0.2)
        assert app.is_running and not isinstance(app.screen, ConfirmScreen)
        assert app.state.job.state is JobState.PRINTING and not app.controller.quitting
        quitting.gate.release(100)
        await wait_for(pilot, lambda s: s.job.state is JobState.DONE, what="the end")


async def test_the_cancel_choice_cancels_the_service_print_then_quits(quitting):
    app = quitting.app
    async with quitting.printing() as pilot:
        quitting.gate.release()
        await pilot.press("ctrl+q")
        await wait_for(pilot, lambda s: isinstance(app.screen, ConfirmScreen), what="question")
        await pilot.press("l")  # "Cancel the print"
        await _until_closed(pilot, app)
    job = quitting.backend.jobs[0]
    assert job.finished and job.reason == "quit" and job.estops == 0
    assert quitting.backend.closed_after_jobs == [True]


@pytest.mark.parametrize("name", ["SIGHUP", "SIGTERM"])
async def test_a_signal_leaves_a_service_print_running_and_says_so(quitting, name):
    app = quitting.app
    async with quitting.printing() as pilot:
        app.on_stop_signal(name)  # what the loop's signal handler calls
        await _until_closed(pilot, app)
    job = quitting.backend.jobs[0]
    assert not app.is_running
    assert not job.finished and job.reason == "" and job.estops == 0
    log = (quitting.state / "tui.log").read_text()
    assert f"{name}: the terminal UI quits; the print of {quitting.gcode}" in log
    assert "goes on in the printer service" in log
    quitting.gate.release(100)
    assert job.wait(10)


@pytest.mark.parametrize("quitting", ["in-process"], indirect=True)
async def test_in_process_a_signal_still_stops_the_print_like_a_cancel(quitting):
    app = quitting.app
    async with quitting.printing() as pilot:
        quitting.gate.release()
        app.on_stop_signal("SIGHUP")
        await wait_for(pilot, lambda s: app.controller.quitting == "SIGHUP", what="stopping")
        await _until_closed(pilot, app)
    job = quitting.backend.jobs[0]
    assert job.finished and job.reason == "SIGHUP"
    assert quitting.backend.closed_after_jobs == [True]
