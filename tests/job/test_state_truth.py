"""State that never lies: the elapsed time stops at the end, temperatures are polled in
every state and marked when stale, a device fault is explained and not cleared unasked."""

from __future__ import annotations

from cdprhost.job.before_start import before_start
from cdprhost.job.runner import PrintJob, PrintOptions
from cdprhost.job.state import (
    STALE_S,
    Failure,
    JobSnapshot,
    JobState,
    Planned,
    Progress,
    StateChanged,
    Temperatures,
    reduce,
    temperatures_of,
)
from cdprhost.machine import Machine
from cdprhost.machine.poll import StatusPoll
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.messages import EstopFlag


def _fold(*events):
    snap = JobSnapshot()
    for e in events:
        snap = reduce(snap, e)
    return snap


def test_the_elapsed_time_stops_when_the_job_ends():
    snap = _fold(
        StateChanged(JobState.PREFLIGHT, at=1.0),
        StateChanged(JobState.HEATING, at=2.0),
        StateChanged(JobState.PRINTING, at=5.0),
        StateChanged(JobState.CANCELLING, at=9.0),
    )
    assert snap.elapsed_s(now=10.0) == 8.0  # running: up to now
    done = reduce(snap, StateChanged(JobState.CANCELLED, at=10.5))
    assert done.elapsed_s(now=100.0) == done.elapsed_s(now=1000.0) == 8.5
    assert JobSnapshot().elapsed_s(now=5.0) == 0.0


def test_a_temperature_reading_says_when_it_is_stale():
    assert not Temperatures(200.0, 60.0, 200.0, 60.0).stale
    assert Temperatures(200.0, 60.0, 200.0, 60.0, age_s=STALE_S + 0.1).stale


def test_the_poll_keeps_temperatures_fresh_with_no_job():
    link = open_embedded()
    try:
        Machine(link, load_profile("paper-prototype")).set_heaters(180.0, 0.0)
        poll = StatusPoll(link, every_s=0.2)
        seen = []
        unsubscribe = poll.subscribe(seen.append)
        for _ in range(20):
            poll.tick()
            link.poll(0.1)  # time passes on the device (anyone pumping the link)
        unsubscribe()
        poll.tick()
        assert len(seen) == 20
        last = seen[-1]
        assert last.status is not None and not last.stale
        temps = temperatures_of(last.status, last.age_s)
        assert temps.hotend_target == 180.0 and temps.hotend > seen[0].status.hotend_c
        link.emergency_stop()  # the device stops and still answers: readings stay fresh
        first = poll.tick().status
        for _ in range(5):
            link.poll(0.3, fault_ok=True)
            after = poll.tick()
        assert not after.stale and "e-stop" in after.error
        assert after.status.faulted and after.status.hotend_target_c == 0
        assert after.status.received_at > first.received_at + 1.0  # read again and again
        assert link.state == "faulted"
        link.clear_fault()
        for _ in range(3):
            poll.tick()
            link.poll(0.3)
        fresh = poll.reading()
        assert not fresh.stale and fresh.status.hotend_target_c == 0  # the device's heaters off
    finally:
        link.close()


def test_a_fault_is_explained_before_a_start_and_not_cleared_unasked(tmp_path):
    gcode = tmp_path / "part.gcode"
    gcode.write_text("G28\nG1 X5 Y5 Z1 F3000\n")
    link = open_embedded()
    try:
        link.emergency_stop(flags=EstopFlag.KEEP_MOTORS)
        in_session = before_start(link, gcode, tmp_path)
        assert in_session.fault is not None and in_session.clearable
        link.handshake()  # a new session finds the fault on the device
        check = before_start(link, gcode, tmp_path)
        assert check.fault is not None and "emergency stop" in check.fault
        assert check.clearable and "Clear it and start?" in check.question
        profile = load_profile("paper-prototype")
        options = PrintOptions(resume_dir=tmp_path, clear_fault=False)
        result = PrintJob(gcode, profile, lambda: link, options).run()
        assert result.status == "refused" and "clear it first" in result.reason
        assert link.request_status().faulted  # still there: the operator decides
        assert not link.device.record  # nothing moved
        options = PrintOptions(resume_dir=tmp_path, clear_fault=True)
        assert PrintJob(gcode, profile, lambda: link, options).run().status == "completed"
    finally:
        link.close()


