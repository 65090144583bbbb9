"""What the AVR does per received segment, kept cheap for 2,000 print-like segments/s
(issue 29), still exact:

- the step-rate check on receipt takes a 32-bit path for a short fast segment (the
  print's); its boundary is the protocol's: a segment exactly at MAX_STEP_RATE (peak) is
  taken, one step more is ERROR STEP_RATE naming the axis and its peak rate, constant
  speed and ramped alike;
- a DATA frame of segments only is decoded once, on receipt, into the queue slots its
  items take (commands.c, stage_segments); a frame with anything else is checked and
  decoded again when executed, from the coder context the staged frames before it
  left: the record is exact either way, predicted deltas across the two included;
- such a frame behind nothing held is queued as it is checked: the FLOW of its own ACK
  already counts its motion as buffered (it waited for a main-loop turn's execution);
- a segment whose deltas are plain one-byte codes takes the decoder's short path; a
  longer code or a segment cut short by the frame's end takes the full one (the cut one
  is BAD_COMMAND naming its opcode and offset, and nothing of its frame runs).
"""

from __future__ import annotations

import json
import os

import pytest

from firmware_protocol.messages import ErrorCode, Flow, Flush, Segment, SetFan
from firmware_protocol.segments import SegmentBatch
from firmware_protocol.streams import expected_record
from tests.conformance.device import RawHost, start
from tests.firmware.raw import errors

pytestmark = [
    pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals"),
    pytest.mark.timeout(300),
]

CONSTANT, TO_REST = -1, 255


def _record(dev) -> list[dict]:
    return [json.loads(x) for x in dev.record.read_text().splitlines() if x.strip()]


@pytest.mark.parametrize(
    ("ticks", "axis", "ramp"),
    [
        (50, 3, CONSTANT),  # n steps in 0.5 ms at constant speed: 2,000 n steps/s
        (100, 2, TO_REST),  # n steps in 1 ms braking to rest: a peak of twice the mean
    ],
)
def test_the_rate_check_boundary_on_short_segments(avr_built, tmp_path, ticks, axis, ramp):
    dev = start("avr", tmp_path, "--speedup", "4")
    h = RawHost(dev.path)
    try:
        ident = h.hello()
        n = ident.max_step_rate // 2_000  # steps at exactly the rate, both shapes
        assert n * 2_000 == ident.max_step_rate  # (8,000 as built by default)
        h.send(
            # n steps in 0.5 ms: exactly the rate on every axis
            Segment(ticks=50, deltas=(n, -n, n, -n), ramp=CONSTANT),
            # n steps in 1 ms to rest: a peak of exactly the rate
            Segment(ticks=100, deltas=(-n, n, -n, n), ramp=TO_REST),
            Flush(),
        )
        h.wait_for(lambda: h.status().segments_done == 2, timeout=30, what="both segments")
        assert not errors(h, ErrorCode.STEP_RATE)
        deltas = tuple(n + 1 if k == axis else 0 for k in range(4))
        h.send(Segment(ticks=ticks, deltas=deltas, ramp=ramp), Flush())
        err = h.wait_for(lambda: errors(h, ErrorCode.STEP_RATE), what="STEP_RATE")[0]
        assert (err.axis, err.value, err.segment) == (axis, (n + 1) * 2_000, 3)
    finally:
        h.close()
        dev.stop()
    assert [r["seq"] for r in _record(dev) if "error" not in r] == [1, 2]


def test_a_staged_frame_refuses_its_segment_over_the_rate_at_that_segment(avr_built, tmp_path):
    # a frame of segments only is staged on receipt, each segment's own limits checked as
    # it is stored; the one over the rate sends the frame the checked way, which refuses
    # it at its own number (STEP_RATE naming the axis and its peak) with nothing of it or
    # after it run, as a frame that is not staged
    dev = start("avr", tmp_path, "--speedup", "4")
    h = RawHost(dev.path)
    try:
        n = h.hello().max_step_rate // 2_000  # steps in 0.5 ms at exactly the rate
        ok = [Segment(ticks=50, deltas=(n, -n, 1, 0), ramp=CONSTANT) for _ in range(3)]
        over = Segment(ticks=50, deltas=(1, -(n + 1), 1, 0), ramp=CONSTANT)
        h.send(*ok, over, *ok[:2], Segment(ticks=100, deltas=(1, 0, 0, 0), ramp=TO_REST))
        err = h.wait_for(lambda: errors(h, ErrorCode.STEP_RATE), what="STEP_RATE")[0]
        assert (err.axis, err.value, err.segment) == (1, (n + 1) * 2_000, 4)
    finally:
        h.close()
        dev.stop()
    assert all(r["seq"] <= 3 for r in _record(dev) if "error" not in r)


