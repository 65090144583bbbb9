"""The device model's one shutdown path (protocol 2.1): thermal faults latch, a fault that
arrives while faulted is reported, soft limits, a fresh boot id at every start."""

from __future__ import annotations

import contextlib

import pytest

import firmware_protocol.messages as M
from cdprhost.link import DeviceFault
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.device.firmware import SimDevice
from firmware_protocol.messages import ErrorCode


def test_a_thermal_fault_while_faulted_is_reported_and_latches():
    """UNDERRUN first (heater kept on), then the element fails: THERMAL_RUNAWAY is still
    reported; CLEAR_FAULT is refused, over a new session too."""
    link = open_embedded(faults="heater_fail_after=5", heater_lease_s=60)
    link.send(M.SetHeater(M.HOTEND, 2100), M.Segment(4000, (300, 0, 0, 0), 0), M.Flush())
    with pytest.raises(DeviceFault, match="underrun"):
        link.wait_idle(10)
    mc = link.device.machine
    assert mc.fault == ErrorCode.UNDERRUN and mc.heaters[0].target == 210.0
    end = link.now() + 60
    while link.now() < end:  # the host stays alive (it reads the reports): the heater fails
        link._dev.failure = None
        with contextlib.suppress(DeviceFault):
            link._core.pump(0.5)
        if mc.last_error == ErrorCode.THERMAL_RUNAWAY:
            break
    assert mc.last_error == ErrorCode.THERMAL_RUNAWAY and mc.latched == ErrorCode.THERMAL_RUNAWAY
    assert mc.heaters[0].target == 0.0
    assert [e.code for e in link._dev.events if hasattr(e, "code")] == [
        ErrorCode.UNDERRUN,
        ErrorCode.THERMAL_RUNAWAY,
    ]  # the second fault reported too
    with pytest.raises(DeviceFault, match="refuses to clear THERMAL_RUNAWAY"):
        link.clear_fault()
    link.handshake()
    with pytest.raises(DeviceFault, match="refuses to clear"):
        link.clear_fault()
    assert mc.fault == ErrorCode.THERMAL_RUNAWAY  # still latched


def test_soft_limits_refuse_a_segment_before_it_moves():
    link = open_embedded()
    link.send(M.Home(0b111, (0, 0, 0)))
    link.wait_idle(60)
    link.send(M.SetLimits(2, -50, 50))
    link.send(M.Segment(1000, (0, 0, 40, 0), 255))
    link.wait_idle(10)
    link.send(M.Segment(1000, (0, 0, 20, 0), 255))
    with pytest.raises(DeviceFault) as exc:
        link.wait_idle(10)
    assert (exc.value.code, exc.value.axis, exc.value.value) == (ErrorCode.ENDSTOP_HIT, 2, 60)
    assert link.device.machine.pos[2] == 40


def test_every_start_of_the_device_has_its_own_boot_id():
    ids = {SimDevice().boot_id for _ in range(20)}
    assert len(ids) == 20
    dev = SimDevice()
    first = dev.boot_id
    dev.reboot(1.0)
    assert dev.boot_id not in (0, first)
