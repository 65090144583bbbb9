"""The event hub without a server: a state change is published at once, progress and
temperatures at most every THROTTLE_S; an unchanged printer publishes nothing; an ended job
goes to the history once."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from cdprhost.job.state import JobSnapshot, JobState, Temperatures
from cdprhost.server.printer import PrinterStatus
from cdprhost.server.web import IDLE_TEMPS_S, THROTTLE_S, Hub


class FakePrinter:
    def __init__(self) -> None:
        self.now = PrinterStatus()

    def status(self) -> PrinterStatus:
        return self.now


def test_state_changes_go_at_once_progress_is_throttled_and_nothing_repeats():
    printer = FakePrinter()
    hub = Hub(printer, lambda p: p.name if p else None)  # type: ignore[arg-type]
    t = 100.0
    assert hub.sample(t) and hub.version == 1  # the first look
    assert not hub.sample(t + 0.1)  # nothing changed: nothing sent
    job = JobSnapshot(state=JobState.PRINTING, layers=5, estimated_time_s=100.0)
    printer.now = PrinterStatus(file=Path("/u/part.gcode"), job=job, started_at=1.0)
    assert hub.sample(t + 0.2) and hub.version == 2  # a state change: at once
    printer.now = replace(printer.now, job=replace(job, device_time_s=1.0, layer=1))
    assert not hub.sample(t + 0.3)  # progress within THROTTLE_S of the last: held back
    assert hub.sample(t + 0.2 + THROTTLE_S) and hub.version == 3  # ... and sent then
    assert b'"layer":1' in hub.data
    printer.now = replace(printer.now, job=replace(printer.now.job, state=JobState.PAUSED))
    assert hub.sample(t + 0.2 + THROTTLE_S + 0.01) and hub.version == 4  # urgent again


def test_an_ended_job_goes_to_the_history_once():
    printer = FakePrinter()
    hub = Hub(printer, lambda p: p.name if p else None)  # type: ignore[arg-type]
    job = JobSnapshot(state=JobState.PRINTING, layers=5)
    printer.now = PrinterStatus(file=Path("/u/part.gcode"), job=job, started_at=1.0)
    hub.sample(0.0)
    printer.now = replace(
        printer.now, job=replace(job, state=JobState.CANCELLED, reason="cancel"), ended_at=9.0
    )
    hub.sample(1.0)
    hub.sample(2.0)
    printer.now = replace(printer.now, job=replace(printer.now.job, notices=("x",)))
    hub.sample(3.0)
    assert [h["result"] for h in hub.history] == ["cancelled"]
    assert hub.history[0]["file"] == "part.gcode" and hub.history[0]["reason"] == "cancel"


class HeatedPrinter(FakePrinter):
    def __init__(self) -> None:
        super().__init__()
        self.asked = 0
        self.reading = Temperatures(150.0, 50.0, 0.0, 0.0)

    def temperatures(self) -> Temperatures:
        self.asked += 1
        return self.reading


def test_with_no_job_the_page_sees_the_heaters_cool():
    printer = HeatedPrinter()
    hub = Hub(printer, lambda p: p.name if p else None)  # type: ignore[arg-type]
    hub.poll_temperatures(10.0)
    assert hub.sample(10.0) and hub.doc is not None
    assert hub.doc["temps"]["hotend"] == 150.0
    printer.reading = Temperatures(120.0, 45.0, 0.0, 0.0)
    hub.poll_temperatures(10.5)  # asked at most every IDLE_TEMPS_S
    assert printer.asked == 1
    hub.poll_temperatures(10.0 + IDLE_TEMPS_S)
    hub.sample(10.0 + IDLE_TEMPS_S)
    assert printer.asked == 2 and hub.doc["temps"]["hotend"] == 120.0
    # a running job's own readings are shown, and the printer is not asked
    job = JobSnapshot(state=JobState.PRINTING, temperatures=Temperatures(200.0, 60.0, 200, 60))
    printer.now = PrinterStatus(file=Path("/u/part.gcode"), job=job, started_at=1.0)
    hub.poll_temperatures(20.0)
    hub.sample(20.0)
    assert printer.asked == 2 and hub.doc["temps"]["hotend"] == 200.0
