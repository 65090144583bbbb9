"""A stream's frames stay short on a clean line (issue 29): a device reads a frame only once
it is whole, so a long frame keeps its segments out of the queue while it crosses the wire."""

from __future__ import annotations

from cdprhost.link.segment_feed import STREAM_FRAME_BYTES
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.segments import F_SCHEDULE, SEG_BASE
from firmware_protocol.streams import demo_stream
from tests.link.wire_spy import data_frames


def test_a_clean_stream_cuts_its_frames_at_the_stream_size_while_the_limit_grows():
    link = open_embedded()
    try:
        with data_frames(link) as frames:
            link.queue_segments(demo_stream(3000, seed=2))
            link.wait_idle(timeout=120)
        assert link.progress.segments_done == 3000
        # the line's limit grew past the stream's frames (nothing was lost) ...
        assert link._core.payload_limit > STREAM_FRAME_BYTES
    finally:
        link.close()
    # ... and every frame of segments stayed within them, most of them full; only a
    # segment with its schedule block (the last one's ramp to rest) goes alone in a longer one
    longer = [op for n, op in frames if n > STREAM_FRAME_BYTES]
    assert all(op >= SEG_BASE and op & F_SCHEDULE for op in longer) and len(longer) <= 2
    lengths = sorted(n for n, _ in frames)
    assert lengths[len(lengths) // 2] >= STREAM_FRAME_BYTES - 8
