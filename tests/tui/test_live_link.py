"""The link screen and the console on real devices: a ``cdprhost sim-device`` on a
pseudo-terminal (listed, or typed), a pyserial URL, the embedded simulator (named)."""

from __future__ import annotations

import sys

import pytest
from textual.widgets import Input, OptionList

from cdprhost.tui.control.backend import EMBEDDED
from cdprhost.tui.control.live import LiveBackend

from .conftest import make_app, shown, sim_device, wait_for

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux")


async def type_port(pilot, port: str) -> None:
    await pilot.press("t")
    field = pilot.app.screen.query_one("#port-input", Input)
    assert field.has_focus
    field.value = port
    await pilot.press("enter")


async def test_link_screen_lists_the_pty_device_and_takes_a_typed_port():
    with sim_device("--speedup", "5") as (pty, _):
        backend = LiveBackend("paper-prototype", speedup=None)
        app = make_app(backend, connect_on_start=False)
        async with app.run_test(size=(100, 32)) as pilot:
            await pilot.press("f1")
            screen = app.screen
            await wait_for(pilot, lambda s: any(c.port == pty for c in screen.choices), timeout=20)
            choice = next(c for c in screen.choices if c.port == pty)
            assert choice.simulated and "sim-device" in choice.detail
            assert screen.choices[0].port == EMBEDDED and screen.choices[0].simulated
            text = await shown(pilot)
            assert "embedded simulated device" in text
            # other pty devices on this machine may push ours below the fold: highlight it
            options = screen.query_one("#port-list", OptionList)
            options.highlighted = screen.choices.index(choice)
            await pilot.pause(0.2)
            assert f"{pty}  simulated device" in await shown(pilot)
            # a pyserial URL that answers nothing: a clear error, no traceback
            await type_port(pilot, "loop://")
            state = await wait_for(pilot, lambda s: s.connection.status == "error", timeout=30)
            assert state.connection.port == "loop://" and "Traceback" not in await shown(pilot)
            # the pty device, typed
            await type_port(pilot, pty)
            state = await wait_for(pilot, lambda s: s.connected, timeout=30)
            assert not state.connection.simulated and state.connection.port == pty
            assert dict(state.connection.identity)["port"] == pty
            text = await shown(pilot)
            assert "SIMULATOR" not in text and f"{pty} @ 250000 baud" in text
            # the embedded simulator, picked from the list, says so
            options.focus()
            options.highlighted = 0
            await pilot.press("c")
            state = await wait_for(
                pilot, lambda s: s.connected and s.connection.port == EMBEDDED, timeout=30
            )
            assert state.connection.simulated
            text = await shown(pilot)
            assert "SIMULATOR: no machine moves" in text and "SIMULATOR" in text.splitlines()[0]


async def test_console_on_the_embedded_device():
    backend = LiveBackend("paper-prototype", speedup=None)
    app = make_app(backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected, timeout=20)
        await pilot.press("f6")

        async def send(command: str) -> list[str]:
            before = len(app.state.console)
            await pilot.press("ctrl+u")
            app.screen.query_one("#console-input", Input).value = command
            await pilot.press("enter")
            await wait_for(
                pilot,
                lambda s: not s.busy and len(s.console) > before + 1,
                timeout=60,
                what=command,
            )
            await pilot.pause(0.05)
            return [f"{c.kind}: {c.text}" for c in app.state.console[before:]]

        assert any("not homed" in t for t in await send("G1 X10"))
        assert any("ok homed" in t for t in await send("G28"))
        out = await send("G1 X10 Y5 Z150")
        assert any("X10.00 Y5.00 Z150.00" in t for t in out), out
        assert any("X10.00 Y5.00 Z150.00" in t for t in await send("M114"))
        out = await send("G1 Z900")
        assert any(t.startswith("error: refused, nothing moved") for t in out), out
        await send("M104 S50")
        assert any("hotend" in t and "/ 50.0" in t for t in await send("M105"))
        out = await send("M220 S50")
        assert any("no print is running" in t for t in out)
        out = await send("M112")
        assert any("emergency stop" in t for t in out), out
        out = await send("M999")
        assert any("ok cleared" in t for t in out), out
        assert any("ok homed" in t for t in await send("G28"))
        assert "G28" in await shown(pilot)
