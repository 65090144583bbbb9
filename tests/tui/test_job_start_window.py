"""The moment between pressing start and the job's first event (the runner starts in a
worker): the UI already holds a running job. Once, a status poll in that window put the
device's pre-print status (not homed, steps 0) on the screen, where it stayed through the
print and passed for the parked position after a cancel (seen on a busy CI machine)."""

from __future__ import annotations

import threading

from cdprhost.job.state import JobState

from .conftest import make_app, pick_file, wait_for
from .fakes import FakeBackend


class SlowStartBackend(FakeBackend):
    """The job's worker is held before the job exists (a busy PC, a slow file to open)."""

    def __init__(self, **kw):
        super().__init__(**kw)
        self.go = threading.Event()
        self.status_asks = 0

    def device_status(self):
        self.status_asks += 1
        return super().device_status()

    def make_job(self, *args, **kw):
        self.go.wait(10.0)
        return super().make_job(*args, **kw)


async def test_a_started_print_is_active_before_its_first_event(gcode_file):
    backend = SlowStartBackend(segments=5, layers=1)
    app = make_app(backend, status_interval_s=0.05)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda s: s.connected and s.device is not None, what="a status")
        await pick_file(pilot, gcode_file)
        await wait_for(pilot, lambda s: s.file.preflight is not None, what="preflight")
        await pilot.press("s", "y")
        await wait_for(pilot, lambda s: s.job_id == 1, what="the start")
        assert app.state.job_active and app.state.job.state is JobState.PREFLIGHT
        assert app.state.device is None  # the device as it was before the print is gone
        asks = backend.status_asks
        await pilot.pause(0.4)  # eight poll periods with the job's worker held
        assert backend.status_asks == asks and app.state.device is None
        backend.go.set()
        state = await wait_for(pilot, lambda s: s.job.state is JobState.DONE, what="done")
        assert state.history[0].status == "done"
        await wait_for(pilot, lambda s: s.device is not None, what="the device read again")
