"""Protocol and behaviour conformance of both simulated devices (see conftest)."""

from __future__ import annotations

import json
import time

import pytest

from cdprhost.link import DeviceFault, open_link
from firmware_protocol.framing import Kind, encode_frame
from firmware_protocol.messages import (
    PROTOCOL_MAJOR,
    Boot,
    ClearFault,
    Configure,
    Dwell,
    EmergencyStop,
    Enable,
    Error,
    ErrorCode,
    EstopAck,
    EstopFlag,
    Event,
    EventCode,
    Flag,
    Flow,
    Flush,
    GetStatus,
    Hello,
    Home,
    Ident,
    Segment,
    SetFan,
    SetHeater,
    Status,
    WaitHeater,
)
from firmware_protocol.streams import demo_stream, expected_record
from tests.protocol.test_proto_fuzz import BAD_PAYLOADS, fuzz_frames

pytestmark = pytest.mark.timeout(300)


def _record(dev):
    return [json.loads(line) for line in dev.record.read_text().splitlines()]


def test_handshake_and_duplicate_hello(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    ident = h.hello(0x4321)
    assert ident.major == PROTOCOL_MAJOR and ident.axes == 4 and ident.heaters == 2
    assert ident.cpu_hz == 16_000_000  # 3.0: 160 cycles a tick, the reciprocal table's
    # the same clock on both, so the host plans the same segments for both; the queue is
    # each device's own (flow control only): the AVR built with the step engine trades
    # half its 128 slots for the ring of schedule chunks (config.h QUEUE_SIZE)
    assert ident.clock_hz == 100_000 and ident.queue_capacity in (64, 128)
    assert ident.max_step_rate >= 8_000  # the host plans for 90 % of it (device_limits.py)
    assert ident.watchdog_ms == 2000 and ident.rx_window >= 64
    h.send(Dwell(10))
    h.wait_for(lambda: h.flows and h.flows[-1].items_done == 1, what="the dwell done")
    # the same HELLO again (a duplicate) keeps the session: numbering goes on
    h.urgent.clear()
    h.urgent_send(Hello(0x4321))
    h.wait_for(lambda: any(isinstance(m, Ident) for m in h.urgent), what="IDENT again")
    h.send(Dwell(10))
    h.wait_for(lambda: h.flows and h.flows[-1].items_done == 2, what="the second dwell done")
    st = h.status()
    assert st.flags & Flag.SYNCED and st.items_received == 2
    assert st.queue_free == ident.queue_capacity  # every slot free again, as announced


def test_a_hello_of_another_major_gets_an_ident_and_opens_no_session(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)

    def answered():
        # sent again until answered, as a host does (a booting device may miss one)
        h.urgent_send(Hello(0x2222, major=PROTOCOL_MAJOR - 1))  # a 2.x host
        h.pump(0.2)
        return next((m for m in h.urgent if isinstance(m, Ident) and m.nonce == 0x2222), None)

    ident = h.wait_for(answered, what="IDENT to a HELLO of the previous major")
    assert ident.major == PROTOCOL_MAJOR  # the host then refuses it, naming both versions
    # still no session: the device goes on announcing its boot, as before any HELLO
    h.urgent.clear()
    h.wait_for(lambda: any(isinstance(m, Boot) for m in h.urgent), what="BOOT after it")
    ident = h.hello(0x2222)  # a HELLO of its own major then opens one
    h.send(Dwell(10))
    h.wait_for(lambda: h.flows and h.flows[-1].items_done == 1, what="the dwell done")


def test_the_first_hello_since_a_boot_is_answered_after_a_whole_boot(device_factory, host_factory):
    """A host whose flush at its open cut the periodic BOOT short sends HELLO at once (it
    heard bytes); the session that opens ends the announcements. The record the boot kept
    (an exact resume's last executed segment) still reaches it: BOOT before that IDENT.
    A later session hears none (a BOOT at connect means no session since that boot)."""
    dev = device_factory()
    h = host_factory(dev.path)
    h.wait_for(lambda: any(isinstance(m, Boot) for m in h.urgent), what="the device up")
    h.urgent.clear()  # just after an announcement: the next one is 0.25 s away
    h.urgent_send(Hello(0x5151))
    ident = h.wait_for(
        lambda: next((m for m in h.urgent if isinstance(m, Ident)), None), what="IDENT"
    )
    kinds = [type(m) for m in h.urgent]
    assert Boot in kinds and kinds.index(Boot) < kinds.index(Ident), kinds
    boot = next(m for m in h.urgent if isinstance(m, Boot))
    assert boot.boot_id == ident.boot_id and boot.major == PROTOCOL_MAJOR
    h.urgent.clear()
    h.urgent_send(Hello(0x6262))  # another host: a new session of the same boot
    h.wait_for(
        lambda: any(isinstance(m, Ident) and m.nonce == 0x6262 for m in h.urgent),
        what="IDENT to the second HELLO",
    )
    h.pump(0.3)  # longer than the announcements' period: none come in a session
    assert not any(isinstance(m, Boot) for m in h.urgent), h.urgent


@pytest.mark.parametrize("faults", [None, "corrupt=0.002,drop=0.002,dup=0.002,seed=3"])
def test_stream_record_exact_with_and_without_line_faults(device_factory, faults):
    dev = device_factory(*(["--faults", faults] if faults else []), "--speedup", "2")
    batch = demo_stream(150, seed=2, min_ticks=1000, max_ticks=4000)
    link = open_link(dev.path)
    try:
        link.queue_segments(batch)
        link.wait_idle(120)
    finally:
        link.close()
    assert dev.stop() == 0
    assert _record(dev) == expected_record(batch)


@pytest.mark.parametrize("payload, code", BAD_PAYLOADS)
def test_bad_fields_are_answered_with_an_error(device_factory, host_factory, payload, code):
    """The model's own list of bad payloads (over-wide varints, values out of range)."""
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.ep.send(payload, items=1)
    err = h.wait_for(lambda: h.of(Error), what="an ERROR")
    assert err.code == code
    st = h.status()
    assert st.flags & Flag.FAULT and st.last_error == code
    assert st.motion_ticks == 0  # never executed
    h.send(ClearFault())
    h.wait_for(lambda: h.of(Event, code=EventCode.FAULT_CLEARED), what="FAULT_CLEARED")


def test_bad_command_names_the_opcode(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.ep.send(bytes([0x02, 0x3F]))  # GET_STATUS, then an opcode nobody defined
    err = h.wait_for(lambda: h.of(Error, code=ErrorCode.BAD_COMMAND), what="BAD_COMMAND")
    assert (err.item, err.axis, err.value) == (0, 0x3F, 1)


def test_underrun_is_reported(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.send(Segment(4000, (150, 0, 0, 0), 0), Flush())  # ends moving, nothing follows
    err = h.wait_for(lambda: h.of(Error, code=ErrorCode.UNDERRUN), timeout=20, what="UNDERRUN")
    assert err.segment == 1


def test_start_rule_waits_for_a_block_or_flush(device_factory, host_factory):
    """Below the start threshold and without a block end, motion waits for FLUSH."""
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.send(Configure(2000, 1_000_000, 10_000))  # start threshold 10 s
    h.send(Segment(4000, (150, 0, 0, 0), 0), Segment(4000, (150, 0, 0, 0), -1))
    h.pump(1.0)
    st = h.status()
    assert st.segments_done == 0 and not st.flags & Flag.MOVING
    assert st.buffered_ticks == 8000
    h.send(Flush())  # now: it starts, runs both and underruns after the second
    err = h.wait_for(lambda: h.of(Error, code=ErrorCode.UNDERRUN), timeout=20, what="UNDERRUN")
    assert err.segment == 2


def test_queue_full_leaves_the_frame_unacknowledged(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    ident = h.hello()
    h.send(SetHeater(0, 2000), WaitHeater(0, 10))  # holds the queue while heating
    for _ in range((ident.queue_capacity - 1) // 50):
        h.send(*[Dwell(10)] * 50)
    rest = ident.queue_capacity - 1 - 50 * ((ident.queue_capacity - 1) // 50)
    if rest:
        h.send(*[Dwell(10)] * rest)
    h.wait_for(lambda: h.flows and h.flows[-1].queue_free == 0, what="a full queue")
    h.keepalive = 0  # nothing behind the refused frame
    h.send(Dwell(10))  # one more: the device has no room and does not acknowledge it
    h.pump(1.0)
    assert h.ep.sender.unacked_items() == 1
    assert h.flows[-1].queue_free == 0 and h.flows[-1].flags & Flag.WAITING
    assert not h.flows[-1].flags & Flag.FAULT


def test_estop_acknowledged_and_latched(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.send(Enable(0xF), SetHeater(0, 500), Segment(100_000, (4_000, 0, 0, 0), 255))
    h.pump(0.5)
    h.urgent_send(EmergencyStop())
    h.wait_for(lambda: any(isinstance(m, EstopAck) for m in h.urgent), what="ESTOP_ACK")
    h.wait_for(lambda: h.of(Error, code=ErrorCode.ESTOP), what="ESTOP error")
    st = h.status()
    assert st.flags & Flag.ESTOP and st.flags & Flag.FAULT
    # a plain e-stop keeps the motors enabled (the effector hangs on them), heaters off
    assert st.enabled_mask == 0xF and st.hotend_target_dc == 0
    assert dev.stop() == 0
    rows = _record(dev)
    assert rows and rows[-1].get("error") == "estop"
    assert 0 < rows[-1]["steps"][0] < 4_000


def test_estop_can_keep_heaters_and_motors(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.send(Enable(0xF), SetHeater(0, 500), Segment(100_000, (4_000, 0, 0, 0), 255))
    h.pump(0.5)
    h.urgent_send(EmergencyStop(EstopFlag.KEEP_HEATERS | EstopFlag.KEEP_MOTORS))
    h.wait_for(lambda: h.of(Error, code=ErrorCode.ESTOP), what="ESTOP error")
    st = h.status()
    assert st.flags & Flag.ESTOP and st.enabled_mask == 0xF and st.hotend_target_dc == 500


def test_estop_releases_the_motors_only_when_asked(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.send(Enable(0xF), SetHeater(0, 500))
    h.wait_for(lambda: h.status().enabled_mask == 0xF, what="motors enabled")
    h.urgent_send(EmergencyStop(EstopFlag.KEEP_HEATERS | EstopFlag.RELEASE_MOTORS))
    h.wait_for(lambda: h.of(Error, code=ErrorCode.ESTOP), what="ESTOP error")
    st = h.status()
    assert st.flags & Flag.ESTOP and st.enabled_mask == 0 and st.hotend_target_dc == 500


def test_homing_reports_positions(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.send(Home(0b111, (10, 20, 30)))
    ev = h.wait_for(lambda: h.of(Event, code=EventCode.HOMED), timeout=60, what="HOMED")
    assert ev.values == (10, 20, 30)
    st = h.status()
    assert st.homed_mask == 0b111 and st.steps[:3] == (10, 20, 30)
    assert st.motion_ticks == 200_000  # 8000 steps from the switch at 4000 steps/s


def test_silent_host_turns_heaters_off_within_the_watchdog(device_factory, host_factory, kind):
    """No frame for the watchdog time: heaters off, motors held, ERROR WATCHDOG.

    On the AVR the harness also watches the heater pins: no heater pin is high later than
    the watchdog time after the host's last byte (plus 0.1 s for the harness's 1 ms polls
    and the scheduling of a loaded machine). The Python model has no pins to watch; both
    must answer with ERROR WATCHDOG and a zero heater target after the same silence."""
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.send(Configure(500, 25_000, 10_000), Enable(0b111), SetHeater(0, 1500))
    h.wait_for(lambda: h.flows and h.flows[-1].flags & Flag.HEATING, what="heating")
    h.keepalive = 0
    h.pump(0.2)  # acknowledgements only
    time.sleep(0.9)  # silent for longer than the 0.5 s watchdog
    h.keepalive = 0.5
    err = h.wait_for(lambda: h.of(Error, code=ErrorCode.WATCHDOG), what="watchdog error")
    assert err.value == 500
    st = h.status()
    assert st.hotend_target_dc == 0 and st.flags & Flag.FAULT
    assert st.enabled_mask == 0b111  # a cable robot must not drop its effector
    if kind == "avr":
        dev.stop()
        on_after_silence = dev.stats()["heater_on_silence_max_s"]
        assert 0.4 < on_after_silence <= 0.5 + 0.1, on_after_silence


def test_fuzzed_frames_then_a_clean_session(device_factory, host_factory, kind):
    """The model's own fuzz (random fields after real opcodes, mutated frames, garbage),
    20,000 frames on both (CDPR_FUZZ_FRAMES sets another count; the model alone takes
    100,000 in tests/protocol, in-process); then a clean session."""
    import os

    count = int(os.environ.get("CDPR_FUZZ_FRAMES", "20000"))
    # the AVR takes the 590 kB at 250000 baud of its simulated UART: 24 s at 1x, 12 s at 2x
    dev = device_factory("--speedup", "2")
    h = host_factory(dev.path)
    h.hello(4242)
    h.ep.window_bytes = None  # past the device's window too: its receive ring may overflow
    sent = 0
    for k, frame in enumerate(fuzz_frames(count, seed=12)):
        if isinstance(frame, tuple):
            what, payload = frame
            if what == "data":
                h.ep.send(payload)
            else:
                h.write_raw(encode_frame(Kind.URGENT, 0, 0, payload))
        else:
            h.write_raw(frame)
        sent += 1
        if k % 20 == 0:
            h.pump(0.001)
            # the host's own backlog drains before more is queued: the Python model reads
            # without limit, the AVR at 250000 baud (a real line applies back-pressure), and
            # the data frames must reach the message checks on both
            if len(h.ep.sender.backlog) > 16:
                h.wait_for(lambda: len(h.ep.sender.backlog) <= 4, timeout=30, what="drained")
            h.reports.clear()
            h.flows.clear()
    h.urgent_send(EmergencyStop())
    h2 = host_factory(dev.path)
    h2.hello(60001)
    h2.send(ClearFault(), GetStatus())
    st = h2.wait_for(lambda: h2.of(Status), timeout=30, what="STATUS after the fuzz")
    assert st.flags & Flag.SYNCED and sent > 0.95 * count  # (the generator skips a few)
    # the framing checks and the message checks were both reached
    assert st.bad_frames > count // 10 and st.items_received > 100


def test_device_faults_reach_the_host_link(device_factory):
    dev = device_factory()
    link = open_link(dev.path)
    try:
        with pytest.raises(DeviceFault):
            link.send(SetFan(1, 100))  # one fan only: BAD_VALUE
            link.wait_idle(10)
    finally:
        link.close()


def test_flow_reports_carry_buffered_time_and_the_clock(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    h.send(Dwell(50_000))
    h.wait_for(lambda: h.flows and h.flows[-1].flags & Flag.MOVING, what="moving")
    first = h.flows[-1]
    assert isinstance(first, Flow) and 0 < first.buffered_ticks <= 50_000
    h.wait_for(lambda: h.flows[-1].items_done == 1, timeout=10, what="the dwell done")
    last = h.flows[-1]
    assert last.buffered_ticks == 0 and last.clock > first.clock
