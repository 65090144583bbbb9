"""One truth about a device stopped by a fault (issue 32): the link says "faulted", not
lost; its status still comes; every command to it (home, heaters, drivers, a jog, a
calibration move, a print start; from the console too) is refused with the fault and
the way out, and nothing is sent."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.job.runner import PrintJob, PrintOptions
from cdprhost.job.state import JobSnapshot, JobState, Progress, StateChanged
from cdprhost.link import DeviceFault, PortVanished
from cdprhost.machine import DeviceFaulted, Machine
from cdprhost.machine.faults import describe_fault
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded
from cdprhost.tui.control.backend import EMBEDDED
from cdprhost.tui.control.live import LiveBackend
from cdprhost.tui.widgets.progress_panel import progress_lines, reason_after
from firmware_protocol.messages import ErrorCode, EstopFlag, Flag

PROFILE = load_profile("paper-prototype")


@pytest.fixture
def stopped():
    """A homed machine, then an e-stop (motors kept, as F9 F9 does)."""
    link = open_embedded()
    machine = Machine(link, PROFILE)
    machine.home()
    assert link.emergency_stop(flags=EstopFlag.KEEP_MOTORS)
    yield machine
    link.close()


def _refused(exc: pytest.ExceptionInfo[DeviceFaulted]) -> str:
    text = str(exc.value)
    assert "refused, nothing sent" in text and "emergency stop" in text
    assert "M999" in text  # the way out, and what it does
    assert "heaters stay off" in text
    return text


def test_the_link_of_a_faulted_device_is_faulted_not_lost_and_still_answers(stopped):
    link = stopped.link
    assert link.state == "faulted" and link.lost is None
    assert link.fault is not None and link.fault.code == ErrorCode.ESTOP
    before = link.request_status()  # answered: a fault is not a lost link
    link.poll(0.5, fault_ok=True)
    after = link.request_status()
    assert before.faulted and after.faulted and after.received_at > before.received_at
    with pytest.raises(DeviceFault):  # a job's waits still end on the fault
        link.poll(0.0)
    link.clear_fault()
    assert link.state == "connected" and link.fault is None


@pytest.mark.parametrize(
    "operation",
    [
        lambda m: m.home(),
        lambda m: m.set_heaters(100.0, None),  # M104 S100
        lambda m: m.set_heaters(None, 60.0),  # M140 S60
        lambda m: m.enable(),
        lambda m: m.move_to((5.0, 5.0, 200.0)),  # a jog
        lambda m: m.visit(np.array([[0.0, 0.0, 200.0]])),  # a calibration pose
    ],
    ids=["G28", "M104", "M140", "M17", "jog", "calibrate"],
)
def test_every_operation_on_a_faulted_device_is_refused_and_sends_nothing(stopped, operation):
    link = stopped.link
    sent, record = link.items_sent, len(link.device.record)
    with pytest.raises(DeviceFaulted) as exc:
        operation(stopped)
    _refused(exc)
    assert link.items_sent == sent and len(link.device.record) == record
    st = link.request_status()
    assert st.hotend_target_c == 0 and st.bed_target_c == 0 and st.flags & Flag.FAULT


@pytest.fixture
def live():
    backend = LiveBackend("paper-prototype", speedup=None)
    backend.connect(EMBEDDED, 250000)
    backend.home()
    assert backend.emergency_stop()
    yield backend
    backend.close()


def test_the_console_refuses_g28_and_m104_with_the_fault_and_m999_clears_it(live):
    def say(line: str) -> list[tuple[str, str]]:
        return [(c.kind, c.text) for c in live.console(line) if c.kind != "device"]

    for line in ("G28", "M104 S100", "G1 X5 F600"):
        answer = say(line)[1:]
        assert answer[0][0] == "error" and "refused, nothing sent" in answer[0][1], answer
        assert "M999" in answer[0][1] and "emergency stop" in answer[0][1]
        for _, text in answer:  # the refusal, and the e-stop's own report once
            assert "Fault" not in text and "estop: estop" not in text  # no class, no echo
    assert say("M999")[1][0] == "reply"
    assert live.link.state == "connected"
    assert say("M104 S100")[1] == ("reply", "ok")


def test_a_jog_from_the_tui_backend_is_refused_with_the_fault(live):
    view = live.device_status()  # the status still comes, with the fault in words
    assert "emergency stop" in view.fault
    with pytest.raises(DeviceFaulted, match="M999"):
        live.jog_to((5.0, 5.0, 200.0))


def test_a_print_start_on_a_faulted_device_is_refused_with_the_way_out(stopped, tmp_path):
    gcode = tmp_path / "part.gcode"
    gcode.write_text("G28\nG1 X5 Y5 Z1 F3000\n")
    options = PrintOptions(resume_dir=tmp_path, clear_fault=False)
    result = PrintJob(gcode, PROFILE, lambda: stopped.link, options).run()
    assert result.status == "refused"
    assert "emergency stop" in result.reason and "M999" in result.reason
    assert not stopped.link.device.record[-1:] or stopped.link.request_status().faulted


def test_a_watchdog_fault_is_named_once():
    link = open_embedded()
    try:
        st = link.request_status()
        from dataclasses import replace

        text = describe_fault(
            replace(st, flags=st.flags | Flag.FAULT, last_error=int(ErrorCode.WATCHDOG))
        )
        assert text is not None and text.count("watchdog") == 1
    finally:
        link.close()


def test_heating_is_shown_only_once_the_device_heats(tmp_path):
    """The stream runs ahead: an M190 sent during the start G28 is not "waiting for bed"
    while both targets are still 0."""
    gcode = tmp_path / "part.gcode"
    gcode.write_text("G28\nM190 S40\nG1 X5 Y5 Z1 F3000\n")
    holder = {}
    targets_when_heating = []

    def factory():
        holder["link"] = open_embedded()
        return holder["link"]

    def seen(event):
        if isinstance(event, StateChanged) and event.state is JobState.HEATING:
            bed = holder["link"].device.machine.heaters[1]
            targets_when_heating.append((bed.target, event.reason))

    options = PrintOptions(resume_dir=tmp_path)
    result = PrintJob(gcode, PROFILE, factory, options, on_event=seen).run()
    holder["link"].close()
    assert result.status == "completed"
    assert targets_when_heating and all(t == 40.0 for t, _ in targets_when_heating)
    assert "waiting for bed 40 C" in targets_when_heating[0][1]


def test_a_finished_job_does_not_say_its_state_twice():
    assert reason_after(JobState.CANCELLED, "cancelled") == ""
    assert reason_after(JobState.CANCELLED, "cancelled: quit") == "quit"
    assert reason_after(JobState.FAILED, "/dev/pts/0: emergency stop") == (
        "/dev/pts/0: emergency stop"
    )
    head, _, _ = progress_lines(JobSnapshot(state=JobState.CANCELLED, reason="cancelled"), "")
    assert head.plain.strip() == "CANCELLED"


def test_a_link_failure_is_told_without_a_class_name(tmp_path):
    gcode = tmp_path / "part.gcode"
    gcode.write_text("G28\nG1 X5 Y5 Z1 F3000\n")

    def gone():
        raise PortVanished("/dev/ttyACM0: the port went away")

    result = PrintJob(gcode, PROFILE, gone, PrintOptions(resume_dir=tmp_path)).run()
    assert result.status == "failed"
    assert result.reason == "/dev/ttyACM0: the port went away"  # not "PortVanished: ..."


def test_paused_and_parked_the_position_shown_is_the_parked_one(tmp_path):
    lines = ["G28", "M104 S200", "M109 S200", "G92 E0", "G1 Z0.3 F3000"]
    lines += [f"G1 X{20 * (k % 2)} Y{k % 7} E{k * 0.1:.2f} F1800" for k in range(1, 120)]
    gcode = tmp_path / "part.gcode"
    gcode.write_text("\n".join(lines) + "\n")
    events = []
    holder = {}

    def factory():
        holder["link"] = open_embedded()
        return holder["link"]

    def on_event(e):
        events.append(e)
        if isinstance(e, StateChanged) and e.state is JobState.HEATING:
            holder["heated"] = True
        if isinstance(e, StateChanged) and e.state is JobState.PRINTING and "heated" in holder:
            job.request_pause()
        if isinstance(e, StateChanged) and e.state is JobState.PAUSED:
            job.request_cancel()

    job = PrintJob(gcode, PROFILE, factory, PrintOptions(resume_dir=tmp_path), on_event=on_event)
    job.run()
    paused = next(i for i, e in enumerate(events) if getattr(e, "state", None) is JobState.PAUSED)
    shown = [e for e in events[:paused] if isinstance(e, Progress)][-1]
    park = PROFILE.gcode.park_xy_mm
    assert shown.position[:2] == pytest.approx(park, abs=0.05)  # not the last printed move
    assert shown.position[2] >= 0.3 + PROFILE.gcode.park_lift_mm - 0.05