def test_a_frame_of_segments_behind_nothing_held_is_queued_as_it_is_checked(avr_built, tmp_path):
    dev = start("avr", tmp_path, "--speedup", "4")
    h = RawHost(dev.path)
    try:
        capacity = h.hello().queue_capacity
        h.pump(0.2)
        seen = len(h.flows)
        frame = [Segment(ticks=1_000, deltas=(2, -1, 1, 0), ramp=CONSTANT) for _ in range(8)]
        h.send(*frame)  # no block's end, no FLUSH: nothing starts
        ack = h.wait_for(lambda: h.flows[seen:], what="the frame's ACK")[0]
        assert isinstance(ack, Flow)
        assert ack.buffered_ticks == 8 * 1_000  # queued already, not held for a later turn
        assert h.status().queue_free == capacity - 8
    finally:
        h.close()
        dev.stop()


def test_staged_and_checked_frames_keep_the_coder_context(avr_built, tmp_path):
    # segments only (staged on receipt), then segments with a queued command (checked,
    # decoded when executed): the second frame's first segments repeat or predict from
    # the last of the first (opcode-only and predicted codings), so a context not handed
    # on from the staged frame would decode them wrong
    first = [Segment(ticks=100, deltas=(3 + k % 2, -2, 1, k % 3), ramp=CONSTANT) for k in range(12)]
    second = [
        Segment(ticks=100, deltas=(4, -2, 1, 2), ramp=CONSTANT),
        Segment(ticks=100, deltas=(4, -2, 1, 2), ramp=CONSTANT),
        Segment(ticks=100, deltas=(5, -3, 1, 2), ramp=CONSTANT),
        Segment(ticks=200, deltas=(2, -1, 0, 1), ramp=TO_REST),
    ]
    segments = first + second
    dev = start("avr", tmp_path, "--speedup", "4")
    h = RawHost(dev.path)
    try:
        h.hello()
        h.send(*first)
        h.send(*second[:2], SetFan(0, 0), *second[2:], Flush())
        h.wait_for(
            lambda: h.status().segments_done == len(segments), timeout=30, what="the segments"
        )
        assert not [m for m in h.reports if type(m).__name__ == "Error"]
    finally:
        h.close()
        dev.stop()
    batch = SegmentBatch(
        [s.ticks for s in segments], [s.deltas for s in segments], [s.ramp for s in segments]
    )
    rows = [r for r in _record(dev) if "error" not in r]
    assert rows == expected_record(batch)


# raw segment codings (PROTOCOL.md 4.1): opcode 0x80 | flags, the duration (LEB128) when
# flagged, then each coded delta zigzagged (one byte for |delta| < 64)
DURATION_100_MS = bytes([0x8A, 0x90, 0x4E])  # modules' deltas and a duration: 10,000 units


def test_plain_one_byte_segments_and_the_full_decoder_agree(avr_built, tmp_path):
    payload = (
        DURATION_100_MS
        + bytes([0x02, 0x02, 0x02])  # (1, 1, 1, 0)
        + bytes([0x88, 0x81, 0x01, 0x02, 0x04])  # a two-byte code: (-65, 1, 2, 0)
        + bytes([0x98, 0x03, 0x02, 0x02, 0x06])  # one byte each: (-2, 1, 1, 3)
        + bytes([0x88, 0x7F, 0x7E, 0x00])  # the one-byte extremes: (-64, 63, 0, 0)
        + bytes([0x80])  # a pause (no deltas): the motion ends at rest
    )
    deltas = [(1, 1, 1, 0), (-65, 1, 2, 0), (-2, 1, 1, 3), (-64, 63, 0, 0), (0, 0, 0, 0)]
    dev = start("avr", tmp_path, "--speedup", "4")
    h = RawHost(dev.path)
    try:
        h.hello()
        h.ep.send(payload, items=len(deltas))
        h.send(Flush())
        h.wait_for(lambda: h.status().segments_done == len(deltas), timeout=30, what="the run")
        assert not [m for m in h.reports if type(m).__name__ == "Error"]
    finally:
        h.close()
        dev.stop()
    batch = SegmentBatch([10_000] * len(deltas), deltas, [CONSTANT] * len(deltas))
    assert [r for r in _record(dev) if "error" not in r] == expected_record(batch)


def test_a_segment_cut_short_is_bad_command_and_its_frame_does_not_run(avr_built, tmp_path):
    # the second segment asks for four one-byte codes and the frame ends after three
    payload = DURATION_100_MS + bytes([0x02, 0x02, 0x02, 0x98, 0x02, 0x02, 0x02])
    dev = start("avr", tmp_path, "--speedup", "4")
    h = RawHost(dev.path)
    try:
        h.hello()
        h.ep.send(payload, items=2)
        h.send(Flush())
        err = h.wait_for(lambda: errors(h, ErrorCode.BAD_COMMAND), what="BAD_COMMAND")[0]
        assert (err.axis, err.value) == (0x98, 6)
        assert h.status().segments_done == 0
    finally:
        h.close()
        dev.stop()
    assert [r for r in _record(dev) if "error" not in r] == []
