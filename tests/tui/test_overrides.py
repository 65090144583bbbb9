"""Speed and flow overrides of a running print from the print screen's keys and the console
(the real print job on the embedded simulated device)."""

from __future__ import annotations

from dataclasses import replace

from textual.widgets import Input

from cdprhost.job.state import JobSnapshot, JobState, Overrides
from cdprhost.tui.control.live import LiveBackend
from cdprhost.tui.screens.print_screen import override_line
from cdprhost.tui.state import UiState

from .conftest import make_app, pick_file, shown, wait_for
from .parts import small_part


async def _console(pilot, app, command: str) -> list[str]:
    before = len(app.state.console)
    await pilot.press("ctrl+u")
    app.screen.query_one("#console-input", Input).value = command
    await pilot.press("enter")
    await wait_for(pilot, lambda s: len(s.console) > before + 1, timeout=30, what=command)
    return [f"{c.kind}: {c.text}" for c in app.state.console[before:]]


async def test_keys_and_console_set_speed_and_flow_while_printing(tmp_path):
    part = tmp_path / "tube.gcode"
    # long enough to be printing still when the console's last request goes, on a busy PC
    part.write_text(small_part(layers=90), encoding="utf-8")
    backend = LiveBackend(
        "paper-prototype",
        speedup=10.0,
        job_options={"resume_dir": tmp_path / "resume", "log_path": tmp_path / "job.jsonl"},
    )
    app = make_app(backend)
    async with app.run_test(size=(110, 34)) as pilot:
        await wait_for(pilot, lambda s: s.connected, timeout=20)
        await pick_file(pilot, part)
        await wait_for(pilot, lambda s: s.file.preflight is not None, timeout=30)
        await pilot.press("s", "y")
        state = await wait_for(
            pilot, lambda s: s.job.state is JobState.PRINTING or s.job.state.finished, timeout=60
        )
        assert state.job.state is JobState.PRINTING, state.job.reason
        assert "speed 100 %" not in await shown(pilot)  # no row while both are 100 %
        await pilot.press("plus", "plus", "greater_than_sign")
        state = await wait_for(
            pilot,
            lambda s: s.job.overrides.speed_pct == 120 and s.job.overrides.flow_pct == 105,
            timeout=30,
            what="the keys' overrides applied",
        )
        assert state.job.overrides.time_ratio < 1.0  # the time left follows
        assert "speed 120 % · flow 105 %" in await shown(pilot)
        await pilot.press("minus")
        await wait_for(pilot, lambda s: s.job.overrides.speed_pct == 110, timeout=30)
        # the console: the same requests, and a clear refusal out of range
        await pilot.press("f6")
        out = await _console(pilot, app, "M221 S95")
        assert any(t.startswith("reply: ok flow 95 %") for t in out), out
        out = await _console(pilot, app, "M220 S0")
        assert any("out of range" in t for t in out), out
        out = await _console(pilot, app, "M220 S9999")
        assert any("out of range" in t for t in out), out
        await wait_for(pilot, lambda s: s.job.overrides.flow_pct == 95, timeout=30)
        assert app.state.job.overrides.speed_pct == 110  # the refusals changed nothing
        await pilot.press("f2", "x", "y")
        await wait_for(pilot, lambda s: s.job.state.finished, timeout=60)


def test_the_override_line_shows_only_while_a_print_runs_with_an_override():
    assert override_line(UiState()).plain == ""
    printing = replace(UiState(), job=JobSnapshot(state=JobState.PRINTING))
    assert override_line(printing).plain == ""  # both 100 %
    faster = replace(printing, job=replace(printing.job, overrides=Overrides(150.0, 100.0, 0.7)))
    text = override_line(faster).plain
    assert "speed 150 % · flow 100 %" in text and "+/- speed" in text
