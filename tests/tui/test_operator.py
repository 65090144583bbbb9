"""What an operator at the machine relies on (fake backend): the state shown at once when a
pause or cancel waits for a rest point, stale temperatures, help generated from the keys,
inputs that keep their letters, screenshots, the file picker, console, history, park on
cancel, the time estimate."""

from __future__ import annotations

import threading

import pytest
from textual.widgets import DataTable, Input

from cdprhost.job.state import JobState
from cdprhost.tui.keys import key_rows
from cdprhost.tui.screens.dialogs import ConfirmScreen
from cdprhost.tui.screens.file_picker import FilePickerScreen
from cdprhost.tui.screens.help import HelpScreen
from cdprhost.tui.tabs import TABS
from cdprhost.tui.widgets.temperature_graph import TemperatureGraph

from .conftest import make_app, pick_file, shown, wait_for
from .fakes import FakeBackend


class FakeClock:
    def __init__(self, t: float = 1000.0):
        self.t = t

    def __call__(self) -> float:
        return self.t


async def start_print(pilot, path) -> None:
    await wait_for(pilot, lambda s: s.connected, what="connected")
    await pick_file(pilot, path)
    await wait_for(pilot, lambda s: s.file.preflight is not None, what="preflight")
    await pilot.press("s", "y")
    await wait_for(pilot, lambda s: s.job.state is JobState.PRINTING, what="printing")


async def test_pause_and_cancel_show_at_once_while_the_motion_runs_to_rest(gcode_file):
    """The job takes a pause or cancel only where the motion comes to rest (here every 10
    segments); until then the screen must say PAUSING / CANCELLING, not look frozen."""
    gate = threading.Semaphore(0)
    app = make_app(FakeBackend(gate=gate, segments=40, rest_every=10))
    async with app.run_test(size=(80, 24)) as pilot:
        await start_print(pilot, gcode_file)
        for _ in range(3):
            gate.release()
        await wait_for(pilot, lambda s: s.job.segments_done == 3, what="3 segments")
        await pilot.press("p")
        text = await shown(pilot)
        assert app.state.job.state is JobState.PRINTING  # the job has not taken it yet
        assert "PAUSING  stopping within the moves sent" in text
        assert "pausing" in text.splitlines()[0]  # the tab bar says it too
        assert not app.check_print_action("pause_print")  # no second pause
        for _ in range(7):  # run to the rest point
            gate.release()
        await wait_for(pilot, lambda s: s.job.state is JobState.PAUSED, what="paused")
        assert app.state.job_request == "" and "PAUSED" in await shown(pilot)
        await pilot.press("r", "y")
        await wait_for(pilot, lambda s: s.job.state is JobState.PRINTING, what="resumed")
        gate.release()
        await pilot.press("x", "y")
        text = await shown(pilot)
        assert "CANCELLING" in text and "cancelling" in text.splitlines()[0]
        for _ in range(12):
            gate.release()
        await wait_for(pilot, lambda s: s.job.state is JobState.CANCELLED, what="cancelled")


async def test_stale_temperatures_are_marked(gcode_file):
    clock = FakeClock()
    gate = threading.Semaphore(0)
    app = make_app(FakeBackend(gate=gate), clock=clock)
    async with app.run_test(size=(80, 24)) as pilot:
        await start_print(pilot, gcode_file)
        graph = app.screen.query_one(TemperatureGraph)
        await pilot.pause(0.2)
        assert not graph.stale and "STALE" not in await shown(pilot)
        clock.t += 12.0  # no reading for 12 s: the link may be gone
        await wait_for(pilot, lambda s: graph.stale, what="stale marking", timeout=10)
        assert "STALE 12s" in await shown(pilot)
        gate.release()  # a new reading arrives
        await wait_for(pilot, lambda s: not graph.stale, what="fresh again", timeout=10)
        app.controller.cancel()


