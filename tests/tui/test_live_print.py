"""A whole print on the embedded simulated device through the UI (the real print job).

Start, pause, resume, finish; and the error path: a device reset mid-print shows
where it stopped and the resume point.
"""

from __future__ import annotations

import pytest

pytest.importorskip("cdprhost.job.runner", reason="the print runner has not landed yet")


from textual.widgets import Static

from cdprhost.job.resume import find_resume_point, resume_path_for
from cdprhost.job.state import JobState
from cdprhost.tui.control.live import LiveBackend
from cdprhost.tui.screens.dialogs import ConfirmScreen, FailureScreen

from .conftest import make_app, pick_file, shown, wait_for
from .parts import small_part


@pytest.fixture
def part(tmp_path):
    path = tmp_path / "tube.gcode"
    path.write_text(small_part(), encoding="utf-8")
    return path


async def open_file(pilot, path):
    await pick_file(pilot, path)
    state = await wait_for(
        pilot, lambda s: s.file.preflight is not None or s.file.error, timeout=30
    )
    assert state.file.error == "" and state.file.preflight.ok, state.file.preflight


async def test_whole_print_on_the_simulated_device_with_pause_and_resume(part, tmp_path):
    backend = LiveBackend(
        "paper-prototype",
        speedup=25.0,
        job_options={"resume_dir": tmp_path / "resume", "log_path": tmp_path / "job.jsonl"},
    )
    app = make_app(backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected, timeout=20)
        await open_file(pilot, part)
        await pilot.press("s")
        assert isinstance(app.screen, ConfirmScreen)
        await pilot.press("y")
        state = await wait_for(
            pilot, lambda s: s.job.state is JobState.PRINTING or s.job.state.finished, timeout=60
        )
        assert state.job.state is JobState.PRINTING, f"{state.job.state}: {state.job.reason}"
        await pilot.press(
            "p"
        )  # takes effect where the motion next comes to rest (a layer end here)
        state = await wait_for(
            pilot, lambda s: s.job.state in (JobState.PAUSED, JobState.DONE), timeout=60
        )
        assert state.job.state is JobState.PAUSED, "the print ended before the pause took effect"
        assert state.job.layer < 9  # paused before the last layer
        paused_at = state.job.segments_done
        await pilot.pause(0.3)
        assert app.state.job.segments_done == paused_at  # nothing moves while paused
        await pilot.press("r", "y")
        state = await wait_for(pilot, lambda s: s.job.state.finished, timeout=120)
        assert state.job.state is JobState.DONE, state.job.reason
        assert state.job.fraction == 1.0 and state.job.layers == 10
        assert state.job.segments_done > paused_at
        text = await shown(pilot)
        assert "DONE" in text and "layer 10/10" in text


