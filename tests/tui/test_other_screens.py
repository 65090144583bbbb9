"""Connection, jog, calibrate and diagnose screens on the fake backend; palette; 80x24."""

from __future__ import annotations

import pytest
from textual.widgets import DataTable, Input, OptionList

from cdprhost.tui.app import CdprApp
from cdprhost.tui.screens.dialogs import ConfirmScreen

from .conftest import make_app, shown, wait_for
from .fakes import FakeBackend


async def test_connection_screen_ports_errors_and_reconnect(fake_backend):
    app = make_app(fake_backend)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await pilot.press("f1")
        assert app.current_mode == "connection"
        options = app.screen.query_one("#port-list", OptionList)
        await wait_for(pilot, lambda s: options.option_count == 2, what="ports listed")
        assert "c Connect" in await shown(pilot) and "d Disconnect" in await shown(pilot)
        await pilot.press("d")
        await wait_for(pilot, lambda s: s.connection.status == "disconnected")
        options.highlighted = 1  # a port that does not answer
        await pilot.press("c")
        state = await wait_for(pilot, lambda s: s.connection.status == "error")
        assert "/dev/ttyFAKE0: no such device" in state.connection.error
        assert "no such device" in await shown(pilot)
        options.highlighted = 0
        await pilot.press("c")
        await wait_for(pilot, lambda s: s.connected)
        table = app.screen.query_one("#identity", DataTable)
        assert table.row_count == 5
        assert "cdpr-sim 0.1" in await shown(pilot)


async def test_jog_shows_feasibility_before_moving(fake_backend):
    app = make_app(fake_backend)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        app.controller.refresh_device()
        await wait_for(pilot, lambda s: s.device is not None, what="device status")
        await pilot.press("f3")
        start = app.state.device.position
        await pilot.press("3", "down")  # 10 mm steps, y-
        jog = app.state.jog
        assert jog.ok and jog.target == pytest.approx((start[0], start[1] - 10.0, start[2]))
        assert "feasible · Enter moves" in await shown(pilot)
        await pilot.press("enter")
        await wait_for(pilot, lambda s: not s.busy and s.jog is None, what="move done")
        assert fake_backend.moves == [pytest.approx(jog.target)]
        assert app.state.device.position == pytest.approx(jog.target)
        await pilot.press("4", *["pageup"] * 3)  # +150 mm in z: beyond z_max
        jog = app.state.jog
        assert not jog.ok and "NOT feasible" in await shown(pilot)
        await pilot.press("enter")  # refused: nothing moves
        await pilot.pause()
        assert len(fake_backend.moves) == 1
        await pilot.press("escape")
        assert app.state.jog is None
        await pilot.press("h")
        assert isinstance(app.screen, ConfirmScreen)
        await pilot.press("y")
        await wait_for(
            pilot, lambda s: not s.busy and s.device.position != pytest.approx(jog.target)
        )
        hotend = app.screen.query_one("#hotend-input", Input)
        hotend.value = "215"
        app.screen.query_one("#bed-input", Input).value = "60"
        await pilot.press("t")
        await wait_for(
            pilot, lambda s: s.device.hotend_target == 215.0 and not s.busy, what="heaters"
        )
        assert app.state.device.bed_target == 60.0
        hotend.value = "999"
        await pilot.press("t")  # above the profile's hotend maximum: refused
        await pilot.pause()
        assert app.state.device.hotend_target == 215.0