@pytest.mark.parametrize("mode", [t.mode for t in TABS])
async def test_help_lists_the_keys_with_the_footer_labels(fake_backend, mode):
    app = make_app(fake_backend)
    async with app.run_test(size=(100, 40)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await app.switch_mode(mode)
        await pilot.pause()
        screen = app.screen
        screen.set_focus(None)  # one-letter keys reach the screen
        await pilot.pause()
        footer = (await shown(pilot)).splitlines()[-1]
        rows = key_rows(app, screen)
        await pilot.press("question_mark")
        await wait_for(pilot, lambda s: isinstance(app.screen, HelpScreen), what="help")
        text = await shown(pilot)
        for row in rows:  # every key of the screen, named as the footer names it
            assert row.keys in text and row.description in text, row
            if row.enabled and f"{row.keys} {row.description}" in footer:
                continue
        for binding in screen.BINDINGS:
            if binding.show and screen.check_action(binding.action.split("(")[0], ()):
                label = f"{app.get_key_display(binding)} {binding.description}"
                assert label in footer, (label, footer)
        assert "Everywhere" in text and "f1" in text and "Link" in text
        await pilot.press("escape")
        await wait_for(pilot, lambda s: not isinstance(app.screen, HelpScreen), what="closed")


INPUTS = {
    "connection": ("#port-input", "#baud-input"),
    "jog": ("#hotend-input", "#bed-input"),
    "calibrate": ("#fit-poses", "#session-dir", "#take-input"),
    "diagnose": ("#diag-session",),
    "console": ("#console-input",),
}


@pytest.mark.parametrize("mode", sorted(INPUTS))
async def test_typing_in_a_field_never_fires_one_letter_commands(fake_backend, mode):
    app = make_app(fake_backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await app.switch_mode(mode)
        await pilot.pause()
        screen = app.screen
        letters = [b.key for b in screen.BINDINGS if len(b.key) == 1 and b.key.isprintable()]
        letters += ["question_mark"]
        for selector in INPUTS[mode]:
            field = screen.query_one(selector, Input)
            field.value = ""
            field.focus()
            await pilot.pause()
            before = app.state
            await pilot.press(*letters)
            await pilot.pause()
            assert app.screen is screen, f"{selector}: a key opened {app.screen}"
            assert app.state.connected and app.state.busy == ""
            assert app.state.calibration == before.calibration
            typed = field.value
            if field.type == "text":
                assert typed == "".join("?" if k == "question_mark" else k for k in letters)


async def test_screenshot_without_a_downloads_folder(fake_backend, tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))  # no ~/Downloads there
    app = make_app(fake_backend, state_folder=tmp_path / "state")
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await pilot.press("ctrl+s")
        folder = tmp_path / "state" / "screenshots"
        for _ in range(100):
            if folder.is_dir() and any(folder.glob("*.svg")):
                break
            await pilot.pause(0.05)
        shots = list(folder.glob("*.svg"))
        assert len(shots) == 1 and "<svg" in shots[0].read_text()[:200]


async def test_file_picker_offers_recent_files(tmp_path):
    a, b = tmp_path / "a.gcode", tmp_path / "sub" / "b.gcode"
    b.parent.mkdir()
    for p in (a, b):
        p.write_text("G28\nG1 X1 Y1 E1 F600\n")
    app = make_app(FakeBackend(), state_folder=tmp_path / "state")
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await pick_file(pilot, a)
        await wait_for(pilot, lambda s: s.file.preflight is not None and s.recent)
        assert app.state.recent == (str(a),)
        await pick_file(pilot, b)
        await wait_for(pilot, lambda s: len(s.recent) == 2)
        assert app.state.recent == (str(b), str(a))  # newest first
        await pilot.press("o")  # the picker opens on the recent list
        await wait_for(pilot, lambda s: isinstance(app.screen, FilePickerScreen))
        text = await shown(pilot)
        assert "Recent" in text and "b.gcode" in text and "a.gcode" in text
        await pilot.press("down", "enter")  # the second recent file: a.gcode
        await wait_for(pilot, lambda s: s.file.path == str(a) and s.file.preflight is not None)
        await pilot.press("o", "ctrl+t")  # the folder tree: G-code files and folders
        await wait_for(pilot, lambda s: app.screen.query_one("#file-tree").has_focus)
        await pilot.press("escape")
        await wait_for(pilot, lambda s: not isinstance(app.screen, FilePickerScreen))
    again = make_app(FakeBackend(), state_folder=tmp_path / "state")
    async with again.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: len(s.recent) == 2, what="recent files kept")


async def test_console_answers_and_refuses_moves_while_printing(gcode_file):
    gate = threading.Semaphore(0)
    backend = FakeBackend(gate=gate)
    backend.log.append(
        __import__("cdprhost.tui.control.views", fromlist=["ConsoleLine"]).ConsoleLine(
            "error", "device error HEATER_RUNAWAY: hotend", 0.0
        )
    )
    app = make_app(backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        app.controller.refresh_device()
        await wait_for(pilot, lambda s: s.device is not None)
        await pilot.press("f6")
        field = app.screen.query_one("#console-input", Input)
        assert field.has_focus
        await pilot.press(*"M105", "enter")
        await wait_for(pilot, lambda s: any(c.kind == "reply" for c in s.console), what="reply")
        text = await shown(pilot)
        assert "> M105" in text and "hotend 25.0" in text
        assert "device error HEATER_RUNAWAY" in text  # what the device said, in red
        await pilot.press("up")  # the last command again
        assert field.value == "M105"
        await pilot.press("f2")
        await start_print(pilot, gcode_file)
        await pilot.press("f6")
        await pilot.press("ctrl+u", *"G28", "enter")
        await wait_for(pilot, lambda s: "only M105 and M114" in s.console[-1].text, what="refused")
        assert backend.sent == ["M105"]  # nothing reached the machine while printing
        await pilot.press(*"M114", "enter")
        await wait_for(
            pilot,
            lambda s: s.console[-1].text.startswith("position") or "steps" in s.console[-1].text,
        )
        app.controller.cancel()
        for _ in range(40):
            gate.release()


async def test_cancel_reads_the_device_again_and_the_job_goes_to_the_history(gcode_file, tmp_path):
    gate = threading.Semaphore(0)
    backend = FakeBackend(gate=gate)
    app = make_app(backend, state_folder=tmp_path / "state")
    async with app.run_test(size=(100, 32)) as pilot:
        await start_print(pilot, gcode_file)
        gate.release()
        await pilot.press("x", "y")
        await wait_for(pilot, lambda s: s.job.state is JobState.CANCELLED, what="cancelled")
        # the job parks itself (one safe-stop path); the UI reads the device again after it
        await wait_for(pilot, lambda s: s.device is not None and not s.busy, what="read again")
        await wait_for(pilot, lambda s: len(s.history) == 1, what="history")
        record = app.state.history[0]
        assert record.status == "cancelled" and record.file == str(gcode_file)
        await pilot.press("f7")
        table = app.screen.query_one(DataTable)
        assert table.row_count == 1 and "cancelled" in await shown(pilot)
    again = make_app(FakeBackend(), state_folder=tmp_path / "state")
    async with again.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: len(s.history) == 1, what="history kept")
        await pilot.press("f7")
        await pilot.pause()
        await pilot.press("enter")  # reopens the file on the print screen
        await wait_for(pilot, lambda s: s.file.path == str(gcode_file), what="reopened")
        assert again.current_mode == "print"


