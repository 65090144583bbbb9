"""Snapshot tests of every screen at 80x24, 120x40 and 200x60 (fake backend, fixed clocks, UTC).

Update after an intended change with ``pytest tests/tui/test_snapshots.py
--snapshot-update`` and review the SVGs under ``__snapshots__``.
"""

from __future__ import annotations

import inspect
import threading
import time

import pytest
from textual.widgets import Input

from cdprhost.tui.control.views import ConsoleLine, JobRecord

from .conftest import make_app, pick_file, wait_for
from .fakes import FakeBackend
from .parts import small_part

SIZES = pytest.mark.parametrize(
    "size", [(80, 24), (120, 40), (200, 60)], ids=["80x24", "120x40", "200x60"]
)
WALL = 1_750_000_000.0  # 2025-06-15 15:06:40 UTC


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    """A temporary working folder (paths on screen are the same every time), UTC clocks."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("TZ", "UTC")
    time.tzset()
    (tmp_path / "part.gcode").write_text(small_part(layers=6))
    (tmp_path / "bad.gcode").write_text("".join(f"G1 X{i} ; line {i + 1}\n" for i in range(30)))
    yield tmp_path
    monkeypatch.undo()
    time.tzset()


@pytest.fixture
def snap_compare(snap_compare):
    """The plugin's ``snap_compare``, with every text field's cursor held steady before the
    picture: a blinking cursor is a clock on screen (shown or not by whether half a second
    passed since the last key, as it may under load: a console snapshot failed so once)."""

    def compare(app, *, run_before=None, **kw):
        async def steady(pilot):
            if run_before is not None:
                result = run_before(pilot)
                if inspect.isawaitable(result):
                    await result
            for field in pilot.app.screen.query(Input):
                field.cursor_blink = False  # the cursor stays as it is just after a key

        return snap_compare(app, run_before=steady, **kw)

    return compare


def app_for(backend, workdir):
    return make_app(
        backend, clock=lambda: 100.0, wall_clock=lambda: WALL, state_folder=workdir / "state"
    )


async def connected(pilot):
    await wait_for(pilot, lambda s: s.connected)
    pilot.app.controller.refresh_device()
    await wait_for(pilot, lambda s: s.device is not None)


def open_and_wait(name):
    async def run_before(pilot):
        await connected(pilot)
        await pick_file(pilot, name)
        await wait_for(pilot, lambda s: s.file.preflight is not None)
        await wait_for(pilot, lambda s: pilot.app.screen.source is not None)
        await pilot.pause(1.1)  # one tick: the time estimate

    return run_before


@SIZES
def test_print_screen_file_open(snap_compare, workdir, size):
    app = app_for(FakeBackend(), workdir)
    assert snap_compare(app, terminal_size=size, run_before=open_and_wait("part.gcode"))


@SIZES
def test_print_screen_preflight_violations(snap_compare, workdir, size):
    app = app_for(FakeBackend(), workdir)
    assert snap_compare(
        app, terminal_size=size, run_before=open_and_wait("bad.gcode"), press=["down", "enter"]
    )


@SIZES
def test_print_screen_mid_print(snap_compare, workdir, size):
    gate = threading.Semaphore(0)
    app = app_for(FakeBackend(gate=gate), workdir)

    async def run_before(pilot):
        await open_and_wait("part.gcode")(pilot)
        await pilot.press("s", "y")
        await wait_for(pilot, lambda s: s.job.state.value == "printing")
        for _ in range(14):
            gate.release()
        await wait_for(pilot, lambda s: s.job.segments_done == 14)
        await pilot.pause(1.1)

    assert snap_compare(app, terminal_size=size, run_before=run_before)
    app.controller.cancel()


@SIZES
def test_print_screen_failure_dialog(snap_compare, workdir, size):
    app = app_for(FakeBackend(fail_at=12), workdir)

    async def run_before(pilot):
        await open_and_wait("part.gcode")(pilot)
        await pilot.press("s", "y")
        await wait_for(pilot, lambda s: s.job.state.value == "failed")

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@SIZES
def test_help_screen(snap_compare, workdir, size):
    app = app_for(FakeBackend(), workdir)

    async def run_before(pilot):
        await connected(pilot)
        pilot.app.screen.set_focus(None)
        await pilot.press("question_mark")

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@SIZES
def test_file_picker(snap_compare, workdir, size):
    app = app_for(FakeBackend(), workdir)

    async def run_before(pilot):
        await open_and_wait("bad.gcode")(pilot)
        await open_and_wait("part.gcode")(pilot)
        await pilot.press("o")
        await pilot.pause(0.3)

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@SIZES
def test_connection_screen(snap_compare, workdir, size):
    app = app_for(FakeBackend(), workdir)

    async def run_before(pilot):
        await connected(pilot)
        await pilot.press("f1")
        await wait_for(pilot, lambda s: pilot.app.screen.query_one("#port-list").option_count == 2)

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@SIZES
def test_jog_screen_infeasible_target(snap_compare, workdir, size):
    app = app_for(FakeBackend(), workdir)

    async def run_before(pilot):
        await connected(pilot)
        await pilot.press("f3", "3", "left", "pageup")

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@SIZES
def test_calibrate_screen_results(snap_compare, workdir, size):
    app = app_for(FakeBackend(), workdir)

    async def run_before(pilot):
        await connected(pilot)
        await pilot.press("f4", "n")
        await wait_for(pilot, lambda s: s.calibration.stage == "planned")
        for k in range(1, 5):
            await pilot.press("m")
            await wait_for(pilot, lambda s, k=k: s.calibration.poses[k - 1].status == "settled")
            pilot.app.controller.ingest_take(f"takes/{k}.csv")
            await wait_for(pilot, lambda s, k=k: s.calibration.poses[k - 1].status == "take ok")
        await pilot.press("i")
        await wait_for(pilot, lambda s: s.calibration.stage == "done")

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@SIZES
def test_diagnose_screen_result(snap_compare, workdir, size):
    app = app_for(FakeBackend(), workdir)

    async def run_before(pilot):
        await pilot.press("f5")
        pilot.app.controller.diagnose("session")
        await wait_for(pilot, lambda s: s.diagnose.result is not None)

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@SIZES
def test_console_screen(snap_compare, workdir, size):
    backend = FakeBackend()
    backend.log.append(ConsoleLine("error", "device error HEATER_RUNAWAY: hotend", WALL))
    app = app_for(backend, workdir)

    async def run_before(pilot):
        await connected(pilot)
        await pilot.press("f6", *"M105", "enter")
        await wait_for(pilot, lambda s: any(c.kind == "reply" for c in s.console))
        await pilot.press(*"G4", "enter")
        await wait_for(pilot, lambda s: s.console[-1].text.startswith("G4 is not"))
        # the state holds the line before the screen has written it (a loaded machine)
        await wait_for(pilot, lambda s: pilot.app.screen.last_written is s.console[-1])
        await pilot.pause()

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@SIZES
def test_history_screen(snap_compare, workdir, size):
    from cdprhost.tui.control.store import JobHistory

    history = JobHistory(workdir / "state" / "history.jsonl")
    for k, (status, reason) in enumerate(
        [("done", ""), ("failed", "device reset (boot id changed)"), ("cancelled", "cancelled")]
    ):
        history.append(
            JobRecord(
                str(workdir / "part.gcode"),
                status,
                WALL - 7200 + 1800 * k,
                WALL - 7200 + 1800 * k + 1500,
                6 if status == "done" else 3,
                6,
                reason,
                3 if k == 2 else None,
            )
        )
    app = app_for(FakeBackend(), workdir)

    async def run_before(pilot):
        await connected(pilot)
        await wait_for(pilot, lambda s: len(s.history) == 3)
        await pilot.press("f7")

    assert snap_compare(app, terminal_size=size, run_before=run_before)
