"""Pause and cancel stop the machine within the motion already sent (issue 23), read from
the device's own record (device time at 1x on the embedded device)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cdprhost.job.resume import ResumePoint
from cdprhost.job.runner import PrintJob
from cdprhost.job.state import JobState, StateChanged
from cdprhost.kinematics.machine import MachineModel
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded
from tests.e2e.conftest import first_layers
from tests.job.stop_figures import CUP, fast_circles, peak_decel, run_with_request, speeds

LATENCY_S = 2.0  # the acceptance: at rest within 2 s of the request


def _first_layers(tmp: Path, layers: int = 3) -> Path:
    return first_layers(CUP, tmp, layers, ("M104 S0", "M140 S0"))


def _check_controlled(run, model, accel_margin=1.6):
    """Deceleration within the profile's limit, no step-rate jump, no extrusion but the
    retract once the stop began."""
    stop = run.stop
    window = run.window()
    v, _ = speeds(model, window)
    last_program = run.by_seq(stop.first_segment - 1)
    # the stop continues from the last program segment's speed and only slows down
    stopping = [r for r in window if r["seq"] >= stop.first_segment - 1]
    v_stop, _ = speeds(model, stopping)
    assert np.all(np.diff(v_stop) <= 1e-6 + 0.02 * v_stop[:-1]), v_stop
    # a stop that begins at rest (the program had come to rest there: v0 = 0) needs no
    # deceleration; the window's segments ahead of it then are the program's own stop,
    # within the profile's limit
    limit = stop.accel if stop.v0 > 0 else run.job.profile.motion.max_accel_mm_s2
    assert peak_decel(model, window) <= accel_margin * max(limit, 1.0)
    if stop.v0 == 0:
        assert peak_decel(model, stopping) <= 1e-6
    e = [r["steps"][3] for r in stopping]
    assert all(b <= a for a, b in zip(e, e[1:]))  # never forward
    ext = run.job.profile.extruder
    assert e[0] - e[-1] == round(ext.retract_mm * ext.steps_per_mm)  # the retract, exactly
    assert last_program["steps"][3] == e[0]
    return v


@pytest.mark.parametrize("at_s", [40.0, 75.0])
def test_cancel_on_the_cup_stops_within_the_buffered_motion(tmp_path, at_s):
    run = run_with_request(_first_layers(tmp_path), "cancel", at_s, tmp_path)
    assert run.result.status == "cancelled"
    assert run.latency_s <= LATENCY_S, run.latency_s
    model = MachineModel.from_profile(run.job.profile)
    _check_controlled(run, model)
    status = run.link.request_status()
    assert not status.faulted and not status.busy
    assert status.hotend_target_c == 0 and status.bed_target_c == 0
    # parked: lifted from where it stopped
    z_stop = model.fk(
        model.sliders_from_steps(np.asarray(run.by_seq(run.stop.last_segment)["steps"][:3]))[
            None, :
        ]
    )[0, 2]
    z_now = model.fk(model.sliders_from_steps(np.asarray(status.steps[:3]))[None, :])[0, 2]
    assert z_now == pytest.approx(z_stop + run.job.profile.park.lift_mm, abs=0.05)
    # the resume point names the last program segment the device executed
    point = ResumePoint.load(run.result.resume_file)
    assert point.device_segment == run.stop.first_segment - 1
    assert point.last_line == run.stop.line


def test_pause_on_the_cup_stops_parks_and_resumes_to_completion(tmp_path):
    run = run_with_request(_first_layers(tmp_path), "pause", 60.0, tmp_path)
    assert JobState.PAUSED in run.states and run.result.status == "completed"
    assert run.latency_s <= LATENCY_S, run.latency_s
    _check_controlled(run, MachineModel.from_profile(run.job.profile))


def test_a_fast_stop_decelerates_over_several_segments_at_the_limit(tmp_path):
    run = run_with_request(fast_circles(tmp_path / "fast.gcode"), "cancel", 6.0, tmp_path)
    assert run.result.status == "cancelled"
    stop = run.stop
    assert stop.v0 > 50.0  # stopped at speed, on the curve
    assert run.latency_s <= LATENCY_S
    model = MachineModel.from_profile(run.job.profile)
    _check_controlled(run, model)
    assert peak_decel(model, run.window()) >= 0.5 * stop.accel  # at the limit, not slower


def test_a_request_is_logged_when_asked_and_when_effective(tmp_path):
    run_with_request(_first_layers(tmp_path), "cancel", 40.0, tmp_path)
    text = (tmp_path / "job.jsonl").read_text()
    assert '"what": "cancel"' in text  # asked
    assert "cancel requested" in text and "cancel: at rest" in text  # and effective


def test_a_cancel_while_the_device_waits_for_its_heater_acts_at_once(tmp_path):
    gcode = tmp_path / "hot.gcode"
    gcode.write_text("G28\nM104 S240\nM109 S240\nG92 E0\nG1 X10 Y0 Z1 E1 F1800\n")
    holder = {}

    def factory():
        holder["link"] = open_embedded()
        return holder["link"]

    def on_event(e):
        if isinstance(e, StateChanged) and e.state is JobState.HEATING:
            holder["asked"] = holder["link"].now()
            job.request_cancel()

    job = PrintJob(gcode, load_profile("paper-prototype"), factory, on_event=on_event)
    result = job.run()
    link = holder["link"]
    st = link.request_status()
    assert result.status == "cancelled"
    assert st.hotend_c < 150  # it never finished heating: the wait was flushed
    assert link.now() - holder["asked"] < LATENCY_S + 1.0  # the lift included, device time
    assert st.hotend_target_c == 0 and not st.faulted and not st.busy