async def test_calibration_wizard_screen(fake_backend):
    app = make_app(fake_backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await pilot.press("f4")
        await pilot.press("n")
        state = await wait_for(pilot, lambda s: s.calibration.stage == "planned", what="planned")
        assert (
            len(state.calibration.poses) == 7
            and [p.role for p in state.calibration.poses].count("check") == 3
        )
        assert app.screen.query_one("#poses", DataTable).row_count == 7
        take_input = app.screen.query_one("#take-input", Input)
        for k in range(1, 5):
            await pilot.press("m")
            await wait_for(
                pilot,
                lambda s, k=k: (
                    s.calibration.current == k and s.calibration.poses[k - 1].status == "settled"
                ),
                what=f"pose {k} settled",
            )
            await pilot.press("k")
            take_input.value = (
                "takes/bad.csv" if k == 2 else f"takes/{k}.csv"
            )  # pose 2: first take rejected
            await pilot.press("enter")
            await wait_for(
                pilot, lambda s, k=k: s.calibration.poses[k - 1].status in ("take ok", "rejected")
            )
            if app.state.calibration.poses[k - 1].status == "rejected":
                assert "not static" in await shown(pilot)
                await pilot.press("k")  # the same pose again, with a good take
                take_input.value = f"takes/{k}b.csv"
                await pilot.press("enter")
                await wait_for(pilot, lambda s, k=k: s.calibration.poses[k - 1].status == "take ok")
        assert fake_backend.calibration.moved == [1, 2, 3, 4]
        await pilot.press("i")
        state = await wait_for(pilot, lambda s: s.calibration.stage == "done", what="identified")
        assert state.calibration.result.rms_after_mm == pytest.approx(0.051)
        assert app.screen.query_one("#parameters", DataTable).row_count == 12
        text = await shown(pilot)
        assert "14.200 → 0.0510 mm" in text and "calibrated.toml" in text


async def test_diagnose_screen(fake_backend):
    app = make_app(fake_backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await pilot.press("f5", "e")
        app.screen.query_one("#diag-session", Input).value = "/data/missing"
        await pilot.press("enter")
        state = await wait_for(pilot, lambda s: s.diagnose.error != "", what="error")
        assert "session.toml: no such file" in await shown(pilot)
        await pilot.press("e")
        app.screen.query_one("#diag-session", Input).value = "/data/session"
        await pilot.press("enter")
        state = await wait_for(pilot, lambda s: s.diagnose.result is not None, what="diagnosis")
        assert state.diagnose.result.verdict == "named"
        assert app.screen.query_one("#candidates", DataTable).row_count == 4
        text = await shown(pilot)
        assert "verdict named  effect cable_elasticity" in text
        assert "0.152 → 0.071 mm" in text and "noise floor 0.066 mm" in text
        assert "█ before" in text and "┈ noise floor" in text


async def test_command_palette_commands_follow_state(fake_backend, gcode_file):
    app = make_app(fake_backend)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        titles = [c.title for c in app.get_system_commands(app.screen)]
        assert "Screen: Jog (f3)" in titles and "Device: home" in titles
        assert "Print: start" not in titles  # no file yet
        app.controller.open_file(str(gcode_file))
        await wait_for(pilot, lambda s: s.file.preflight is not None)
        titles = [c.title for c in app.get_system_commands(app.screen)]
        assert "Print: start" in titles and "Print: pause" not in titles


@pytest.mark.parametrize("mode", ["connection", "print", "jog", "calibrate", "diagnose"])
async def test_screens_render_at_80x24_with_key_bindings(fake_backend, mode):
    app = make_app(fake_backend)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await app.switch_mode(mode)
        await pilot.pause()
        lines = (await shown(pilot)).splitlines()
        assert len(lines) == 24
        assert "F2 Print" in lines[0]  # the tab bar
        assert "^q Quit" in lines[-1] and "^p palette" in lines[-1]
        expected = {
            "connection": "c Connect",
            "print": "o Open",
            "jog": "h Home",
            "calibrate": "n Plan poses",
            "diagnose": "e Session",
        }[mode]
        assert expected in lines[-1]


async def test_quit_while_printing_cancels_the_job(gcode_file):
    import threading

    gate = threading.Semaphore(0)
    backend = FakeBackend(gate=gate)
    app: CdprApp = make_app(backend)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        app.controller.open_file(str(gcode_file))
        await wait_for(pilot, lambda s: s.file.preflight is not None)
        app.controller.start()
        await wait_for(pilot, lambda s: s.job.state.value == "printing")
        await pilot.press("ctrl+q")
        assert isinstance(app.screen, ConfirmScreen)
        await pilot.press("y")
        await pilot.pause(0.2)
    assert backend.jobs[0]._cancel.is_set()


async def test_command_palette_switches_screens(fake_backend):
    app = make_app(fake_backend)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        await pilot.press("ctrl+p")
        await pilot.pause()
        await pilot.press(*"screen: jog")
        await pilot.pause(0.3)
        await pilot.press("enter")
        await pilot.pause(0.2)
        assert app.current_mode == "jog"
