"""A reset of the board after a killed host (issue 30, item 3), on the Python device: the
next connect's DTR auto-reset, a SIGUSR1 of `cdprhost sim-device` here. The device keeps
its counters through it and announces them in BOOT; ``print --resume`` reads them and
continues from the exact segment. After a reset without a record (a power loss) the exact
place is unknown and ``--resume`` is refused, naming the layer to restart from."""

from __future__ import annotations

import json
import signal
import sys
import time

import pytest

from cdprhost.job.resume import ResumePoint, resume_path_for
from cdprhost.link import open_link
from firmware_protocol.codes import BootCause
from tests.e2e.processes import (
    SimDeviceProcess,
    printing_point,
    signal_service,
    square_part,
    start_print,
    wait_until,
)
from tests.e2e.reset_resume import ONE_MOVE, compare

pytestmark = [
    pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux"),
    pytest.mark.timeout(300),
]

SPEEDUP = "20"
LAYERS = 4


def _program(dev: SimDeviceProcess) -> list[dict]:
    return [r for r in dev.records() if "error" not in r]


def _settled(dev: SimDeviceProcess) -> list[dict]:
    """The record once the stopped device has written all of it (it streams every 0.25 s)."""
    last: list[dict] = []
    for _ in range(40):
        now = _program(dev)
        if now and now == last:
            return now
        last = now
        time.sleep(0.3)
    raise AssertionError("the record kept growing after the stop")


def _clean_record(tmp_path, gcode) -> list[dict]:
    folder = tmp_path / "clean"
    folder.mkdir()
    with SimDeviceProcess(folder, "--speedup", SPEEDUP) as dev:
        host = start_print(gcode, dev.path, tmp_path / "clean-state")
        out, err = host.communicate(timeout=200)
        assert host.returncode == 0, out + err
    return _program(dev)  # all of it: the device has exited


def _kill_then_reset(dev, gcode, state) -> ResumePoint:
    """Kill the host mid-print, let the device's watchdog stop it, then reset the board."""
    host = start_print(gcode, dev.path, state)
    printing_point(gcode, state, segments=200)
    signal_service(dev.path, state, signal.SIGKILL)
    host.communicate(timeout=60)
    wait_until(lambda: dev.stderr_has("host watchdog"), 60, "the device's watchdog")
    dev.proc.send_signal(signal.SIGUSR1)
    wait_until(lambda: dev.stderr_has("reset (external_reset)"), 30, "the reset")
    return ResumePoint.load(resume_path_for(gcode, state / "jobs"))


def test_a_reset_after_a_killed_host_then_resume_continues_from_the_exact_segment(tmp_path):
    gcode = square_part(tmp_path / "part.gcode", layers=LAYERS)
    clean = _clean_record(tmp_path, gcode)
    state = tmp_path / "state"
    with SimDeviceProcess(tmp_path, "--speedup", SPEEDUP) as dev:
        point = _kill_then_reset(dev, gcode, state)
        first = _settled(dev)
        assert first[-1]["seq"] >= point.device_segment
        report = tmp_path / "resume.json"
        host = start_print(gcode, dev.path, state, "--resume", "--yes", "--json", str(report))
        out, err = host.communicate(timeout=200)
        assert host.returncode == 0, out + err
        result = json.loads(report.read_text())
    resumed = _program(dev)[len(first) :]  # all of it: the device has exited
    assert result["status"] == "completed" and result["last_layer"] == LAYERS
    assert any("reset before this connect (external reset" in n for n in result["notices"])
    assert any("kept through the reset" in n for n in result["notices"]), result["notices"]
    same = compare(clean, first, resumed)
    assert same.prefix_equal and same.approach_found and same.last_equal, same
    assert same.filament_equal, same
    # every segment after the move the device stopped in is the uninterrupted print's: module
    # steps, extruder increment and duration; that move's rest (if it stopped moving) was
    # planned again from rest
    assert same.replaced <= ONE_MOVE and same.resumed - same.tail_equal <= ONE_MOVE + 2, same


def test_a_reset_while_idle_is_announced_at_the_next_connect(tmp_path):
    with SimDeviceProcess(tmp_path, "--speedup", SPEEDUP) as dev:
        link = open_link(dev.path)
        assert link.boot is not None and link.boot.cause == BootCause.POWER_ON
        link.close()
        dev.proc.send_signal(signal.SIGUSR1)
        wait_until(lambda: dev.stderr_has("reset (external_reset)"), 30, "the reset")
        link = open_link(dev.path)
        try:
            boot = link.boot
            assert boot is not None and boot.cause == BootCause.EXTERNAL_RESET and boot.prev_valid
        finally:
            link.close()
        link = open_link(dev.path)  # no reset since that session: nothing to announce
        assert link.boot is None
        link.close()


def test_resume_after_a_power_loss_is_refused_naming_the_layer(tmp_path):
    """A new device (a power-on: no record) cannot confirm a point a killed host left."""
    gcode = square_part(tmp_path / "part.gcode", layers=LAYERS)
    state = tmp_path / "state"
    with SimDeviceProcess(tmp_path, "--speedup", SPEEDUP) as dev:
        host = start_print(gcode, dev.path, state)
        point = printing_point(gcode, state, segments=200)
        signal_service(dev.path, state, signal.SIGKILL)
        host.communicate(timeout=60)
    assert isinstance(point, ResumePoint)
    with SimDeviceProcess(tmp_path, "--speedup", SPEEDUP) as dev:  # powered on again
        report = tmp_path / "resume.json"
        host = start_print(gcode, dev.path, state, "--resume", "--yes", "--json", str(report))
        out, err = host.communicate(timeout=120)
        result = json.loads(report.read_text())
        assert host.returncode == 1 and result["status"] == "refused", out + err
        assert "kept no record" in result["reason"] and "--resume-from-layer" in result["reason"]
        assert not [r for r in dev.records() if "error" not in r]  # nothing moved
    assert resume_path_for(gcode, state / "jobs").exists()  # the point stays
