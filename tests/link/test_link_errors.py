"""Every wait ends with a clear error: missing, busy, vanished ports; silent, garbled, foreign devices."""

from __future__ import annotations

import os
import threading
import time

import pytest
import serial

import cdprhost.link.session_setup as session_setup
import firmware_protocol.device.firmware as firmware
from cdprhost.cli.main import main
from cdprhost.link import (
    DeviceSilent,
    PortBusy,
    PortNotFound,
    PortVanished,
    ProtocolMismatch,
    open_link,
)
from cdprhost.link.host_link import HostLink
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.device.firmware import SimDevice
from firmware_protocol.device.harness import VirtualBench
from firmware_protocol.device.pty_server import PtyServer
from firmware_protocol.messages import PROTOCOL_MINOR
from firmware_protocol.streams import demo_stream

needs_pty = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals")


class ServerThread:
    def __init__(self, device=None):
        self.server = PtyServer(device or SimDevice())
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def close(self):
        self.server.stop()
        self.thread.join(2)
        self.server.close()


def test_missing_port():
    with pytest.raises(PortNotFound, match="no such port") as exc:
        open_link("/dev/does-not-exist-cdpr")
    assert exc.value.exit_code == 2


@pytest.mark.timeout(60)  # the wait ends (how soon is not asserted: the machine is shared)
def test_silent_device_times_out_with_a_clear_message():
    with pytest.raises(DeviceSilent, match="no answer|no valid frame"):
        open_link("loop://", timeout_s=0.3)  # hears only its own HELLO frames


@needs_pty
def test_garbage_suggests_a_wrong_baud_rate():
    master, slave = os.openpty()
    path = os.ttyname(slave)
    stop = threading.Event()

    def babble():
        while not stop.is_set():
            os.write(master, os.urandom(64).replace(b"\xa5", b"\x00"))
            time.sleep(0.01)

    th = threading.Thread(target=babble, daemon=True)
    th.start()
    try:
        with pytest.raises(DeviceSilent, match="wrong baud rate"):
            open_link(path, timeout_s=1.0)  # long enough for a starved babbler to write
    finally:
        stop.set()
        th.join(1)
        os.close(master)
        os.close(slave)


@needs_pty
def test_port_in_use_is_refused():
    srv = ServerThread()
    try:
        with serial.Serial(srv.server.path, exclusive=True):
            with pytest.raises(PortBusy, match="in use"):
                open_link(srv.server.path)
    finally:
        srv.close()


@needs_pty
def test_port_vanishing_mid_session():
    srv = ServerThread()
    link = open_link(srv.server.path)
    link.queue_segments(demo_stream(20, seed=1))
    srv.close()  # the device side disappears (both pty ends closed)
    with pytest.raises(PortVanished, match="unplugged"):
        link.queue_segments(demo_stream(2000, seed=2))
        link.wait_idle(5)
    link.close()


def test_protocol_major_mismatch(monkeypatch):
    # a 3.x host and a 2.x device (schedule blocks are 3.0's): the host refuses it
    monkeypatch.setattr(firmware, "PROTOCOL_MAJOR", 2)
    with pytest.raises(ProtocolMismatch, match=f"protocol 2.{PROTOCOL_MINOR}") as exc:
        open_embedded()
    assert exc.value.device_version == (2, PROTOCOL_MINOR)
    assert exc.value.host_version == (3, PROTOCOL_MINOR)


def test_a_host_of_a_newer_major_is_refused_and_the_device_opens_no_session(monkeypatch):
    # the other direction of the test above: the host speaks a major the device does not
    # (a 2.x host and a 3.0 device)
    monkeypatch.setattr(session_setup, "PROTOCOL_MAJOR", 2)
    device = SimDevice()
    link = HostLink(VirtualBench(device), device=device)
    with pytest.raises(ProtocolMismatch, match="protocol 3") as exc:
        link.handshake()
    assert exc.value.host_version == (2, PROTOCOL_MINOR)
    assert exc.value.device_version == (3, PROTOCOL_MINOR)
    assert not device.synced  # it answered with IDENT and took nothing further


def test_sim_device_cli_rejects_bad_options(capsys):
    assert main(["sim-device", "--faults", "corrupt=2"]) == 2
    assert "--faults: corrupt" in capsys.readouterr().err
    assert main(["sim-device", "--faults", "bogus=1"]) == 2
    assert "unknown key 'bogus'" in capsys.readouterr().err
    assert main(["sim-device", "--truth", "paper-simulation"]) == 2
    assert "--truth needs --mocap-dir" in capsys.readouterr().err


def test_a_planner_late_error_says_how_late_or_that_a_segment_could_not_be_queued():
    from cdprhost.link.events import error_text
    from firmware_protocol.codes import ErrorCode
    from firmware_protocol.messages import Error

    late = error_text(Error(ErrorCode.PLANNER_LATE, 9, 7, 0xFF, 3))
    assert late.endswith("segment 7: the device's segment preparation fell 3 ticks behind")
    # value 0: the step engine found no slot for an axis's chunk (it stops rather than
    # go on without that axis's steps)
    stuck = error_text(Error(ErrorCode.PLANNER_LATE, 9, 7, 2, 0))
    assert "axis 2" in stuck and "could not prepare the segment's steps" in stuck
    assert "0 ticks" not in stuck


def test_an_emergency_stop_error_says_so_in_words():
    """The device's ESTOP error, however it reaches the user (a wait that the stop broke, or
    an operation refused after it), names an emergency stop, not just its code."""
    from cdprhost.link.events import error_text
    from firmware_protocol.codes import ErrorCode
    from firmware_protocol.messages import Error

    text = error_text(Error(ErrorCode.ESTOP, 2, 0, 0xFF, 0))
    assert text == "estop at item 2, segment 0: emergency stop"
