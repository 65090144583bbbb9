"""Stopping, and a screen that never lies (issue 23, fake backend): quit while printing goes
through the job's safe stop before the link closes and the job lands in the history with its
resume point; the emergency-stop key works from every screen and shows the device's answer;
keys that cannot act say why; temperatures of a finished job are not shown as current; a
device fault is explained before a start, and a saved resume point offered."""

from __future__ import annotations

import json
import threading
from dataclasses import replace

import pytest

from cdprhost.job.state import JobState, Notice
from cdprhost.tui.app import ESTOP_KEY
from cdprhost.tui.control.views import ResumeView
from cdprhost.tui.screens.dialogs import ConfirmScreen
from cdprhost.tui.screens.help import HelpScreen
from cdprhost.tui.tabs import TABS
from cdprhost.tui.widgets.temperature_graph import TemperatureGraph

from .conftest import make_app, pick_file, shown, wait_for
from .fakes import FakeBackend


def notes(app) -> str:
    """The notifications on show (title and message)."""
    return "\n".join(f"{n.title}: {n.message}" for n in app._notifications)


async def start_print(pilot, path, until=JobState.PRINTING) -> None:
    await wait_for(pilot, lambda s: s.connected, what="connected")
    await pick_file(pilot, path)
    await wait_for(pilot, lambda s: s.file.preflight is not None, what="preflight")
    await pilot.press("s")
    await wait_for(pilot, lambda s: isinstance(pilot.app.screen, ConfirmScreen), what="question")
    await pilot.press("y")
    await wait_for(pilot, lambda s: s.job.state is until, what=until.value)


async def test_quit_while_printing_stops_the_job_before_the_link_closes(gcode_file, tmp_path):
    gate = threading.Semaphore(0)
    backend = FakeBackend(gate=gate, segments=40)
    app = make_app(backend, state_folder=tmp_path / "state")
    async with app.run_test(size=(100, 32)) as pilot:
        await start_print(pilot, gcode_file)
        for _ in range(5):
            gate.release()
        await wait_for(pilot, lambda s: s.job.segments_done == 5, what="5 segments")
        # the job saves its resume point as it goes
        backend.resume_points[str(gcode_file)] = ResumeView(
            "/tmp/r.json", str(gcode_file), "cancelled: quit", 1, 15, None, "", True
        )
        await pilot.press("ctrl+q")
        assert "Stop it (like a cancel" in await shown(pilot)
        await pilot.press("y")
        for _ in range(100):
            if not app.is_running:
                break
            await pilot.pause(0.05)
    job = backend.jobs[0]
    assert job.finished and job.reason == "quit" and job.estops == 0
    assert backend.closed_after_jobs == [True]  # the link closed after the job had ended
    lines = (tmp_path / "state" / "history.jsonl").read_text().splitlines()
    record = json.loads(lines[-1])
    assert record["status"] == "cancelled" and record["reason"] == "cancelled: quit"
    assert record["resume_at"] == "line 15 (layer 1)"


async def test_quit_asked_again_while_stopping_is_an_emergency_stop(gcode_file, tmp_path):
    gate = threading.Semaphore(0)
    backend = FakeBackend(gate=gate, segments=40, rest_every=100)  # never reaches a rest point
    app = make_app(backend, state_folder=tmp_path / "state")
    async with app.run_test(size=(100, 32)) as pilot:
        await start_print(pilot, gcode_file)
        gate.release()
        await pilot.press("ctrl+q", "y")
        await wait_for(pilot, lambda s: app.controller.quitting == "quit", what="quitting")
        assert app.is_running  # it waits for the machine
        await pilot.press("ctrl+q")
        await wait_for(pilot, lambda s: backend.jobs[0].estops == 1, what="e-stop")
        for _ in range(40):
            gate.release()
        for _ in range(100):
            if not app.is_running:
                break
            await pilot.pause(0.05)
    assert backend.closed_after_jobs == [True]


