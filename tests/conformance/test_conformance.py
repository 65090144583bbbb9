"""Protocol and behaviour conformance of both simulated devices (see conftest)."""

from __future__ import annotations

import json
import random

import pytest

from cdprhost.link import DeviceFault, open_link
from firmware_protocol.framing import Kind, encode_frame
from firmware_protocol.messages import (
    ClearFault,
    EmergencyStop,
    Enable,
    Error,
    ErrorCode,
    EstopAck,
    Event,
    EventCode,
    Flag,
    GetStatus,
    Home,
    Segment,
    SetHeater,
    Status,
    encode_message,
)
from firmware_protocol.streams import demo_stream, expected_record

pytestmark = pytest.mark.timeout(240)


def _record(dev):
    return [json.loads(line) for line in dev.record.read_text().splitlines()]


def test_handshake_and_duplicate_hello(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    ident = h.hello(0x4321)
    assert ident.major == 1 and ident.axes == 4 and ident.heaters == 2
    # the same clock and queue on both, so the host plans the same segments for both
    assert ident.clock_hz == 100_000 and ident.queue_capacity == 128
    assert ident.max_step_rate >= 60_000  # the module speed limit of the profiles
    st = h.status()
    assert st.flags & Flag.SYNCED and st.queue_free == 128


@pytest.mark.parametrize("faults", [None, "corrupt=0.002,drop=0.002,dup=0.002,seed=3"])
def test_stream_record_exact_with_and_without_line_faults(device_factory, faults):
    dev = device_factory(*(["--faults", faults] if faults else []), "--speedup", "2")
    batch = demo_stream(150, seed=2, min_ticks=1000, max_ticks=4000)
    link = open_link(dev.path)
    try:
        link.queue_segments(batch)
        link.wait_idle(120)
        retransmits = link.stats().retransmits if hasattr(link, "stats") else None
    finally:
        link.close()
    assert dev.stop() == 0
    assert _record(dev) == expected_record(batch)
    del retransmits


def test_bad_command_and_clear_fault(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.ep.send(bytes([0x3F]))  # an opcode nobody defined
    err = h.wait_for(lambda: h.of(Error, code=ErrorCode.BAD_COMMAND), what="BAD_COMMAND")
    assert err.item == 0
    h.send(ClearFault())
    h.wait_for(lambda: h.of(Event, code=EventCode.FAULT_CLEARED), what="FAULT_CLEARED")


def test_over_wide_field_is_refused_not_truncated(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    # DWELL with an 11-byte varint: longer than any field may be
    h.ep.send(bytes([0x13]) + b"\xff" * 10 + b"\x01", items=1)
    h.wait_for(lambda: h.of(Error, code=ErrorCode.BAD_COMMAND), what="BAD_COMMAND")


def test_underrun_is_reported(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.send(Segment(4000, (300, 0, 0, 0), 0))  # starts from rest, ends moving, nothing follows
    err = h.wait_for(lambda: h.of(Error, code=ErrorCode.UNDERRUN), timeout=20, what="UNDERRUN")
    assert err.segment == 1


def test_estop_acknowledged_and_latched(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.send(Enable(0xF), Segment(100_000, (20_000, 0, 0, 0), -1))
    h.pump(0.5)
    frame = encode_frame(Kind.URGENT, 0, 0, encode_message(EmergencyStop()))
    h.write_raw(frame)
    h.wait_for(lambda: any(isinstance(m, EstopAck) for m in h.urgent), what="ESTOP_ACK")
    h.wait_for(lambda: h.of(Error, code=ErrorCode.ESTOP), what="ESTOP error")
    st = h.status()
    assert st.flags & Flag.ESTOP and st.flags & Flag.FAULT and st.enabled_mask == 0
    assert dev.stop() == 0
    rows = _record(dev)
    assert rows and rows[-1].get("error") == "estop"
    assert 0 < rows[-1]["steps"][0] < 20_000


def test_homing_reports_positions(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.send(Home(0b111, (10, 20, 30)))
    ev = h.wait_for(lambda: h.of(Event, code=EventCode.HOMED), timeout=60, what="HOMED")
    assert ev.values == (10, 20, 30)
    st = h.status()
    assert st.homed_mask == 0b111 and st.steps[:3] == (10, 20, 30)


def test_heater_failure_is_a_thermal_runaway(device_factory, host_factory):
    """The element fails (device time 1 s): heating at full power without rising is a runaway."""
    dev = device_factory("--faults", "heater_fail_after=1", "--speedup", "4")
    h = host_factory(dev.path)
    h.hello()
    h.send(SetHeater(0, 2000))
    err = h.wait_for(
        lambda: h.of(Error, code=ErrorCode.THERMAL_RUNAWAY), timeout=90, what="THERMAL_RUNAWAY"
    )
    assert err.axis == 0
    st = h.status()
    assert st.hotend_target_dc == 0


def test_malformed_frames_then_a_clean_session(device_factory, host_factory, kind):
    """Random and mutated frames (fewer for the AVR: simavr runs near real time)."""
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    rng = random.Random(7)
    good = encode_frame(Kind.DATA, 0, 0, bytes([0x02]))
    count = 400 if kind == "avr" else 5000
    for i in range(count):
        if i % 2:
            frame = bytearray(good)
            for _ in range(rng.randint(1, 3)):
                frame[rng.randrange(len(frame))] = rng.randrange(256)
            data = bytes(frame)
        else:
            n = rng.randint(0, 248)
            payload = bytes(rng.randrange(256) for _ in range(n))
            data = encode_frame(rng.randint(1, 4), rng.randrange(256), rng.randrange(256), payload)
        h.write_raw(data)
        if i % 50 == 0:
            h.pump(0.01)
    h2 = host_factory(dev.path)
    h2.hello(0x777)
    h2.send(ClearFault(), GetStatus())
    st = h2.wait_for(lambda: h2.of(Status), timeout=20, what="STATUS after fuzz")
    assert st.flags & Flag.SYNCED


def test_silent_host_turns_heaters_off(device_factory, host_factory, kind):
    if kind == "python":
        pytest.skip("the protocol-1 Python model has no host watchdog (protocol 2 adds one)")
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.send(SetHeater(0, 1500))
    h.pump(0.3)
    h.port.reset_input_buffer()
    import time

    time.sleep(3.0)  # silent: no frame for longer than the 2 s watchdog
    h.wait_for(lambda: h.of(Error, code=ErrorCode.ESTOP), timeout=10, what="watchdog error")
    st = h.status()
    assert st.hotend_target_dc == 0 and st.flags & Flag.FAULT


def test_print_through_open_link_surfaces_device_faults(device_factory):
    dev = device_factory()
    link = open_link(dev.path)
    try:
        with pytest.raises(DeviceFault):
            link.send(SetHeater(5, 100))  # no heater 5: BAD_COMMAND
            link.wait_idle(10)
    finally:
        link.close()
