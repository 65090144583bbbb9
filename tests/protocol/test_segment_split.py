"""Segments cut along their profile so that every schedule fits a block."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol.ramp_profile import RAMP_CONSTANT, RAMP_FROM_REST, RAMP_TO_REST, step_times
from firmware_protocol.schedule_block import MAX_CHUNKS, encode_block
from firmware_protocol.segment_split import fit_for_blocks, split_segment
from firmware_protocol.segments import SegmentBatch
from firmware_protocol.step_schedule import check_segment, reciprocal_table

CPT = 160
TABLE = reciprocal_table(CPT)


@settings(max_examples=200, deadline=None)
@given(
    st.integers(2, 20_000),
    st.lists(st.integers(-3000, 3000), min_size=4, max_size=4),
    st.integers(-1, 255),
    st.floats(0.01, 0.99),
)
def test_the_pieces_keep_the_steps_the_time_and_the_ends_of_the_ramp(ticks, deltas, code, where):
    at = min(ticks - 1, max(1, int(ticks * where)))
    (t1, d1, c1), (t2, d2, c2) = split_segment(ticks, tuple(deltas), code, at)
    assert t1 + t2 == ticks and t1 == at
    assert [a + b for a, b in zip(d1, d2)] == deltas
    assert all(a * d >= 0 and b * d >= 0 for a, b, d in zip(d1, d2, deltas))  # no reversal
    if code == RAMP_CONSTANT:
        assert c1 == c2 == RAMP_CONSTANT
    if code == RAMP_FROM_REST:
        assert c1 == RAMP_FROM_REST
    if code == RAMP_TO_REST:
        assert c2 == RAMP_TO_REST


def test_the_pieces_step_where_the_segment_would_have():
    # a ramp from rest: the pieces' edges, end to end, lie within a step interval of the
    # whole segment's (the cut is a whole step, the ramp codes are 1/255 steps)
    ticks, n = 11_000, 2000
    (t1, d1, c1), (t2, d2, c2) = split_segment(ticks, (n, 0, 0, 0), RAMP_FROM_REST, 5500)
    whole = step_times(n, ticks, RAMP_FROM_REST)
    pieces = np.concatenate([step_times(d1[0], t1, c1), t1 + step_times(d2[0], t2, c2)])
    interval = np.gradient(whole)
    assert len(pieces) == n
    assert np.all(np.abs(pieces - whole) <= interval)


def test_a_long_ramp_from_rest_is_cut_until_every_block_fits():
    # from rest to 100,000 steps/s over 5,000 steps: 47 chunks at 1 us in one piece
    batch = SegmentBatch(
        np.array([10_000, 2000]),
        np.array([[0, 0, 0, 5000], [10, 0, 0, 1000]]),
        np.array([RAMP_FROM_REST, RAMP_TO_REST], dtype=np.int16),
    )
    cut, explicit = fit_for_blocks(batch, CPT, 16.0, TABLE)
    assert len(cut) > 2
    assert cut.ticks.sum() == batch.ticks.sum()
    assert np.array_equal(cut.deltas.sum(axis=0), batch.deltas.sum(axis=0))
    assert cut.ramps[0] == RAMP_FROM_REST and cut.ramps[-1] == RAMP_TO_REST
    assert all(len(s.chunks) <= MAX_CHUNKS for s in explicit.values())
    for i in range(len(cut)):
        scheds = {k: s for (j, k), s in explicit.items() if j == i}
        assert (
            check_segment(
                cut.deltas[i], int(cut.ticks[i]), int(cut.ramps[i]), scheds, CPT, 16.0, TABLE
            )
            <= 16.0
        )
        encode_block(cut.deltas[i].tolist(), int(cut.ticks[i]), scheds, TABLE)


def test_a_batch_that_fits_is_returned_as_it_is():
    batch = SegmentBatch(np.array([3000]), np.array([[300, 20, 0, 1]]), np.array([-1]))
    cut, explicit = fit_for_blocks(batch, CPT, 16.0, TABLE)
    assert cut is batch and explicit == {}


def test_a_cut_outside_the_segment_is_refused():
    with pytest.raises(ValueError, match="1..99"):
        split_segment(100, (1, 0, 0, 0), RAMP_CONSTANT, 100)
