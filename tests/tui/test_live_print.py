"""A whole print on the embedded simulated device through the UI (the real print job).

Start, pause, resume, finish; and the error path: a device reset mid-print shows
where it stopped and the resume point.
"""

from __future__ import annotations

import pytest

pytest.importorskip("cdprhost.job.runner", reason="the print runner has not landed yet")


from cdprhost.job.resume import resume_path_for
from cdprhost.job.state import JobState
from cdprhost.tui.control.live import LiveBackend
from cdprhost.tui.screens.dialogs import ConfirmScreen, FailureScreen

from .conftest import make_app, shown, wait_for


def small_part(layers: int = 10, side: float = 30.0) -> str:
    """A square tube of 0.2 mm layers with slicer layer annotations; each layer ends with a
    retraction, so the motion comes to rest there (where a pause takes effect)."""
    out = [
        "; generated for the UI tests",
        "G21",
        "G90",
        "M82",
        "M140 S60",
        "M104 S200",
        "G28",
        "G92 E0",
    ]
    e, h = 0.0, side / 2
    corners = [(-h, -h), (h, -h), (h, h), (-h, h), (-h, -h)]
    for k in range(layers):
        z = 0.3 + 0.2 * k
        out += [
            ";LAYER_CHANGE",
            f";Z:{z:.1f}",
            f"G1 Z{z:.2f} F600",
            f"G1 X{-h:.2f} Y{-h:.2f} F6000",
            f"G1 E{e:.4f} F2400",
        ]
        for x, y in corners[1:]:
            e += side * 0.033
            out.append(f"G1 X{x:.2f} Y{y:.2f} E{e:.4f} F1800")
        out.append(f"G1 E{e - 0.8:.4f} F2400")
    out += ["M104 S0", "M140 S0", "G1 Z20 F600"]
    return "\n".join(out) + "\n"


@pytest.fixture
def part(tmp_path):
    path = tmp_path / "tube.gcode"
    path.write_text(small_part(), encoding="utf-8")
    return path


async def open_file(pilot, path):
    await pilot.press("o")
    pilot.app.screen.query_one("#file-input").value = str(path)
    await pilot.press("enter")
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
        await pilot.press(
            "r"
        )  # resume from that layer: the link is re-opened, a new job starts there
        state = await wait_for(pilot, lambda s: s.job_id == 2 and s.job.state.finished, timeout=120)
        assert state.connection.status in ("connected", "error")
        second = state.job.failure  # the simulated device resets again after 150 segments
        assert second is not None, (state.job.state, state.job.reason, state.job.segments_done)
        assert second is not None and second.last_layer >= failure.last_layer
        assert (
            second.last_line >= failure.last_line
        )  # the stopped layer is printed again from its start
