"""M220 / M221 while printing (embedded device): the speed override shortens what is not sent
yet and the time left follows; the flow override scales the extruder's steps; both refuse a
percentage out of range; the resume point stays the program's."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.gcode.sample_parts import square_walls
from cdprhost.job.resume import ResumePoint
from cdprhost.job.runner import PrintJob, PrintOptions
from cdprhost.job.state import JobSnapshot, JobState, Overrides, Planned, Progress, reduce
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded


def _part(tmp_path, layers=8):
    path = tmp_path / "part.gcode"
    path.write_text(square_walls(layers))
    return path


def _print(tmp_path, speed=None, flow=None):
    profile = load_profile("paper-prototype")
    holder, events = {}, []

    def factory():
        holder["link"] = open_embedded()
        return holder["link"]

    job = PrintJob(_part(tmp_path), profile, factory, on_event=events.append)
    if speed is not None:
        job.request_speed(speed)
    if flow is not None:
        job.request_flow(flow)
    result = job.run()
    assert result.status == "completed", result.reason
    return result, holder["link"].device.record, events


def test_m220_s200_shortens_the_segments_not_sent_yet_and_the_eta_follows(tmp_path):
    _, clean, _ = _print(tmp_path)
    _, fast, events = _print(tmp_path, speed=200)
    # the same path: every segment ends on the same steps, only the times differ
    assert [r["steps"] for r in fast] == [r["steps"] for r in clean]
    assert fast[-1]["t"] < 0.75 * clean[-1]["t"]
    applied = [e for e in events if isinstance(e, Overrides)]
    assert applied and applied[0].speed_pct == 200 and 0.4 < applied[-1].time_ratio < 0.8
    # the time left: the planned time still to run at the override's ratio
    planned = next(e for e in events if isinstance(e, Planned))
    snap = reduce(JobSnapshot(state=JobState.PRINTING), planned)
    half = Progress(1, 1, 0, planned.estimated_time_s / 2)
    at_100 = reduce(snap, half).eta_s
    at_200 = reduce(reduce(snap, applied[-1]), half).eta_s
    assert at_200 == pytest.approx(at_100 * applied[-1].time_ratio)
    assert at_200 < 0.8 * at_100


def test_m221_scales_the_extruder_steps_and_not_the_path(tmp_path):
    _, clean, _ = _print(tmp_path)
    _, more, events = _print(tmp_path, flow=150)
    assert [r["steps"][:3] for r in more] == [r["steps"][:3] for r in clean]
    e_clean = np.array([r["steps"][3] for r in clean])
    e_more = np.array([r["steps"][3] for r in more])
    first = int(np.flatnonzero(e_clean != e_more)[0])  # where the override took over
    base_clean, base_more = e_clean[first - 1], e_more[first - 1]
    assert base_clean == base_more
    assert np.all(np.abs((e_more[first:] - base_more) - 1.5 * (e_clean[first:] - base_clean)) <= 1)
    assert any(isinstance(e, Overrides) and e.flow_pct == 150 for e in events)


@pytest.mark.parametrize("percent", [0, 9999])
def test_an_override_out_of_range_is_refused_and_changes_nothing(tmp_path, percent):
    job = PrintJob(_part(tmp_path), load_profile("paper-prototype"), open_embedded)
    with pytest.raises(ValueError, match="out of range"):
        job.request_speed(percent)
    with pytest.raises(ValueError, match="out of range"):
        job.request_flow(percent)
    assert job.overrides.factors() == (1.0, 1.0)


def test_the_resume_point_records_the_overrides_and_a_resume_says_it_starts_at_100(tmp_path):
    profile = load_profile("paper-prototype")
    part = _part(tmp_path)
    options = PrintOptions(resume_dir=tmp_path / "resume")
    job, seen = None, []

    def on_event(e):
        if isinstance(e, Overrides) and e.time_ratio != 1.0:
            seen.append(e)
        if seen and isinstance(e, Progress) and job.state is JobState.PRINTING:
            job.request_cancel()  # printing with the override in effect: stop there

    job = PrintJob(part, profile, open_embedded, options=options, on_event=on_event)
    job.request_speed(150)
    job.request_flow(90)
    stopped = job.run()
    assert stopped.status == "cancelled" and stopped.resume_file
    point = ResumePoint.load(stopped.resume_file)
    assert (point.speed_pct, point.flow_pct) == (150, 90)
    assert point.exact  # the program's place: line, point and filament position
    resumed = PrintJob(
        part,
        profile,
        open_embedded,
        options=PrintOptions(resume=point, resume_dir=tmp_path / "resume"),
    ).run()
    assert resumed.status == "completed", resumed.reason
    assert any(
        "ran at speed 150 %, flow 90 %" in n and "resumes at speed 100 %, flow 100 %" in n
        for n in resumed.notices
    ), resumed.notices
