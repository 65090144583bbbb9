"""Pause and resume through a real pty at 1x (the link's watermarks in real time): the stop
lands within the motion sent, the print resumes at the exact steps and completes with the
same program segments as an uninterrupted print."""

from __future__ import annotations

import sys
import threading

import pytest

from cdprhost.job.runner import PrintJob, PrintOptions
from cdprhost.job.state import JobState, StateChanged
from cdprhost.link import open_link
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded
from tests.e2e.processes import SimDeviceProcess, square_part

pytestmark = [
    pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux"),
    pytest.mark.timeout(300),
]


def test_pause_and_resume_on_a_pty_at_1x_continue_exactly(tmp_path):
    gcode = square_part(tmp_path / "part.gcode", layers=1)
    profile = load_profile("paper-prototype")
    clean = {}

    def embedded():
        clean["link"] = open_embedded()
        return clean["link"]

    options = PrintOptions(resume_dir=tmp_path / "resume")
    assert PrintJob(gcode, profile, embedded, options).run().status == "completed"
    expected = [r["steps"] for r in clean["link"].device.record]
    marks: dict[str, object] = {}
    with SimDeviceProcess(tmp_path, "--speedup", "1") as dev:

        def on_event(e):
            if not isinstance(e, StateChanged):
                return
            if e.state is JobState.PRINTING and "asked" not in marks:
                marks["asked"] = True
                threading.Timer(4.0, job.request_pause).start()  # mid-layer
            if e.state is JobState.PAUSED:
                marks["stop"] = job.last_stop
                threading.Timer(0.5, job.request_resume).start()
            if e.state is JobState.PRINTING and "stop" in marks and "resumed" not in marks:
                marks["resumed"] = job.link.segments_sent

        job = PrintJob(gcode, profile, lambda: open_link(dev.path), options, on_event=on_event)
        result = job.run()
        job.link.close()
        dev.stop()  # the record is complete once the device has exited
        records = dev.records()
    assert result.status == "completed", result.reason
    stop = marks["stop"]
    assert stop.line > 0  # stopped in the program, not before it
    got = [
        r["steps"]
        for r in records
        if "error" not in r and not stop.first_segment <= r["seq"] <= marks["resumed"]
    ]
    assert got == expected
