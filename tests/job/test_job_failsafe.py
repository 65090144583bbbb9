"""How a job ends when something goes wrong (embedded device, virtual time): an e-stop
first when the host gives up, complete only when the device confirms the last segment,
a job log that fills up stops safely, resume points written while printing and exact."""

from __future__ import annotations

import errno
import io
import json

import pytest

import cdprhost.job.log as job_log
from cdprhost.cli.main import main
from cdprhost.job.resume import ResumePoint, ResumeWriter, find_resume_point, resume_path_for
from cdprhost.job.runner import PrintJob, PrintOptions
from cdprhost.job.state import Progress
from cdprhost.link import LinkError
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.messages import ErrorCode
from tests.e2e.processes import square_part
from tests.service.inprocess import serve_in_thread


def run_job(path, tmp_path, *, on_link=None, options=None, on_event=None, faults=None):
    holder = {}

    def factory():
        link = open_embedded(faults=faults)
        holder["link"] = link
        if on_link:
            on_link(link)
        return link

    opts = options or PrintOptions()
    opts.resume_dir = tmp_path / "resume"
    job = PrintJob(path, load_profile("paper-prototype"), factory, opts, on_event=on_event)
    result = job.run()
    return result, holder["link"]


@pytest.fixture
def part(tmp_path):
    # 40 layers: 1-2 s of wall time on the embedded device, so the events that come by
    # wall time (progress every 0.1 s, resume saves) come many times even on a fast
    # machine (8 layers gave 3-4 progress events: too few, CI failed on it)
    return square_part(tmp_path / "part.gcode", layers=40)


def test_a_host_side_failure_ends_with_an_emergency_stop_and_an_exact_resume_point(part, tmp_path):
    calls = {"n": 0}

    def sabotage(link):
        feed = link.feed

        def failing_feed(*args, **kwargs):
            calls["n"] += 1
            if calls["n"] > 40:
                raise LinkError("simulated host failure")
            return feed(*args, **kwargs)

        link.feed = failing_feed

    result, link = run_job(part, tmp_path, on_link=sabotage)
    mc = link.device.machine
    assert result.status == "failed" and "simulated host failure" in result.reason
    assert mc.estopped and mc.last_error == ErrorCode.ESTOP  # e-stop first
    assert mc.heaters[0].target == 0 and mc.heaters[1].target == 0
    assert mc.enabled_mask  # motors kept: the effector stays where it is
    point = ResumePoint.load(result.resume_file)
    assert point.device_segment == mc.segments_done > 0  # from the device, not what was sent
    assert result.segments == mc.segments_done and result.print_time_s > 0
    assert point.exact and point.last_line == result.last_line


def test_complete_only_when_the_device_confirms_the_last_segment(part, tmp_path):
    def silent_fault(link):
        dev = link.device
        report = dev._report
        complete = dev.machine._complete

        def fail_at_300(t):
            out = complete(t)
            if dev.machine.segments_done == 300 and not dev.machine.fault:
                dev.machine.fail(ErrorCode.UNDERRUN, dev.machine.items_done, 300, t)
            return out

        dev.machine._complete = fail_at_300
        dev._report = lambda reports: report([r for r in reports if type(r).__name__ != "Error"])

    # the file goes on well past segment 300: the host must not stream on into a device
    # that discards everything (it did, and hung, until it read the FAULT flag)
    result, link = run_job(part, tmp_path, on_link=silent_fault)
    assert result.status == "failed" and "after segment 300" in result.reason, result.reason
    assert result.segments == 300


def test_a_job_log_that_fills_up_stops_at_a_rest_point_with_heaters_off(
    part, tmp_path, monkeypatch, capsys
):
    class Full(io.StringIO):
        """A disk that fills up once the print is under way."""

        progress = 0

        def write(self, text):
            Full.progress += '"Progress"' in text
            if Full.progress > 2:
                raise OSError(errno.ENOSPC, "No space left on device")
            return super().write(text)

    monkeypatch.setattr(job_log, "open", lambda *a, **k: Full(), raising=False)
    serve_in_thread(monkeypatch)  # the job runs in the printer service: here, to reach it
    report = tmp_path / "job.json"
    state = tmp_path / "state"
    monkeypatch.setenv("CDPRHOST_STATE", str(state))
    code = main(
        [
            "print",
            str(part),
            "--profile",
            "paper-prototype",
            "--log",
            str(tmp_path / "job.jsonl"),
            "--json",
            str(report),
        ]
    )
    out = capsys.readouterr()
    assert code == 1 and "Traceback" not in out.err + out.out
    result = json.loads(report.read_text())
    assert result["status"] == "failed" and "No space left on device" in result["reason"]
    assert "reason: job log" in out.out
    point = find_resume_point(part, state / "jobs")
    assert point is not None and point.exact and point.last_layer < 40


