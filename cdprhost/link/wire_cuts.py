"""A wire batch made ready for a device that steps ramps from schedule blocks: each ramp
cut in halves along its own profile until the blocks of all its moving axes fit one
payload with the segment (PROTOCOL.md 5.5).

A print's ramps are cut in its plan (:mod:`cdprhost.motion.block_cuts`, by speed, before
the job numbers its segments). This is the same rule for a batch that was never planned:
the step-timing tests and the rate benches, which build their segments by hand and must
send them as the host would, every fast ramp stepping from its block and none from the
device's own stepping of the profile."""

from __future__ import annotations

import numpy as np

from cdprhost.link.segment_feed import wire_schedules
from firmware_protocol.ramp_profile import RAMP_CONSTANT
from firmware_protocol.segment_split import split_segment
from firmware_protocol.segments import (
    SEGMENT_MAX_BYTES,
    SegmentBatch,
    SegmentContext,
    encode_block_for,
)

#: no piece shorter than this many ticks (the AVR's shortest segment, 400 us)
SHORTEST_PIECE_TICKS = 40


def cut_for_blocks(batch: SegmentBatch, payload: int, tol_cycles: float = 16.0) -> SegmentBatch:
    """``batch`` with every ramp whose blocks (one for each moving axis, within
    ``tol_cycles`` of its profile) would not fit ``payload`` bytes with its segment cut
    in halves (:func:`split_segment`), recursively, down to pieces of two shortest
    segments."""
    ctx = SegmentContext()
    out: list[tuple[int, tuple[int, ...], int]] = []

    def fits(t: int, d: tuple[int, ...], c: int) -> bool:
        one = SegmentBatch(np.array([t]), np.array([d]), np.array([c], dtype=np.int16))
        blocks = wire_schedules(one, ctx, tol_cycles, payload)
        moving = [k for k in range(4) if d[k]]
        # a ramp is never predicted (only steady segments are): each moving axis needs its block
        return all((0, k) in blocks for k in moving) and (
            len(encode_block_for(t, d, {k: s for (_, k), s in blocks.items()}, ctx))
            <= payload - SEGMENT_MAX_BYTES
        )

    def add(t: int, d: tuple[int, ...], c: int) -> None:
        if c == RAMP_CONSTANT or t < 2 * SHORTEST_PIECE_TICKS or fits(t, d, c):
            out.append((t, d, c))
            return
        a, b = split_segment(t, d, c, t // 2)
        add(*a)
        add(*b)

    for i in range(len(batch)):
        add(int(batch.ticks[i]), tuple(int(v) for v in batch.deltas[i]), int(batch.ramps[i]))
    return SegmentBatch(
        np.array([p[0] for p in out]),
        np.array([p[1] for p in out], dtype=np.int64),
        np.array([p[2] for p in out], dtype=np.int16),
    )
