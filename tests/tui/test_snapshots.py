"""Snapshot tests of the main screens (fake backend, fixed sizes, no clocks).

Update after an intended change with ``pytest tests/tui --snapshot-update`` and
review the SVGs under ``__snapshots__``.
"""

from __future__ import annotations

import threading

import pytest

from .conftest import make_app, pick_file, wait_for
from .fakes import FakeBackend

BIG, SMALL = (100, 32), (80, 24)


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    """Run in a temporary folder so file paths on screen are the same every time."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "part.gcode").write_text(
        "".join(f"G1 X{i} Y{i} E{0.1 * i:.2f} ; move {i}\n" for i in range(1, 60))
    )
    (tmp_path / "bad.gcode").write_text("".join(f"G1 X{i} ; line {i + 1}\n" for i in range(30)))
    return tmp_path


def open_and_wait(name):
    async def run_before(pilot):
        await wait_for(pilot, lambda s: s.connected)
        await pick_file(pilot, name)
        await wait_for(pilot, lambda s: s.file.preflight is not None)
        await wait_for(pilot, lambda s: pilot.app.screen.source is not None)

    return run_before


@pytest.mark.parametrize("size", [BIG, SMALL], ids=["100x32", "80x24"])
def test_print_screen_preflight_violations(snap_compare, workdir, size):
    app = make_app(FakeBackend())
    assert snap_compare(
        app, terminal_size=size, run_before=open_and_wait("bad.gcode"), press=["down", "enter"]
    )


@pytest.mark.parametrize("size", [BIG, SMALL], ids=["100x32", "80x24"])
def test_print_screen_mid_print(snap_compare, workdir, size):
    gate = threading.Semaphore(0)
    app = make_app(FakeBackend(gate=gate))

    async def run_before(pilot):
        await open_and_wait("part.gcode")(pilot)
        await pilot.press("s", "y")
        await wait_for(pilot, lambda s: s.job.state.value == "printing")
        for _ in range(14):
            gate.release()
        await wait_for(pilot, lambda s: s.job.segments_done == 14)

    assert snap_compare(app, terminal_size=size, run_before=run_before)
    app.controller.cancel()


def test_print_screen_failure_dialog(snap_compare, workdir):
    app = make_app(FakeBackend(fail_at=12))

    async def run_before(pilot):
        await open_and_wait("part.gcode")(pilot)
        await pilot.press("s", "y")
        await wait_for(pilot, lambda s: s.job.state.value == "failed")

    assert snap_compare(app, terminal_size=SMALL, run_before=run_before)


def test_connection_screen(snap_compare):
    app = make_app(FakeBackend())

    async def run_before(pilot):
        await wait_for(pilot, lambda s: s.connected)
        await pilot.press("f1")
        await wait_for(pilot, lambda s: pilot.app.screen.query_one("#port-list").option_count == 2)

    assert snap_compare(app, terminal_size=SMALL, run_before=run_before)


def test_jog_screen_infeasible_target(snap_compare):
    app = make_app(FakeBackend())

    async def run_before(pilot):
        await wait_for(pilot, lambda s: s.connected)
        pilot.app.controller.refresh_device()
        await wait_for(pilot, lambda s: s.device is not None)
        await pilot.press("f3", "3", "left", "pageup")

    assert snap_compare(app, terminal_size=SMALL, run_before=run_before)


def test_calibrate_screen_results(snap_compare):
    app = make_app(FakeBackend())

    async def run_before(pilot):
        await wait_for(pilot, lambda s: s.connected)
        await pilot.press("f4", "n")
        await wait_for(pilot, lambda s: s.calibration.stage == "planned")
        for k in range(1, 5):
            await pilot.press("m")
            await wait_for(pilot, lambda s, k=k: s.calibration.poses[k - 1].status == "settled")
            pilot.app.controller.ingest_take(f"takes/{k}.csv")
            await wait_for(pilot, lambda s, k=k: s.calibration.poses[k - 1].status == "take ok")
        await pilot.press("i")
        await wait_for(pilot, lambda s: s.calibration.stage == "done")

    assert snap_compare(app, terminal_size=BIG, run_before=run_before)


def test_diagnose_screen_result(snap_compare):
    app = make_app(FakeBackend())

    async def run_before(pilot):
        await pilot.press("f5")
        pilot.app.controller.diagnose("session")
        await wait_for(pilot, lambda s: s.diagnose.result is not None)

    assert snap_compare(app, terminal_size=BIG, run_before=run_before)
