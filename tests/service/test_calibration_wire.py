"""The calibration wizard's device through the service's device session (the embedded
device, as fast as it goes): a visit homes, moves and settles and answers the device's
clock; the virtual motion capture and the simulated camera watch the embedded device; a
visit is refused on a faulted device (with M999), while a print runs, or out of the
workspace, nothing moved."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from cdprhost.kinematics import MachineModel
from cdprhost.profile import load_profile
from cdprhost.service import wire
from cdprhost.service.device_session import DeviceSession


@pytest.fixture
def profile():
    return load_profile("paper-prototype")


@pytest.fixture
def session(profile):
    sent: list = []
    busy = {"job": False}
    s = DeviceSession(None, sent.append, lambda: busy["job"], poll_s=60.0)
    s.sent, s.busy = sent, busy  # type: ignore[attr-defined]
    answer = s.connect(1, wire.Connect(profile=profile.model_dump(mode="json"), speedup=None))
    assert answer.ok, answer.error
    yield s
    s.close()


def _poses(profile) -> np.ndarray:
    return np.array([(10.0, -20.0, 250.0), (-30.0, 15.0, 200.0)])


def test_a_visit_homes_moves_settles_and_answers_the_device_clock(session, profile):
    model = MachineModel.from_profile(profile)
    points = _poses(profile)
    answer = session.run(wire.Visit(id=3, points=tuple(map(tuple, points)), settle_s=0.5))
    assert answer.ok, answer.error
    assert answer.id == 3 and answer.status is not None
    assert answer.status.homed_mask & 0b111 == 0b111  # homed first, as Machine.visit
    expected = model.steps(model.ik(points[-1:]))[0]
    assert answer.status.steps[:3] == tuple(int(v) for v in expected)
    assert answer.device_time_s is not None and answer.device_time_s > 0.5
    later = session.run(wire.Visit(id=4, points=(tuple(points[0]),)))
    assert later.device_time_s > answer.device_time_s  # one clock, going on
    assert any(isinstance(m, wire.DeviceMsg) for m in session.sent)  # the others see it


def test_the_virtual_motion_capture_writes_a_take_at_every_settle(session, profile, tmp_path):
    mocap = tmp_path / "mocap"
    answer = session.run(wire.Observe(id=1, truth="paper-prototype", mocap_dir=str(mocap)))
    assert answer.ok, answer.error
    for k, point in enumerate(_poses(profile), start=1):
        assert session.run(wire.Visit(points=(tuple(point),))).ok
        assert (mocap / f"take-{k:04d}.csv").is_file()
    relative = session.run(wire.Observe(truth="paper-prototype", mocap_dir="mocap"))
    assert not relative.ok and "absolute" in relative.error


def test_the_simulated_camera_takes_pictures_into_the_clients_folder(session, tmp_path):
    missing = session.run(wire.Capture(folder=str(tmp_path / "pictures")))
    assert not missing.ok and "observe with a camera first" in missing.error
    assert session.run(wire.Observe(camera=(320, 240))).ok
    answer = session.run(wire.Capture(folder=str(tmp_path / "pictures"), frames=2))
    assert answer.ok, answer.error
    assert len(answer.files) == 2 and len(set(answer.files)) == 2
    image = cv2.imread(answer.files[0])
    assert image is not None and image.shape == (240, 320, 3)


def test_a_faulted_device_refuses_a_visit_with_the_way_out(session, profile):
    assert session.run(wire.Home()).ok
    before = session.run(wire.Status()).status
    assert session.emergency_stop(5).ok
    answer = session.run(wire.Visit(points=(tuple(_poses(profile)[0]),)))
    assert not answer.ok
    assert "refused, nothing sent" in answer.error and "M999" in answer.error, answer.error
    assert session.run(wire.Status()).status.steps == before.steps  # nothing moved
    assert session.run(wire.ClearFault()).ok
    assert session.run(wire.Visit(points=(tuple(_poses(profile)[0]),))).ok


def test_a_visit_is_refused_while_a_print_runs_and_outside_the_workspace(session, profile):
    assert session.run(wire.Home()).ok
    before = session.run(wire.Status()).status
    far = session.run(wire.Visit(points=((0.0, 0.0, 250.0), (5000.0, 0.0, 250.0))))
    assert not far.ok and far.error.startswith("refused, nothing moved"), far.error
    session.busy["job"] = True
    busy = session.run(wire.Visit(points=((0.0, 0.0, 250.0),)))
    assert not busy.ok and "a print is running" in busy.error
    session.busy["job"] = False
    assert session.run(wire.Status()).status.steps == before.steps


def test_observers_are_for_the_embedded_device_only(profile):
    from cdprhost.sim.embedded import open_embedded

    s = DeviceSession("/dev/pts/999", lambda _: None, lambda: False, poll_s=60.0)
    s.opener = lambda spec, prof: open_embedded(timeout_s=prof.serial.timeout_s)
    assert s.connect(1, wire.Connect(profile=profile.model_dump(mode="json"))).ok
    try:
        answer = s.run(wire.Observe(truth="paper-prototype", mocap_dir="/tmp/x"))
        assert not answer.ok and "embedded simulated device only" in answer.error
    finally:
        s.close()


@pytest.mark.parametrize(
    "line, where",
    [
        (b'{"op":"visit","points":[]}', "points"),
        (b'{"op":"visit","points":[[0,0,NaN]]}', "points"),
        (b'{"op":"visit","points":[[0,0,1]],"settle_s":-1}', "settle_s"),
        (b'{"op":"observe","camera":[100000,100000]}', "camera"),
        (b'{"op":"capture","folder":"/tmp/x","frames":1000}', "frames"),
    ],
)
def test_the_calibration_requests_are_checked_at_the_wire(line, where):
    with pytest.raises(wire.WireError, match=where):
        wire.decode_request(line)


def test_the_answer_carries_the_device_clock_and_the_pictures():
    answer = wire.Answer(id=2, ok=True, device_time_s=1.5, files=("/tmp/a.png",))
    again = wire.decode_reply(wire.encode(answer))
    assert again.device_time_s == 1.5 and again.files == ("/tmp/a.png",)


def test_an_emergency_stop_ends_a_visit_under_way(profile):
    """The e-stop does not wait for the visit's lock: the visit answers that the device
    stopped during the move (a real-time device, so the homing is under way)."""
    import threading

    s = DeviceSession(None, lambda _: None, lambda: False)  # its poll pumps the clock 0.8 s
    assert s.connect(1, wire.Connect(profile=profile.model_dump(mode="json"), speedup=1.0)).ok
    try:
        answers: list = []
        visit = wire.Visit(points=(tuple(_poses(profile)[0]),))
        worker = threading.Thread(target=lambda: answers.append(s.run(visit)))
        worker.start()
        time.sleep(2.0)  # (homing, then the move, at 1x)
        assert s.emergency_stop(9).ok
        worker.join(30)
        assert answers and not answers[0].ok, answers
        assert "emergency stop" in answers[0].error, answers[0].error
        after = s.run(wire.Status()).status
        model = MachineModel.from_profile(profile)
        target = model.steps(model.ik(_poses(profile)[:1]))[0]
        assert "estop" in after.fault and after.steps[:3] != tuple(int(v) for v in target)
    finally:
        s.close()
