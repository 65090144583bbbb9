"""Protocol 3.0's step schedules on both devices (PROTOCOL.md 5.5): a segment with its
schedule block runs; a block whose counts are not the segment's, or that steps faster
than the device's shortest interval, is BAD_VALUE naming the segment and the axis, and
nothing moves."""

from __future__ import annotations

import pytest

from firmware_protocol.messages import (
    PROTOCOL_MINOR,
    Caps,
    Error,
    ErrorCode,
    Flag,
    Flush,
    GetCaps,
    Segment,
    Stepping,
)
from firmware_protocol.schedule_block import encode_block
from firmware_protocol.schedule_fit import fit_axis
from firmware_protocol.segments import F_SCHEDULE, encode_one_segment
from firmware_protocol.step_schedule import FRAC_BITS, AxisSchedule, Chunk, ideal_edges

pytestmark = pytest.mark.timeout(300)

CPT = 160  # cycles a tick: both devices announce 16 MHz and 100 kHz


def _fitted(steps: int, ticks: int, ramp: int, tol: int) -> AxisSchedule:
    return fit_axis(ideal_edges(steps, ticks, ramp, CPT), tol)


def _caps(h) -> Caps:
    h.send(GetCaps())
    return h.wait_for(lambda: h.of(Caps), what="CAPS")


def test_caps_is_followed_by_stepping_in_a_3_1_session_only(device_factory, host_factory):
    """3.1: STEPPING after CAPS says what the device steps without a block (the AVR's step
    engine its tick's 8,000 steps/s, under the engine's own rate); a 3.0 host's session
    (HELLO minor 0) gets CAPS alone, as a 3.0 device would send it."""
    dev = device_factory()
    h = host_factory(dev.path)
    ident = h.hello()
    assert (ident.major, ident.minor) == (3, PROTOCOL_MINOR)
    _caps(h)
    stepping = h.wait_for(lambda: h.of(Stepping), what="STEPPING")
    assert 1 <= stepping.profile_step_rate <= ident.max_step_rate
    h.reports.clear()
    h.hello(nonce=0x2345, minor=0)
    _caps(h)
    h.status()  # answered after anything GET_CAPS brought
    assert h.of(Stepping) is None


def test_segments_with_schedule_blocks_run_and_land_exactly(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    ident = h.hello()
    assert ident.cpu_hz == 16_000_000
    caps = _caps(h)
    assert caps.schedule_tolerance_cycles >= 1
    assert caps.min_step_interval_cycles < ident.cpu_hz // ident.max_step_rate
    tol = caps.schedule_tolerance_cycles
    up = (6, -4, 0, 2)  # from rest, then to rest, each in its own frame (120 bytes)
    for ramp in (0, 255):
        scheds = tuple((k, _fitted(n, 20_000, ramp, tol)) for k, n in enumerate(up) if n)
        h.send(Segment(20_000, up, ramp, scheds))
    h.send(Flush())
    h.wait_for(
        lambda: h.flows and h.flows[-1].segments_done == 2 and not h.flows[-1].flags & 1,
        timeout=30,
        what="both segments done",
    )
    st = h.status()
    assert not st.flags & Flag.FAULT and st.last_error == 0
    assert st.steps == tuple(2 * n for n in up)


def _refused(h, payload: bytes) -> Error:
    h.ep.send(payload, items=1)
    err = h.wait_for(lambda: h.of(Error), what="an ERROR")
    st = h.status()
    assert st.flags & Flag.FAULT and st.motion_ticks == 0  # nothing of it moved
    assert st.steps == (0, 0, 0, 0)
    return err


def _with_block(ticks: int, deltas: tuple[int, int, int, int], block: bytes, h) -> bytes:
    seg = bytearray(encode_one_segment(ticks, deltas, -1, h.ctx))
    seg[0] |= F_SCHEDULE
    return bytes(seg) + block


def test_a_block_whose_counts_are_not_the_segments_is_bad_value(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    slow = 16_000 << FRAC_BITS  # 100 steps/s
    # a further chunk of 10 steps leaves none of the segment's 10 for the first
    greedy = AxisSchedule(0, (Chunk(1, slow, 0), Chunk(10, slow, 0)))
    block = encode_block([11, 0, 0, 0], 10_000, {0: greedy}, h.ctx.table)
    err = _refused(h, _with_block(10_000, (10, 0, 0, 0), block, h))
    assert (err.code, err.segment, err.axis, err.value) == (ErrorCode.BAD_VALUE, 1, 0, 0)


def test_a_block_stepping_faster_than_the_device_is_bad_value(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    caps = _caps(h)
    fast = 10 << FRAC_BITS  # 10 cycles between edges: 1.6 M steps/s
    assert caps.min_step_interval_cycles > 10
    sched = AxisSchedule(100 << FRAC_BITS, (Chunk(10, fast, 0),))
    block = encode_block([0, 10, 0, 0], 10_000, {1: sched}, h.ctx.table)
    err = _refused(h, _with_block(10_000, (0, 10, 0, 0), block, h))
    assert (err.code, err.segment, err.axis, err.value) == (ErrorCode.BAD_VALUE, 1, 1, 10)


def test_a_malformed_block_is_bad_command(device_factory, host_factory):
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    err = _refused(h, _with_block(10_000, (10, 0, 0, 0), bytes([0x10]), h))  # reserved axis
    assert err.code == ErrorCode.BAD_COMMAND


def test_a_block_malformed_in_a_further_chunk_refuses_its_whole_frame(device_factory, host_factory):
    """The frame's check on receipt reads every block to its end: a further chunk's count
    wider than 16 bits, in the second segment of a frame, is BAD_COMMAND and the first
    segment does not move either."""
    dev = device_factory()
    h = host_factory(dev.path)
    h.hello()
    first = encode_one_segment(10_000, (10, 0, 0, 0), -1, h.ctx)
    wide = bytes([0x80, 0x80, 0x04])  # 65,536
    block = bytes([0x01, 0, 0, 0, 1]) + wide + bytes([0, 0])
    h.ep.send(first + _with_block(10_000, (10, 0, 0, 0), block, h), items=2)
    err = h.wait_for(lambda: h.of(Error), what="an ERROR")
    assert err.code == ErrorCode.BAD_COMMAND
    st = h.status()
    assert st.flags & Flag.FAULT and st.motion_ticks == 0
    assert st.steps == (0, 0, 0, 0)