@pytest.mark.parametrize("mode", [t.mode for t in TABS])
async def test_emergency_stop_key_on_every_screen_is_a_double_press(fake_backend, mode):
    app = make_app(fake_backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await app.switch_mode(mode)
        await pilot.pause()
        await pilot.press(ESTOP_KEY)
        await pilot.pause(0.1)
        assert fake_backend.estops == 0  # armed only
        assert "emergency stop armed" in notes(app)
        await pilot.press(ESTOP_KEY)
        await wait_for(pilot, lambda s: fake_backend.estops == 1, what="stopped")
        await wait_for(pilot, lambda s: "the device confirmed" in s.console[-1].text, what="answer")
        assert "E-STOP" in (await shown(pilot)).splitlines()[-1]  # in the key bar


async def test_emergency_stop_while_printing_goes_through_the_job(gcode_file):
    gate = threading.Semaphore(0)
    backend = FakeBackend(gate=gate)
    app = make_app(backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await start_print(pilot, gcode_file)
        gate.release()
        await pilot.press(ESTOP_KEY, ESTOP_KEY)
        state = await wait_for(pilot, lambda s: s.job.state.finished, what="stopped")
        assert state.job.state is JobState.FAILED and state.job.reason == "emergency stop"
        assert backend.jobs[0].estops == 1
        await wait_for(pilot, lambda s: any("EMERGENCY STOP" in c.text for c in s.console))


async def test_a_key_that_cannot_act_says_why(fake_backend, gcode_file):
    app = make_app(fake_backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        app.screen.set_focus(None)
        await pilot.press("p")  # pause, with nothing printing
        await pilot.pause(0.1)
        assert "p Pause: no print is running" in notes(app)
        await pilot.press("question_mark")
        await wait_for(pilot, lambda s: isinstance(app.screen, HelpScreen))
        text = await shown(pilot)
        assert "(not now: no file open" in text and "(not now)" not in text


async def test_footer_offers_no_start_or_cancel_without_a_link(fake_backend, gcode_file):
    app = make_app(fake_backend)
    async with app.run_test(size=(120, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await pick_file(pilot, gcode_file)
        await wait_for(pilot, lambda s: s.file.preflight is not None)
        assert "s Start" in (await shown(pilot)).splitlines()[-1]
        conn = app.state.connection
        app.controller.update(connection=replace(conn, status="error", error="port gone"))
        footer = (await shown(pilot)).splitlines()[-1]
        assert "Start" not in footer and "Cancel" not in footer and "Pause" not in footer
        await pilot.press("s")
        await pilot.pause(0.1)
        assert "s Start: not connected" in notes(app)


async def test_a_finished_jobs_temperatures_are_not_shown_as_current(gcode_file):
    backend = FakeBackend(segments=5)
    app = make_app(backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await start_print(pilot, gcode_file, until=JobState.DONE)
        await wait_for(pilot, lambda s: s.device is not None, what="device read again")
        await pilot.pause(0.2)
        graph = app.screen.query_one(TemperatureGraph)
        assert graph._current == (25.0, 25.0) and graph._targets == (0.0, 0.0)  # the device's


async def test_a_device_fault_is_explained_before_a_start_and_a_resume_point_offered(gcode_file):
    backend = FakeBackend()
    backend.status = replace(
        backend.status,
        fault="the device is stopped by a fault (watchdog: its host stopped answering)",
    )
    backend.resume_points[str(gcode_file)] = ResumeView(
        "/tmp/r.json", str(gcode_file), "watchdog", 2, 33, None, "", True
    )
    app = make_app(backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        app.controller.refresh_device()
        await pick_file(pilot, gcode_file)
        await wait_for(pilot, lambda s: s.file.resume is not None and s.device is not None)
        assert "stopped by a fault (watchdog" in await shown(pilot)  # shown before a start
        await pilot.press("s")
        await wait_for(pilot, lambda s: isinstance(app.screen, ConfirmScreen))
        text = " ".join(app.screen.question.plain.split())  # as asked (wrapped on screen)
        assert "The device is stopped by a fault (watchdog: its host stopped answering)" in text
        assert "Starting clears it" in text
        assert "A resume point is saved for this file: line 33 (layer 2)" in text
        await pilot.press("n")
        await wait_for(pilot, lambda s: not isinstance(app.screen, ConfirmScreen))
        assert app.state.job_id == 0  # nothing started
        await pilot.press("s", "y")  # now the operator accepts: the start clears it
        await wait_for(pilot, lambda s: s.job_id == 1)
        assert backend.cleared_fault
        app.controller.cancel()


async def test_a_notice_from_the_start_does_not_stay_on_the_status_line(gcode_file):
    clock = [1000.0]
    gate = threading.Semaphore(0)
    app = make_app(FakeBackend(gate=gate), clock=lambda: clock[0])
    async with app.run_test(size=(100, 32)) as pilot:
        await start_print(pilot, gcode_file)
        app.pump.put(app.state.job_id, Notice("the device was stopped by a fault: cleared"))
        await wait_for(pilot, lambda s: s.job.notices, what="notice")
        assert "stopped by a fault: cleared" in await shown(pilot)
        clock[0] += 60.0  # a minute later the job is printing: the notice is history
        gate.release()
        await wait_for(pilot, lambda s: s.job.segments_done == 1)
        await pilot.pause(0.2)
        assert "stopped by a fault" not in (await shown(pilot)).splitlines()[4]
        app.controller.cancel()
        for _ in range(40):
            gate.release()


async def test_logging_goes_to_the_console_and_a_file_never_the_terminal(fake_backend, tmp_path):
    import logging
    import sys

    app = make_app(fake_backend, state_folder=tmp_path / "state")
    before = list(logging.getLogger().handlers)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        handlers = logging.getLogger().handlers + logging.getLogger("cdprhost").handlers
        assert not any(getattr(h, "stream", None) is sys.stderr for h in handlers)
        logging.getLogger("cdprhost.job.runner").warning("emergency stop not acknowledged")
        await wait_for(pilot, lambda s: any("not acknowledged" in c.text for c in s.console))
    assert "not acknowledged" in (tmp_path / "state" / "tui.log").read_text()
    assert logging.getLogger().handlers == before  # put back on exit