async def test_preview_follows_the_print_and_browses_layers(tmp_path):
    from .parts import small_part

    part = tmp_path / "tube.gcode"
    part.write_text(small_part(layers=4))
    gate = threading.Semaphore(0)
    app = make_app(FakeBackend(gate=gate, segments=30, layers=4))
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await pick_file(pilot, part)
        await wait_for(pilot, lambda s: s.file.preflight is not None)
        preview = app.screen.query_one("#preview")
        assert preview.shown.toolpath.layers == 4
        assert "layer 1/4" in await shown(pilot)
        await pilot.press("right_square_bracket", "right_square_bracket")
        assert preview.shown.layer == 2 and "layer 3/4" in await shown(pilot)
        await pilot.press("f")  # follow again
        await pilot.press("s", "y")
        await wait_for(pilot, lambda s: s.job.state is JobState.PRINTING)
        for _ in range(12):
            gate.release()
        await wait_for(pilot, lambda s: s.job.segments_done == 12)
        await pilot.pause(0.3)
        assert preview.shown.done_line == app.state.job.line and preview.shown.nozzle is not None
        assert "◆" in await shown(pilot)  # the nozzle
        app.controller.cancel()
        for _ in range(40):
            gate.release()


async def test_time_left_is_wall_clock_and_includes_heating(tmp_path):
    part = tmp_path / "hot.gcode"
    part.write_text("M190 S60\nM109 S200\nG28\n" + "G1 X5 Y5 E1 F600\nG1 X0 Y0 E2\n" * 5)
    gate = threading.Semaphore(0)
    backend = FakeBackend(gate=gate)
    backend.rate = 10.0  # a simulator at 10x: machine time runs 10 times faster
    clock = FakeClock()  # the shown time left counts down with this clock: the test moves it
    app = make_app(backend, clock=clock)
    async with app.run_test(size=(120, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        app.controller.refresh_device()
        await wait_for(pilot, lambda s: s.device is not None)
        await pick_file(pilot, part)
        await wait_for(pilot, lambda s: s.file.preflight is not None)
        text = await shown(pilot)
        # before the start: 60 s machine time at 10x, plus heating from 25 °C (bed, hotend)
        assert "takes ≈ 0:00:" in text and "wall-clock" in text and "heating 0:00:" in text
        await pilot.press("s", "y")
        await wait_for(pilot, lambda s: s.job.state is JobState.PRINTING)
        # The job waits at its first move (the gate). What is shown started from the first
        # estimate drawn (heating included or not, as the events were folded) and counts
        # down; two minutes on it has settled on the estimate. The next tick draws it, and
        # the temperatures read two minutes ago as stale.
        graph = app.screen.query_one(TemperatureGraph)
        clock.t += 120.0
        await wait_for(pilot, lambda s: graph.stale, what="the next tick")
        text = await shown(pilot)
        assert "left 0:00:06 wall-clock · done ≈" in text  # 60 s of machine time at 10x
        app.controller.cancel()
        for _ in range(40):
            gate.release()


async def test_the_simulator_is_named_when_connected(fake_backend):
    app = make_app(fake_backend)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        assert app.state.connection.simulated
        assert "SIM" in (await shown(pilot)).splitlines()[0]
        await pilot.press("f1")
        text = await shown(pilot)
        assert "embedded simulated device" in text and "SIMULATOR: no machine moves" in text
        assert isinstance(app.screen.query_one("#port-input", Input), Input)
        assert not isinstance(app.screen, ConfirmScreen)
