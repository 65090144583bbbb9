"""The schedule block's wire form: round trip, and what a device refuses."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol.schedule_block import (
    MAX_CHUNKS,
    ScheduleBlockError,
    decode_block,
    encode_block,
)
from firmware_protocol.schedule_fit import fit_axis
from firmware_protocol.step_schedule import AxisSchedule, Chunk, ideal_edges, reciprocal_table

CPT = 160
TABLE = reciprocal_table(CPT)


def segment_with_schedules():
    """A segment's deltas, duration, ramp and a fitted schedule for each moving axis."""

    def build(ticks, code, shares, signs, tol):
        r = 0.5 if code < 0 else code / 255
        most = int(100_000 * ticks / 100_000 / max(2 * r, 2 - 2 * r))
        deltas = [sign * int(share * most) for share, sign in zip(shares, signs)]
        scheds = {
            k: fit_axis(ideal_edges(d, ticks, code, CPT), tol) for k, d in enumerate(deltas) if d
        }
        return deltas, ticks, scheds

    return st.builds(
        build,
        st.integers(40, 12_000),
        st.integers(-1, 255),
        st.lists(st.floats(0.0, 1.0), min_size=4, max_size=4),
        st.lists(st.sampled_from([1, -1]), min_size=4, max_size=4),
        st.sampled_from([16.0, 48.0]),
    ).filter(
        # a long ramp from rest to a high rate can take more chunks than a block carries:
        # the feed splits such segments (docs/step-engine.md); what a block carries is tested
        lambda seg: bool(seg[2]) and all(len(s.chunks) <= MAX_CHUNKS for s in seg[2].values())
    )


@settings(max_examples=120, deadline=None)
@given(segment_with_schedules())
def test_a_block_decodes_to_the_schedules_it_was_made_of(seg):
    deltas, ticks, scheds = seg
    data = encode_block(deltas, ticks, scheds, TABLE) + b"\x99"  # the next item's byte
    got, pos = decode_block(data, 0, deltas, ticks, TABLE)
    assert got == scheds
    assert pos == len(data) - 1


@settings(max_examples=300, deadline=None)
@given(st.binary(min_size=0, max_size=40), st.lists(st.integers(-600, 600), min_size=4, max_size=4))
def test_any_bytes_either_are_refused_or_decode_to_counts_that_add_up(data, deltas):
    try:
        got, pos = decode_block(data, 0, deltas, 1000, TABLE)
    except ScheduleBlockError:
        return
    assert pos <= len(data)
    for axis, sched in got.items():
        assert sched.count == abs(deltas[axis])
        assert sched.lead >= 0 and all(c.interval >= 1 and c.count >= 1 for c in sched.chunks)


def _one(steps=10, ticks=1000):
    ideal = ideal_edges(steps, ticks, 0, CPT)
    return fit_axis(ideal, 16.0)


def test_what_the_block_refuses():
    deltas = [10, 0, 0, 0]
    good = encode_block(deltas, 1000, {0: _one()}, TABLE)
    with pytest.raises(ScheduleBlockError, match="mask 0x10"):
        decode_block(b"\x10" + good[1:], 0, deltas, 1000, TABLE)
    with pytest.raises(ScheduleBlockError, match="at least one"):
        decode_block(b"\x00", 0, deltas, 1000, TABLE)
    with pytest.raises(ScheduleBlockError, match="axis 1 has a schedule but no steps"):
        decode_block(b"\x03" + good[1:] + good[1:], 0, deltas, 1000, TABLE)
    with pytest.raises(ScheduleBlockError, match="truncated"):
        decode_block(good[:-1], 0, deltas, 1000, TABLE)
    # a further chunk that takes every step leaves the first none
    greedy = AxisSchedule(0, (Chunk(1, 100_000, 0), Chunk(10, 100_000, 0)))
    data = bytearray(encode_block([11, 0, 0, 0], 1000, {0: greedy}, TABLE))
    with pytest.raises(ScheduleBlockError, match="count 10 further steps of 10"):
        decode_block(bytes(data), 0, deltas, 1000, TABLE)


def test_what_the_encoder_refuses():
    with pytest.raises(ScheduleBlockError, match="count 10 steps of 12"):
        encode_block([12, 0, 0, 0], 1000, {0: _one()}, TABLE)
    with pytest.raises(ScheduleBlockError, match="0..3 only"):
        encode_block([10, 0, 0, 0], 1000, {4: _one()}, TABLE)
    with pytest.raises(ScheduleBlockError, match="at least one"):
        encode_block([10, 0, 0, 0], 1000, {}, TABLE)
    many = AxisSchedule(0, tuple(Chunk(1, 1000, 0) for _ in range(33)))
    with pytest.raises(ScheduleBlockError, match="33 chunks"):
        encode_block([33, 0, 0, 0], 1000, {0: many}, TABLE)


def test_a_predicted_first_interval_costs_one_byte():
    # a constant-speed axis the device would predict, sent anyway: the interval and the
    # first edge are zero corrections
    ideal = ideal_edges(300, 3000, -1, CPT)
    data = encode_block([300, 0, 0, 0], 3000, {0: fit_axis(ideal, 16.0)}, TABLE)
    assert len(data) == 1 + 4  # mask, lead, interval, add, more: one byte each
    assert np.array_equal(data[1:], b"\x00\x00\x00\x00")
