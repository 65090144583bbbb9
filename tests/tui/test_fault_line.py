"""The device's fault line wraps instead of hiding the resume offer it leads to (issue 32),
at 80 and at 120 columns."""

from __future__ import annotations

from dataclasses import replace

import pytest

from cdprhost.tui.control.views import ConsoleLine, ResumeView
from cdprhost.tui.state import FileView

from .conftest import make_app, shown, wait_for

FAULT = (
    "the device is stopped by a fault (watchdog: its host stopped answering) after segment 67245"
)


@pytest.mark.parametrize("size", [(80, 24), (120, 32)])
async def test_the_fault_line_wraps_and_keeps_the_resume_offer(fake_backend, size, tmp_path):
    app = make_app(fake_backend)
    async with app.run_test(size=size) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        path = str(tmp_path / "cup.gcode")
        resume = ResumeView(
            path + ".resume.json", path, "device watchdog", 12, last_line=48213, exact=True
        )
        fake_backend.status = replace(fake_backend.status, fault=FAULT)  # polled again
        await pilot.pause()
        app.state = replace(
            app.state,
            device=fake_backend.status,
            file=FileView(path=path, resume=resume),
        )
        text = " ".join((await shown(pilot)).split())  # the rows, joined
        assert "after segment 67245" in text
        assert "resume point line 48213" in text
        assert "(device watchdog)" in text
        assert "…" not in (await shown(pilot)).split("resume point")[0].splitlines()[-1]


async def test_a_lost_link_is_asked_again_and_recovers_saying_so(fake_backend):
    app = make_app(fake_backend)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        conn = app.state.connection
        app.state = replace(app.state, connection=replace(conn, status="error", error="silent"))
        fake_backend.log.append(
            ConsoleLine("notice", "link back: simulator answers again (new session)", 0.0)
        )
        app.controller.refresh_device()  # the status timer's turn
        state = await wait_for(pilot, lambda s: s.connected, what="the link back")
        assert any("link back" in line.text for line in state.console)


async def test_a_device_operation_on_a_lost_link_says_why_it_is_refused(fake_backend):
    app = make_app(fake_backend)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda s: s.connected)
        conn = app.state.connection
        app.state = replace(app.state, connection=replace(conn, status="error", error="silent"))
        app.controller.home()  # jog screen h
        await pilot.pause()
        said = [line.text for line in app.state.console if line.kind == "error"]
        assert said and "homing: refused, nothing sent: the link is lost (silent)" in said[-1]
