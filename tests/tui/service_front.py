"""A terminal UI in a process of its own, headless, for the tests that stop or kill it:
``python -m tests.tui.service_front PORT FILE.gcode``. It connects to PORT through the
printer service, starts FILE (s, y), prints ``printing`` once the print runs and then, at
the end, ``end <state>``."""

from __future__ import annotations

import asyncio
import sys
import tempfile
from pathlib import Path

from cdprhost.job.state import JobState
from cdprhost.tui.app import CdprApp
from cdprhost.tui.control.service_backend import ServiceBackend


async def _until(pilot, predicate, timeout: float) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not predicate(pilot.app.state):
        if loop.time() > end:
            raise SystemExit(f"timed out: {pilot.app.state.job.state}")
        await pilot.pause(0.05)


async def main(port: str, gcode: str) -> int:
    backend = ServiceBackend("paper-prototype")
    app = CdprApp(
        backend,
        port=port,
        open_file=gcode,
        status_interval_s=0,
        state_folder=Path(tempfile.mkdtemp(prefix="cdpr-front-")),
    )
    async with app.run_test(size=(100, 32)) as pilot:
        await _until(pilot, lambda s: s.connected and s.file.preflight is not None, 120)
        await pilot.press("s")
        await pilot.press("y")
        await _until(pilot, lambda s: s.job.state is JobState.PRINTING, 120)
        print("printing", flush=True)
        await _until(pilot, lambda s: s.job.state.finished, 240)
        print(f"end {app.state.job.state.value}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(asyncio.run(main(sys.argv[1], sys.argv[2])))
