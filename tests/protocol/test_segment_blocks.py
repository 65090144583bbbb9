"""Protocol 3.0: segments with their schedule blocks (PROTOCOL.md 5.5) through the
vectorised encoder, the scalar one and the decoder; what the host puts on the wire."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cdprhost.link.segment_feed import SEGMENT_MAX_BYTES, wire_schedules
from firmware_protocol.message_codec import MessageError, decode_messages, encode_messages
from firmware_protocol.messages import Segment
from firmware_protocol.schedule_fit import plan_schedules
from firmware_protocol.segments import (
    F_SCHEDULE,
    SegmentBatch,
    SegmentContext,
    decode_segment,
    encode_one_segment,
    encode_segments,
)
from firmware_protocol.step_schedule import AxisSchedule, Chunk, device_edges, ideal_edges

CPT = 160

segment = st.tuples(
    st.integers(20, 5000),  # ticks
    st.lists(st.integers(-60, 60), min_size=4, max_size=4),
    st.sampled_from([-1, 0, 40, 128, 200, 255]),
)


def _batch(segs) -> SegmentBatch:
    return SegmentBatch(
        np.array([t for t, _, _ in segs]),
        np.array([d for _, d, _ in segs]),
        np.array([r for _, _, r in segs], dtype=np.int16),
    )


@settings(max_examples=60, deadline=None)
@given(st.lists(segment, min_size=1, max_size=12))
def test_blocks_round_trip_and_both_encoders_agree(segs):
    batch = _batch(segs)
    planned = plan_schedules(batch, CPT, 16.0)
    data, offsets = encode_segments(batch, SegmentContext(), planned)
    scalar = SegmentContext()
    one = b"".join(
        encode_one_segment(
            int(batch.ticks[i]),
            tuple(int(v) for v in batch.deltas[i]),  # type: ignore[arg-type]
            int(batch.ramps[i]),
            scalar,
            {k: s for (j, k), s in planned.items() if j == i},
        )
        for i in range(len(batch))
    )
    assert data == one
    ctx, pos = SegmentContext(), 0
    for i in range(len(batch)):
        assert pos == offsets[i]
        assert bool(data[pos] & F_SCHEDULE) == any(j == i for j, _ in planned)
        ticks, deltas, ramp, scheds, pos = decode_segment(data, pos, ctx)
        assert (ticks, deltas, ramp) == (
            int(batch.ticks[i]),
            tuple(int(v) for v in batch.deltas[i]),
            int(batch.ramps[i]),
        )
        assert scheds == {k: s for (j, k), s in planned.items() if j == i}
        for k, sched in scheds.items():  # what the device runs: within 16 cycles
            ideal = ideal_edges(deltas[k], ticks, ramp, CPT)
            assert np.abs(device_edges(sched) - ideal).max() <= 16
    assert pos == len(data)


def test_a_segment_message_carries_its_block_through_the_codec():
    sched = AxisSchedule(3000, (Chunk(2, 9000, 40), Chunk(3, 9500, -7)))
    msg = Segment(400, (5, 0, 0, 0), 0, ((0, sched),))
    payload = encode_messages([msg], SegmentContext())
    assert decode_messages(payload, SegmentContext()) == [msg]
    assert "schedules=" in repr(msg) and "schedules" not in repr(Segment(400, (5, 0, 0, 0)))
    # a block cut short makes the payload malformed (BAD_COMMAND), not a short segment
    with pytest.raises(MessageError, match="schedule block"):
        decode_messages(payload[:-1], SegmentContext())


def test_the_host_sends_blocks_that_fit_a_payload_and_leaves_the_rest():
    # a ramp to rest of 4 x 10 steps: the four blocks do not fit 120 bytes together
    batch = SegmentBatch(np.array([30_000, 30_000]), np.array([[10] * 4, [3, 0, 0, 0]]))
    batch = SegmentBatch(batch.ticks, batch.deltas, np.array([255, -1], dtype=np.int16))
    ctx = SegmentContext()
    planned = plan_schedules(batch, CPT, 16.0)
    assert {k for i, k in planned if i == 0} == {0, 1, 2, 3}
    sent = wire_schedules(batch, ctx, 16.0, 120)
    data, offsets = encode_segments(batch, SegmentContext(), sent)
    assert 0 < len(sent) < 4 and all(i == 0 for i, _ in sent)
    assert offsets[1] - offsets[0] <= 120  # the segment and its block: one payload
    assert offsets[1] - offsets[0] > 120 - SEGMENT_MAX_BYTES - 60  # a block went
    assert wire_schedules(batch, ctx, 16.0, 248).keys() == planned.keys()  # room for all