def test_progress_after_a_restart_counts_from_where_the_file_restarts(tmp_path):
    snap = _fold(
        Planned(layers=10, moves=50, estimated_time_s=40.0, filament_mm=1.0, done_s=60.0),
        Progress(segments_done=5, line=100, layer=6, device_time_s=10.0),
    )
    assert snap.fraction == 0.7 and snap.eta_s == 30.0
    gcode = tmp_path / "part.gcode"
    gcode.write_text(
        "G28\nM104 S200\nM109 S200\nG92 E0\n"
        + "".join(
            f";LAYER_CHANGE\nG1 Z{0.3 * (n + 1):.1f} F3000\nG1 X20 Y0 E{n + 1} F1800\n"
            f"G1 X0 Y0 F3000\n"
            for n in range(4)
        )
    )
    planned = []
    options = PrintOptions(resume_dir=tmp_path, resume_from_layer=2)
    job = PrintJob(
        gcode, load_profile("paper-prototype"), open_embedded, options, on_event=planned.append
    )
    assert job.run().status == "completed"
    totals = next(e for e in planned if isinstance(e, Planned))
    assert totals.layers == 4 and totals.done_s > 0  # the file's layers, and the time before


def test_a_job_cancelled_before_it_moves_ends_at_once(tmp_path):
    gcode = tmp_path / "part.gcode"
    gcode.write_text("G28\nG1 X5 Y5 Z1 F3000\n")
    opened = []

    def factory():
        opened.append(True)
        return open_embedded()

    job = PrintJob(
        gcode, load_profile("paper-prototype"), factory, PrintOptions(resume_dir=tmp_path)
    )
    assert job.shutdown("quit")  # not started: nothing to wait for
    result = job.run()
    assert result.status == "cancelled" and result.reason == "quit"
    assert job.state is JobState.CANCELLED and not opened  # never connected


def _job_asked_in_its_preflight(tmp_path, ask):
    """A long file's job that calls ``ask(job)`` as its preflight starts: the job, the
    events it sent, and whether it ever opened a link."""
    gcode = tmp_path / "part.gcode"
    gcode.write_text("G28\n" + "".join(f"G1 X{i % 20} Y{i % 7} Z1 F3000\n" for i in range(2000)))
    opened, seen = [], []

    def on_event(e):
        seen.append(e)
        if isinstance(e, StateChanged) and e.state is JobState.PREFLIGHT:
            ask(job)

    job = PrintJob(
        gcode,
        load_profile("paper-prototype"),
        lambda: opened.append(True),
        PrintOptions(resume_dir=tmp_path),
        on_event=on_event,
    )
    return job, seen, opened


def test_a_cancel_during_the_preflight_ends_it_there(tmp_path):
    job, _, opened = _job_asked_in_its_preflight(tmp_path, lambda j: j.request_cancel("SIGTERM"))
    result = job.run()
    assert result.status == "cancelled" and result.reason == "SIGTERM" and not opened


def test_an_emergency_stop_during_the_preflight_ends_it_failed(tmp_path):
    """An e-stop ends a job FAILED wherever it comes: in the preflight too (the device a
    service holds is left stopped; "cancelled" would pass for a clean stop)."""
    job, seen, opened = _job_asked_in_its_preflight(tmp_path, lambda j: j.emergency_stop())
    result = job.run()
    assert result.status == "failed" and not opened
    assert result.reason == "emergency stop before anything moved"
    assert job.state is JobState.FAILED
    assert any(isinstance(e, Failure) for e in seen)
