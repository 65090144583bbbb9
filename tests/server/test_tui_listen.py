"""`cdprhost tui --listen`: the server inside the terminal UI (real app, real print job on the
embedded simulated device, real HTTP over loopback). An upload lands in the recent files; a
print=true upload becomes the TUI's own print and the console says who started it; refusals
change nothing; cancel over HTTP goes through the TUI's controller."""

from __future__ import annotations

import asyncio
import json
from typing import Any

from cdprhost.job.state import JobState
from cdprhost.server.apikey import KeyFile
from cdprhost.server.app import create_app
from cdprhost.server.listen import ServerThread
from cdprhost.server.uploads import UploadFolder
from cdprhost.tui.control.live import LiveBackend
from cdprhost.tui.control.upload_bridge import TuiPrinter
from tests.server.conftest import OUTSIDE, Server, multipart, small_part
from tests.tui.conftest import make_app, wait_for


def test_uploads_inside_the_tui(tmp_path, config_home):
    backend = LiveBackend(
        "paper-prototype",
        speedup=10.0,
        job_options={"resume_dir": tmp_path / "resume", "log_path": tmp_path / "job.jsonl"},
    )
    app = make_app(backend)
    bridge = TuiPrinter(app)
    keys = KeyFile()
    uploads = UploadFolder(tmp_path / "uploads")
    thread = ServerThread(
        create_app(bridge, uploads, keys.current, max_upload_bytes=1_000_000), "127.0.0.1", 0
    )
    thread.start()
    server = Server(thread.url, thread.port, keys.key, uploads.root, None, thread)  # type: ignore[arg-type]

    def upload(name: str, text: str, start: bool = True):
        body, ctype = multipart([("print", "true" if start else "false")], (name, text.encode()))
        return server.request("POST", "/api/files/local", body, {"Content-Type": ctype})

    async def scenario() -> None:
        async with app.run_test(size=(120, 40)) as pilot:
            await wait_for(pilot, lambda s: s.connected, timeout=30)
            refused = await asyncio.to_thread(upload, "outside.gcode", OUTSIDE)
            assert refused.status == 409 and "preflight" in refused.json()["error"]
            assert server.stored() == [] and app.state.job_id == 0

            both = await asyncio.gather(  # at once: one starts, the other is refused
                asyncio.to_thread(upload, "cup.gcode", small_part(40)),
                asyncio.to_thread(upload, "mug.gcode", small_part(40)),
            )
            assert sorted(r.status for r in both) == [201, 409], both
            winner = "cup" if both[0].status == 201 else "mug"
            assert server.stored() == [f"{winner}.gcode"]  # the refused one was not kept
            state = await wait_for(
                pilot, lambda s: s.job.state is JobState.PRINTING, timeout=60, what="printing"
            )
            path = str(uploads.root / f"{winner}.gcode")
            assert state.job_path == path and path in state.recent
            said = " ".join(line.text for line in state.console)
            assert f"upload API: print of {winner}.gcode started by 127.0.0.1" in said

            busy = await asyncio.to_thread(upload, "two.gcode", small_part())
            assert busy.status == 409 and "busy" in busy.json()["error"]
            assert "two.gcode" not in server.stored()
            job = (await asyncio.to_thread(server.request, "GET", "/api/job")).json()
            assert job["state"] == "Printing" and job["job"]["user"].startswith("127.0.0.1")

            body = json.dumps({"command": "cancel"}).encode()
            headers = {"Content-Type": "application/json"}
            cancel = await asyncio.to_thread(server.request, "POST", "/api/job", body, headers)
            assert cancel.status == 204
            state = await wait_for(pilot, lambda s: s.job.state.finished, timeout=60)
            assert state.job.state is JobState.CANCELLED, state.job.reason

    try:
        asyncio.run(scenario())
    finally:
        thread.stop()


def test_markup_in_a_client_user_agent_is_shown_as_text(tmp_path, config_home):
    """A User-Agent (or a file name) is the client's text: ``[/]`` in it is shown as it is,
    and the TUI (and the server inside it) keeps running."""
    backend = LiveBackend(
        "paper-prototype",
        speedup=10.0,
        job_options={"resume_dir": tmp_path / "resume", "log_path": tmp_path / "job.jsonl"},
    )
    app = make_app(backend)
    keys = KeyFile()
    uploads = UploadFolder(tmp_path / "uploads")
    thread = ServerThread(
        create_app(TuiPrinter(app), uploads, keys.current, max_upload_bytes=1_000_000),
        "127.0.0.1",
        0,
    )
    thread.start()
    server = Server(thread.url, thread.port, keys.key, uploads.root, None, thread)  # type: ignore[arg-type]
    agent = "PrusaSlicer [/]"  # the issue's: an unmatched closing tag

    def upload(name: str) -> Any:
        body, ctype = multipart([("print", "true")], (name, small_part(40).encode()))
        headers = {"Content-Type": ctype, "User-Agent": agent}
        return server.request("POST", "/api/files/local", body, headers)

    async def scenario() -> None:
        async with app.run_test(size=(120, 40), notifications=True) as pilot:
            await wait_for(pilot, lambda s: s.connected, timeout=30)
            reply = await asyncio.to_thread(upload, "cup.gcode")
            assert reply.status == 201, reply
            await wait_for(
                pilot, lambda s: s.job.state is JobState.PRINTING, timeout=60, what="printing"
            )
            for _ in range(5):  # the notifications are drawn
                await pilot.pause(0.1)
            assert app.is_running
            said = " ".join(line.text for line in app.state.console)
            assert f"print of cup.gcode started by 127.0.0.1 ({agent})" in said
            body = json.dumps({"command": "cancel"}).encode()
            headers = {"Content-Type": "application/json"}
            cancel = await asyncio.to_thread(server.request, "POST", "/api/job", body, headers)
            assert cancel.status == 204  # the server still answers
            await wait_for(pilot, lambda s: s.job.state.finished, timeout=60)

    try:
        asyncio.run(scenario())
    finally:
        thread.stop()