def test_the_safe_stop_lands_at_rest_with_heaters_off(part, tmp_path):
    def fill_up_later(link):
        pass

    job_holder = {}

    def on_event(event):
        job = job_holder["job"]
        if isinstance(event, Progress) and event.segments_done > 200:
            job.requests.stop_safely("job log /x: No space left on device")

    holder = {}

    def factory():
        holder["link"] = open_embedded()
        return holder["link"]

    job = PrintJob(
        part,
        load_profile("paper-prototype"),
        factory,
        PrintOptions(resume_dir=tmp_path / "resume"),
        on_event=on_event,
    )
    job_holder["job"] = job
    result = job.run()
    dev = holder["link"].device
    assert result.status == "failed" and result.reason.startswith("job log /x")
    assert dev.machine.heaters[0].target == 0 and not dev.machine.fault
    assert "error" not in dev.record[-1]  # nothing cut mid-segment
    assert dev.machine.at_rest and dev.machine.current is None
    assert result.print_time_s > 0 and result.resume_file


def test_resume_points_are_written_while_printing(part, tmp_path, monkeypatch):
    # every save is seen (sampling the file at Progress events missed layers on a busy
    # machine); how many layers the streamer sees go by still depends on timing
    seen = []
    path = resume_path_for(part, tmp_path / "resume")
    save = ResumeWriter.save

    def spy(self, point, now, layer=None):
        written = save(self, point, now, layer)
        if written:
            seen.append(ResumePoint.load(path).device_segment)
        return written

    monkeypatch.setattr(ResumeWriter, "save", spy)
    every_layer = PrintOptions(resume_every_s=3.0, resume_layer_s=0.0)
    result, link = run_job(part, tmp_path, options=every_layer)
    assert result.status == "completed"
    assert len(set(seen)) >= 3 and seen == sorted(seen)  # kept up to date as it printed
    assert not path.exists()  # completed: nothing to resume


def test_a_reset_then_resume_continues_exactly_at_the_last_executed_segment(part, tmp_path):
    clean, clean_link = run_job(part, tmp_path)
    first, link = run_job(part, tmp_path, faults="reset_after=400")
    assert first.status == "failed" and first.segments == 400
    point = ResumePoint.load(first.resume_file)
    assert point.device_segment == 400 and point.exact
    at_stop = link.device.record[399]
    resumed, link2 = run_job(part, tmp_path, options=PrintOptions(resume=point))
    assert resumed.status == "completed" and resumed.last_layer == 40
    # the approach lowers onto the end of segment 400, then the print goes on from there
    assert any(r["steps"][:3] == at_stop["steps"][:3] for r in link2.device.record)
    assert resumed.final_steps[:3] == clean.final_steps[:3]


def test_a_killed_atomic_write_leaves_no_temporary_behind_for_long(tmp_path):
    import os
    import time

    from cdprhost.fileio.atomic import write_text_atomic

    target = tmp_path / "x.resume.json"
    stale = tmp_path / ".x.resume.json.abc123.tmp"  # what a killed writer leaves
    fresh = tmp_path / ".x.resume.json.def456.tmp"  # a writer at work right now
    stale.write_text("half")
    fresh.write_text("half")
    old = time.time() - 3600
    os.utime(stale, (old, old))
    write_text_atomic(target, "{}\n")
    assert target.read_text() == "{}\n" and not stale.exists() and fresh.exists()


def test_a_bug_in_the_job_stops_like_a_cancel_not_an_e_stop(part, tmp_path, monkeypatch):
    """One safe-stop path: an unexpected exception decelerates, retracts, parks and switches
    the heaters off, with the resume point naming the last program segment executed."""
    from cdprhost.job.streamer import Streamer

    real = Streamer._segments
    calls = {"n": 0}

    def buggy(self, batch):
        calls["n"] += 1
        if calls["n"] == 30:
            raise RuntimeError("simulated bug")
        return real(self, batch)

    monkeypatch.setattr(Streamer, "_segments", buggy)
    result, link = run_job(part, tmp_path)
    mc = link.device.machine
    assert result.status == "failed" and "internal error: RuntimeError" in result.reason
    assert not mc.fault and not mc.estopped  # stopped by the host, in control
    assert mc.heaters[0].target == 0 and mc.heaters[1].target == 0
    assert "error" not in link.device.record[-1]  # nothing cut mid-segment
    point = ResumePoint.load(result.resume_file)
    assert 0 < point.device_segment < mc.segments_done  # the program's, before the stop moves