async def test_device_reset_mid_print_shows_the_stop_and_resume_point(part, tmp_path):
    backend = LiveBackend(
        "paper-prototype",
        speedup=None,
        sim_options={"faults": "reset_after=150"},
        job_options={"resume_dir": tmp_path / "resume", "log_path": tmp_path / "job.jsonl"},
    )
    app = make_app(backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected, timeout=20)
        await open_file(pilot, part)
        await pilot.press("s", "y")
        state = await wait_for(pilot, lambda s: s.job.state.finished, timeout=120)
        assert state.job.state is JobState.FAILED
        failure = state.job.failure
        assert (
            failure is not None and failure.last_line is not None and failure.last_layer is not None
        )
        await pilot.pause()
        assert isinstance(app.screen, FailureScreen)
        text = await shown(pilot)
        assert f"last executed line: {failure.last_line}" in text
        assert f"--resume-from-layer {max(failure.last_layer + 1, 1)}" in text
        # keyed by the file's content hash and path
        assert failure.resume_file == str(resume_path_for(part, tmp_path / "resume"))
        await pilot.press("r")  # resume asked for: the link is checked first, and it is down
        await wait_for(pilot, lambda s: s.connection.status == "error", timeout=30)
        await pilot.pause(0.2)
        assert app.state.job_id == 1  # nothing started
        saved = resume_path_for(part, tmp_path / "resume").read_text()
        await pilot.press("f1", "c")  # reconnect: the embedded device again
        await wait_for(pilot, lambda s: s.connected, timeout=30)
        await pilot.press("f2")
        state = await wait_for(pilot, lambda s: s.file.resume is not None, timeout=30)
        resume = state.file.resume
        # the runner saved the exact last executed move: offered like the CLI's --resume
        assert resume.exact and not resume.problem
        assert resume.layer == failure.last_layer + 1 and resume.last_line == failure.last_line
        assert f"resume point line {failure.last_line} (layer {resume.layer})" in await shown(pilot)
        await pilot.press("l")
        await wait_for(pilot, lambda s: isinstance(app.screen, ConfirmScreen), timeout=30)
        text = await shown(pilot)
        assert f"at line {failure.last_line}" in text
        # the stop reason names the reset's cause (watchdog), so the question wraps on screen:
        # it is read whole from the dialog
        question = str(app.screen.query_one("#question", Static).content)
        assert f"at line {failure.last_line}" in question and "(watchdog;" in question
        assert question.endswith("Is the part still on the bed and clear?")
        assert resume_path_for(part, tmp_path / "resume").read_text() == saved
        await pilot.press("y")  # a new job continues at that line
        state = await wait_for(pilot, lambda s: s.job_id == 2 and s.job.state.finished, timeout=120)
        assert state.job_resumed_from == failure.last_layer + 1
        second = state.job.failure  # the simulated device resets again after 150 segments
        assert second is not None, (state.job.state, state.job.reason, state.job.segments_done)
        assert second.last_layer >= failure.last_layer
        assert second.last_line >= failure.last_line  # it went on from the stopped line


async def test_jog_after_a_cancelled_print_moves(tmp_path):
    """A cancelled print leaves the extruder's step counter where the print left it; the next
    jog must keep the extruder still, not try to undo the whole print's filament in one move."""
    part = tmp_path / "tall.gcode"
    part.write_text(small_part(layers=80), encoding="utf-8")
    backend = LiveBackend(
        "paper-prototype",
        speedup=20.0,
        job_options={"resume_dir": tmp_path / "resume", "log_path": tmp_path / "job.jsonl"},
    )
    app = make_app(backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected, timeout=20)
        await open_file(pilot, part)
        await pilot.press("s", "y")
        await wait_for(pilot, lambda s: s.job.segments_done > 200 or s.job.state.finished, 60)
        await pilot.press("x", "y")
        state = await wait_for(pilot, lambda s: s.job.state.finished, timeout=60)
        assert state.job.state is JobState.CANCELLED, state.job.reason
        assert state.job.steps is not None and state.job.steps[3] > 100  # filament was pushed
        stopped_z = state.job.position[2]
        # then it parks (lifted by the profile's park.lift_mm) and turns the heaters off
        state = await wait_for(
            pilot, lambda s: s.device is not None and not s.busy and s.history, timeout=60
        )
        lift = backend.profile.park.lift_mm
        assert state.device.position[2] == pytest.approx(stopped_z + lift, abs=0.05)
        assert state.device.hotend_target == 0 and state.device.bed_target == 0
        assert state.history[0].status == "cancelled"
        extruder = state.device.steps[3]  # after the stop's retract
        await pilot.press("f3", "3", "right")
        target = app.state.jog.target
        assert app.state.jog.ok, app.state.jog.reason
        await pilot.press("enter")
        state = await wait_for(pilot, lambda s: not s.busy, timeout=60)
        assert not app._notifications, [n.message for n in app._notifications]
        assert state.device.position == pytest.approx(target, abs=0.01)
        assert state.device.steps[3] == extruder  # the extruder did not move


def at_rest_after(state) -> float | None:
    """Device seconds from the stop's start to rest, from the job's notice (None: no stop)."""
    import re

    for text in state.job.notices:
        m = re.match(r"(?:cancel|pause|stop): at rest ([0-9.]+) s after the request", text)
        if m:
            return float(m.group(1))
    return None


