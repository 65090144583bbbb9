"""Pause and cancel requests on a real job (embedded device): a controlled stop within the
motion sent, and an exact resume."""

from __future__ import annotations

import threading
import time

from cdprhost.job.runner import PrintJob
from cdprhost.job.state import JobState, StateChanged
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded


def _part(tmp_path, layers=6):
    lines = ["G28", "M104 S200", "M109 S200", "G92 E0", "M106 S128"]
    e = 0.0
    for n in range(layers):
        lines += [";LAYER_CHANGE", f"G1 Z{0.3 * (n + 1):.2f} F3000"]
        for x, y in [(20, 0), (20, 20), (0, 20), (0, 0)] * 3:
            e += 1.0
            lines.append(f"G1 X{x} Y{y} E{e:.3f} F1800")
            lines.append(f"M106 S{100 + n}")  # fan changes between moving segments
        lines += [f"G1 E{e - 1:.3f} F2400", f"G1 E{e:.3f}"]
    path = tmp_path / "part.gcode"
    path.write_text("\n".join(lines + ["M104 S0", "M107"]) + "\n")
    return path


def _run_with(tmp_path, on_state, speedup=None):
    """The part printed on an embedded device (virtual time as fast as the CPU allows,
    or paced to ``speedup`` times real time when a watcher thread must see a phase)."""
    profile = load_profile("paper-prototype")
    holder = {}
    job = None

    def factory():
        holder["link"] = open_embedded(speedup=speedup)
        return holder["link"]

    def on_event(e):
        if isinstance(e, StateChanged):
            on_state(job, e.state)

    job = PrintJob(_part(tmp_path), profile, factory, on_event=on_event)
    result = job.run()
    return job, result, holder["link"].device.record


def _program_steps(record, first, last):
    """Steps of the record without the segments ``first..last`` (the host's own)."""
    return [r["steps"] for r in record if not first <= r["seq"] <= last]


def test_pause_then_resume_prints_the_same_segments_around_the_stop(tmp_path):
    _, clean, clean_record = _run_with(tmp_path, lambda job, s: None)
    seen, marks = [], {}

    def on_state(job, state):
        seen.append(state)
        if state is JobState.PRINTING and JobState.HEATING in seen and "asked" not in marks:
            marks["asked"] = True
            job.request_pause()
        if state is JobState.PAUSED:
            marks["stop"] = job.last_stop
            marks["paused_at"] = job.link.segments_sent
            threading.Timer(0.05, job.request_resume).start()
        if state is JobState.PRINTING and "paused_at" in marks and "resumed_at" not in marks:
            marks["resumed_at"] = job.link.segments_sent

    _, result, record = _run_with(tmp_path, on_state)
    assert JobState.PAUSED in seen and result.status == "completed"
    stop = marks["stop"]
    # the host's own segments: the stop (deceleration, retract), the park, the way back and
    # the unretract; everything else is the program, exactly as without the pause
    inserted = (stop.first_segment, marks["resumed_at"])
    assert _program_steps(record, *inserted) == [r["steps"] for r in clean_record]
    assert record[-1]["steps"] == clean_record[-1]["steps"]


def test_cancel_stops_at_rest_with_heaters_off(tmp_path):
    _, _, full = _run_with(tmp_path, lambda job, s: None)
    seen = []

    def on_state(job, state):
        seen.append(state)
        if state is JobState.PRINTING and JobState.HEATING in seen:  # after the M109 wait
            job.request_cancel()

    job, result, record = _run_with(tmp_path, on_state)
    assert result.status == "cancelled" and result.exit_code == 1
    assert len(record) < len(full)
    if record:  # whatever ran, ran to a rest point: the last executed segment ends at rest
        assert result.segments == len(record)
    status = job.link.request_status()
    assert status.hotend_target_c == 0 and status.bed_target_c == 0


def test_cancel_while_paused_keeps_the_park_and_switches_the_heaters_off(tmp_path):
    seen, marks = [], {}

    def on_state(job, state):
        seen.append(state)
        if state is JobState.PRINTING and JobState.HEATING in seen and "asked" not in marks:
            marks["asked"] = True
            job.request_pause()
        if state is JobState.PAUSED:
            marks["parked"] = job.link.request_status().steps
            job.request_cancel()

    job, result, record = _run_with(tmp_path, on_state)
    assert result.status == "cancelled"
    assert seen[-3:] == [JobState.PAUSED, JobState.CANCELLING, JobState.CANCELLED]
    status = job.link.request_status()
    assert status.steps[:3] == marks["parked"][:3]  # no second lift: it stays parked
    assert status.hotend_target_c == 0 and status.bed_target_c == 0
    assert not status.faulted and not status.busy


def test_pause_while_heating_parks_at_once_and_resumes_with_the_wait(tmp_path):
    _, _, clean_record = _run_with(tmp_path, lambda job, s: None)
    seen, marks = [], {}

    def on_state(job, state):
        seen.append(state)
        if state is JobState.HEATING and "asked" not in marks:
            marks["asked"] = True
            job.request_pause()
        if state is JobState.PAUSED:
            marks["stop"] = job.last_stop
            marks["hotend"] = job.link.request_status().hotend_c
            threading.Timer(0.05, job.request_resume).start()
        if state is JobState.PRINTING and "stop" in marks and "resumed_at" not in marks:
            marks["resumed_at"] = job.link.segments_sent

    _, result, record = _run_with(tmp_path, on_state)
    assert result.status == "completed"
    assert marks["hotend"] < 190  # paused without waiting for the heater
    assert seen.count(JobState.HEATING) == 2  # the wait again after the resume
    inserted = (marks["stop"].first_segment, marks["resumed_at"])
    assert _program_steps(record, *inserted) == [r["steps"] for r in clean_record]


def test_cancel_during_homing_does_not_wait_for_it(tmp_path):
    """Homing crawls (2 s from where the simulated device starts, minutes on a tall machine):
    a cancel stops it at once, nothing of the program runs, heaters off."""
    marks = {}

    def cancel_once_homing(job):
        link = job.link
        while link.progress.items_done < 1:  # the G28's enable has run: homing now
            time.sleep(0.002)
        marks["asked"] = link.now()
        job.request_cancel()

    def on_state(job, state):  # in the job's thread: the watcher needs its own
        if state is JobState.PRINTING and "watcher" not in marks:
            marks["watcher"] = threading.Thread(target=cancel_once_homing, args=(job,))
            marks["watcher"].start()

    # paced: unpaced, the 2 s of homing can pass in the few ms a loaded machine keeps
    # the watcher thread from running (seen in CI), and the program starts
    job, result, record = _run_with(tmp_path, on_state, speedup=10)
    assert result.status == "cancelled"
    assert record == []  # nothing of the program moved
    status = job.link.request_status()
    assert status.homed_mask == 0  # cut short: not homed, so nothing parked
    assert status.hotend_target_c == 0 and status.bed_target_c == 0
    assert job.link.now() - marks["asked"] < 1.0  # homing alone takes 2 s here
