"""The print screen on the fake backend: open, preflight, start/pause/resume/finish, cancel, failure."""

from __future__ import annotations

import threading

from cdprhost.job.state import JobState
from cdprhost.tui.control.views import ResumeView
from cdprhost.tui.screens.dialogs import ConfirmScreen, FailureScreen
from cdprhost.tui.widgets.progress_panel import progress_lines
from cdprhost.tui.widgets.violation_list import ViolationList

from .conftest import make_app, pick_file, shown, wait_for
from .fakes import FakeBackend


async def open_file(pilot, path) -> None:
    await pick_file(pilot, path)
    await wait_for(pilot, lambda s: s.file.preflight is not None or s.file.error, what="preflight")


async def test_opens_on_print_screen_connected(fake_backend):
    app = make_app(fake_backend)
    async with app.run_test(size=(80, 24)) as pilot:
        state = await wait_for(pilot, lambda s: s.connected, what="connected")
        assert app.current_mode == "print"
        assert state.connection.port == "sim"
        assert dict(state.connection.identity)["firmware"] == "cdpr-sim 0.1"


async def test_whole_print_with_pause_and_resume(gcode_file):
    gate = threading.Semaphore(0)
    backend = FakeBackend(gate=gate, segments=30, layers=3)
    app = make_app(backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await open_file(pilot, gcode_file)
        assert app.state.file.preflight.ok
        await pilot.press("s")
        assert isinstance(app.screen, ConfirmScreen)
        await pilot.press("y")
        await wait_for(pilot, lambda s: s.job.state is JobState.PRINTING, what="printing")
        for _ in range(10):
            gate.release()
        state = await wait_for(pilot, lambda s: s.job.segments_done == 10, what="10 segments")
        assert state.job.layers == 3 and state.job.position == (10.0, 5.0, 110.0)
        assert app.check_print_action("pause_print") and not app.check_print_action("resume_print")
        await pilot.press("p")
        await wait_for(pilot, lambda s: s.job.state is JobState.PAUSED, what="paused")
        assert app.check_print_action("resume_print")
        await pilot.press("r")
        assert isinstance(app.screen, ConfirmScreen)
        await pilot.press("y")
        await wait_for(pilot, lambda s: s.job.state is JobState.PRINTING, what="resumed")
        for _ in range(40):
            gate.release()
        state = await wait_for(pilot, lambda s: s.job.state is JobState.DONE, what="done")
        assert state.job.segments_done == 30 and state.job.fraction == 1.0
        assert state.job.link.retransmits == 3
        assert app.problems == []
        head, stats, line = progress_lines(state.job, "")
        assert "DONE" in head.plain and "layer 3/3" in stats.plain


async def test_cancel_asks_first(gcode_file):
    gate = threading.Semaphore(0)
    backend = FakeBackend(gate=gate)
    app = make_app(backend)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await open_file(pilot, gcode_file)
        await pilot.press("s", "y")
        await wait_for(pilot, lambda s: s.job.state is JobState.PRINTING)
        await pilot.press("x")
        assert isinstance(app.screen, ConfirmScreen)
        await pilot.press("n")  # declined: still printing
        gate.release()
        await wait_for(pilot, lambda s: s.job.segments_done == 1)
        assert app.state.job.state is JobState.PRINTING
        await pilot.press("x", "y")
        await wait_for(pilot, lambda s: s.job.state is JobState.CANCELLED, what="cancelled")


async def test_preflight_violations_listed_and_jump_to_line(tmp_path):
    path = tmp_path / "bad.gcode"
    path.write_text("".join(f"G1 X{i} ; line {i + 1}\n" for i in range(30)), encoding="utf-8")
    app = make_app(FakeBackend())
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await open_file(pilot, path)
        pre = app.state.file.preflight
        assert not pre.ok and [v.line for v in pre.violations] == [12, 15]
        assert app.check_print_action("start_print") is None  # refused file: start greyed out
        table = app.screen.query_one(ViolationList)
        assert table.row_count == 2
        await wait_for(pilot, lambda s: app.screen.source is not None, what="source index")
        table.focus()
        await pilot.press("down", "enter")
        await pilot.pause()
        assert app.screen._jump == 15
        text = await shown(pilot)
        assert "> 15 G1 X14 ; line 15" in text.replace("     15", " 15")
        assert "line 15: unknown_command:" in text and "M999 is not" in text  # the title wraps


async def test_device_reset_mid_print_shows_stop_and_resume_point(gcode_file):
    backend = FakeBackend(segments=30, layers=3, fail_at=12)
    backend.resume_points[str(gcode_file)] = ResumeView(
        "/state/part.resume.json", str(gcode_file), "device reset", 2, 22
    )
    app = make_app(backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await open_file(pilot, gcode_file)
        await pilot.press("s", "y")
        state = await wait_for(pilot, lambda s: s.job.state is JobState.FAILED, what="failed")
        await pilot.pause()
        assert state.job.failure.last_line == 22
        assert isinstance(app.screen, FailureScreen)
        text = str(app.screen.query_one("#failure-text").render())
        assert "device reset" in text and "last executed line: 22" in text
        assert "--resume-from-layer 2" in text
        assert "Resume (r)" in await shown(pilot)
        # the port went away with the device: resuming must check the link, not start a job
        backend.link_dead = True
        await pilot.press("r")
        await wait_for(pilot, lambda s: s.connection.status == "error", what="link checked")
        await pilot.pause(0.1)
        assert len(backend.jobs) == 1 and app.state.job_id == 1
        assert any("reconnect" in n.message for n in app._notifications)
        # reconnect, then resume from the print screen: the point is found by the file
        await pilot.press("f1", "c")
        await wait_for(pilot, lambda s: s.connected, what="reconnected")
        await pilot.press("f2")
        await wait_for(pilot, lambda s: s.file.resume is not None, what="resume point")
        assert "resume point layer 2 (device reset) · l Resume stopped" in await shown(pilot)
        await pilot.press("l")
        await wait_for(pilot, lambda s: isinstance(app.screen, ConfirmScreen), what="question")
        assert "Resume part.gcode from layer 2" in await shown(pilot)
        await pilot.press("y")
        await wait_for(pilot, lambda s: s.job_id == 2 and s.job.state.finished, what="second job")
        assert len(backend.jobs) == 2 and backend.jobs[1].resume_from_layer == 1  # 0-based
        assert app.state.job_resumed_from == 2