@pytest.fixture
def tall(tmp_path):
    """Long enough that a key pressed after 100 segments lands mid-print at full speed."""
    path = tmp_path / "tall.gcode"
    path.write_text(small_part(layers=150), encoding="utf-8")
    return path


async def test_cancel_stops_within_the_buffered_motion(tall, tmp_path):
    """On the embedded device (its clock: link seconds are device seconds) the cancel key
    reaches the job at once and the machine is at rest within 2 device seconds."""
    backend = LiveBackend(
        "paper-prototype",
        speedup=5.0,  # paced: the keys land mid-print however fast the machine is
        job_options={"resume_dir": tmp_path / "resume", "log_path": tmp_path / "job.jsonl"},
    )
    app = make_app(backend, state_folder=tmp_path / "state")
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected, timeout=20)
        await open_file(pilot, tall)
        await pilot.press("s", "y")
        await wait_for(pilot, lambda s: s.job.segments_done > 30 or s.job.state.finished, 60)
        await pilot.press("x")
        await wait_for(pilot, lambda s: isinstance(app.screen, ConfirmScreen), timeout=30)
        await pilot.press("y")
        state = await wait_for(pilot, lambda s: s.job.state.finished, timeout=60)
        assert state.job.state is JobState.CANCELLED, state.job.reason
        assert any(n.startswith("cancel requested") for n in state.job.notices)
        latency = at_rest_after(state)
        assert latency is not None and latency <= 2.0, state.job.notices
        # the record is listed at once; its resume point, read from the saved file, follows
        # from a worker that runs alongside the device's new status read
        state = await wait_for(
            pilot,
            lambda s: s.history and s.history[0].resume_at and s.device is not None,
            timeout=60,
            what="the history record with its resume point, and the device read again",
        )
        point = find_resume_point(str(tall), tmp_path / "resume")
        assert point is not None and state.history[0].status == "cancelled"
        assert state.history[0].resume_at == f"line {point.last_line} (layer {point.last_layer})"
        assert state.device.hotend_target == 0 and not state.device.fault


async def test_quit_while_printing_stops_parks_and_records_before_closing(tall, tmp_path):
    """^q, y mid-print: the job stops like a cancel (heaters off, parked, resume point), goes to
    the history, and only then is the link closed: no crash, no watchdog fault."""
    backend = LiveBackend(
        "paper-prototype",
        speedup=5.0,  # paced: the keys land mid-print however fast the machine is
        job_options={"resume_dir": tmp_path / "resume", "log_path": tmp_path / "job.jsonl"},
    )
    app = make_app(backend, state_folder=tmp_path / "state")
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected, timeout=20)
        await open_file(pilot, tall)
        await pilot.press("s", "y")
        await wait_for(pilot, lambda s: s.job.segments_done > 30 or s.job.state.finished, 60)
        assert app.state.job.state.active
        device = backend.link.device
        await pilot.press("ctrl+q")
        await wait_for(pilot, lambda s: isinstance(app.screen, ConfirmScreen), timeout=30)
        await pilot.press("y")
        for _ in range(1200):
            if not app.is_running:
                break
            await pilot.pause(0.05)
    assert not app.is_running
    assert not app.problems
    status = device.status()
    assert status.hotend_target_dc == 0 and status.bed_target_dc == 0  # heaters off
    from firmware_protocol.messages import Flag

    assert not status.flags & Flag.FAULT and not status.flags & Flag.MOVING
    import json

    record = json.loads((tmp_path / "state" / "history.jsonl").read_text().splitlines()[-1])
    assert record["status"] == "cancelled" and record["reason"] == "cancelled: quit"
    point = find_resume_point(str(tall), tmp_path / "resume")
    assert point is not None and record["resume_at"].startswith(f"line {point.last_line} ")
    log = (tmp_path / "job.jsonl").read_text()
    assert "TypeError" not in log and "not open" not in log
