"""Acceptance: one operator session, keys only, against ``cdprhost sim-device`` on a
pseudo-terminal: connect, pick a file, print, pause, resume, cancel (at rest within the moves
already sent), jog; then the device dies mid-print, comes back on a new port, and the failed
print resumes from its layer; last, quit while printing: the machine is stopped, parked,
heaters off and the job recorded before the link closes (no crash, no watchdog fault)."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import sys
import time

import pytest
from textual.widgets import OptionList

from cdprhost.job.state import JobState
from cdprhost.link import open_link
from cdprhost.tui.control.live import LiveBackend
from cdprhost.tui.screens.dialogs import ConfirmScreen, FailureScreen
from cdprhost.tui.screens.file_picker import FilePickerScreen

from .conftest import make_app, shown, sim_device, wait_for
from .parts import small_part

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux")


async def connect_listed(pilot, port: str) -> None:
    """F1, rescan, move down the list to ``port``, Enter."""
    app = pilot.app
    await pilot.press("f1")
    screen = app.screen
    screen.set_focus(screen.query_one("#port-list"))
    await pilot.press("r")
    await wait_for(pilot, lambda s: any(c.port == port for c in screen.choices), 30, "listed")
    options = screen.query_one("#port-list", OptionList)
    for _ in range(5):  # the list is rescanned while shown: other terminals come and go
        await pilot.press("home")
        for _ in range(next(i for i, c in enumerate(screen.choices) if c.port == port)):
            await pilot.press("down")
        if screen.choices[options.highlighted].port == port:
            break
    assert screen.choices[options.highlighted].port == port
    await pilot.press("enter")
    await wait_for(pilot, lambda s: s.connected and s.connection.port == port, 30, "connected")


async def confirm(pilot, *, contains: str = "") -> None:
    await wait_for(pilot, lambda s: isinstance(pilot.app.screen, ConfirmScreen), 30, "question")
    if contains:
        assert contains in await shown(pilot)
    await pilot.press("y")


async def test_operator_session_on_a_pty_device(tmp_path):
    part = tmp_path / "tube.gcode"
    part.write_text(small_part(layers=40), encoding="utf-8")
    backend = LiveBackend(
        "paper-prototype",
        speedup=None,
        job_options={"resume_dir": tmp_path / "resume", "log_path": tmp_path / "job.jsonl"},
    )
    app = make_app(backend, connect_on_start=False, status_interval_s=1.0, health_interval_s=0.5)
    with sim_device("--speedup", "20") as (first_port, first):
        async with app.run_test(size=(100, 32)) as pilot:
            # connect to the device on its pseudo-terminal, picked from the list
            await connect_listed(pilot, first_port)
            assert not app.state.connection.simulated
            # pick the file: o, the path field, Enter
            await pilot.press("f2", "o")
            await wait_for(pilot, lambda s: isinstance(app.screen, FilePickerScreen), 10, "picker")
            await pilot.press("ctrl+o")
            app.screen.query_one("#file-input").value = str(part)
            await pilot.press("enter")
            state = await wait_for(pilot, lambda s: s.file.preflight is not None, 60, "preflight")
            assert state.file.preflight.ok and state.file.preflight.toolpath.layers == 40
            # print, pause, resume
            await pilot.press("s")
            await confirm(pilot, contains="Start printing")
            await wait_for(pilot, lambda s: s.job.segments_done > 50, 60, "printing")
            await pilot.press("p")
            state = await wait_for(pilot, lambda s: s.job.state is JobState.PAUSED, 60, "paused")
            paused_at = state.job.segments_done
            await pilot.press("r")
            await confirm(pilot)
            await wait_for(pilot, lambda s: s.job.segments_done > paused_at + 20, 60, "resumed")
            # cancel: it stops at rest, parks, heaters off, and goes to the history
            await pilot.press("x")
            await confirm(pilot, contains="Cancel the print?")
            state = await wait_for(
                pilot, lambda s: s.job.state is JobState.CANCELLED, 60, "cancelled"
            )
            assert any(": at rest " in n for n in state.job.notices)  # within the moves sent
            state = await wait_for(
                pilot, lambda s: s.history and not s.busy and s.device is not None, 60, "parked"
            )
            assert state.device.hotend_target == 0 and state.history[0].status == "cancelled"
            # jog 10 mm in x, feasibility first
            start = state.device.position
            await pilot.press("f3", "3", "right")
            assert app.state.jog.ok, app.state.jog.reason
            await pilot.press("enter")
            state = await wait_for(pilot, lambda s: not s.busy and s.jog is None, 60, "jogged")
            assert state.device.position[0] == pytest.approx(start[0] + 10.0, abs=0.02)
            # print again; the device dies (power cut) in the middle of it
            await pilot.press("f2", "s")
            await confirm(pilot)
            await wait_for(pilot, lambda s: s.job.layer >= 4, 120, "layer 5")
            os.kill(first.pid, signal.SIGKILL)
            state = await wait_for(pilot, lambda s: s.job.state is JobState.FAILED, 60, "failed")
            failure = state.job.failure
            assert failure is not None and failure.last_layer is not None
            await wait_for(pilot, lambda s: isinstance(app.screen, FailureScreen), 10, "report")
            await pilot.press("escape")
            with sim_device("--speedup", "20") as (second_port, _):
                # the device is back (a new port): reconnect, the resume point is found by file
                await connect_listed(pilot, second_port)
                await pilot.press("f2")
                state = await wait_for(pilot, lambda s: s.file.resume is not None, 30, "resume")
                resume = state.file.resume
                assert resume.problem == "" and resume.layer == failure.last_layer + 1
                assert resume.exact and resume.last_line == failure.last_line  # --resume
                assert f"resume point line {resume.last_line}" in await shown(pilot)
                await pilot.press("l")
                await confirm(pilot, contains=f"at line {resume.last_line}")
                state = await wait_for(
                    pilot,
                    lambda s: (s.job_id == 3 and s.job.segments_done > 20) or s.job.state.finished,
                    120,
                    "resumed print",
                )
                assert state.job.state.active, state.job.reason
                assert state.job_resumed_from == resume.layer
                assert state.job.layer >= failure.last_layer  # it restarted at the stopped layer
                await pilot.press("x")
                await confirm(pilot)
                state = await wait_for(
                    pilot,
                    lambda s: s.job.state.finished and not s.busy and len(s.history) == 3,
                    60,
                    "end",
                )  # the job's end is shown before its history line is added
                assert [r.status for r in state.history] == ["cancelled", "failed", "cancelled"]
                # quit while printing: stopped like a cancel before the link closes
                await pilot.press("s")
                await confirm(pilot)
                await wait_for(pilot, lambda s: s.job_id == 4 and s.job.segments_done > 20, 120)
                await pilot.press("ctrl+q")
                await confirm(pilot, contains="Stop it (like a cancel")
                for _ in range(1200):
                    if not app.is_running and not backend.connected():
                        break
                    await asyncio.sleep(0.05)
                assert not app.is_running and not backend.connected()  # the link closed last
                time.sleep(3.0)  # longer than the device's watchdog: it must not fire
                with contextlib.closing(open_link(second_port, 250000, 2.0)) as link:
                    st = link.request_status()
                assert not st.faulted and not st.busy, st
                assert st.hotend_target_c == 0 and st.bed_target_c == 0
    last = json.loads((app.job_history.path).read_text().splitlines()[-1])
    assert last["status"] == "cancelled" and last["reason"] == "cancelled: quit"
    assert last["resume_at"]  # the resume point it saved
