"""When the device model reports its flow unasked (PROTOCOL.md section 6): an eighth of
its queue freed is reported when it happens, not at the model's next deadline."""

from __future__ import annotations

import pytest

from cdprhost.sim.embedded import open_embedded
from firmware_protocol.streams import demo_stream, expected_record


@pytest.mark.parametrize("baud", [None, 250_000])
def test_a_queue_of_short_segments_is_reported_as_it_frees_and_kept_fed(baud):
    """1-2 ms segments: the device's 128 slots hold about 0.2 s, less than the motion
    between two reports by `flow_ticks`, so only the freed slots' reports can wake the
    host in time (the model noticed them only at its next deadline and ran dry at item
    128, just after it started)."""
    batch = demo_stream(2_000, seed=5, min_ticks=100, max_ticks=200)
    link = open_embedded(baud=baud, timeout_s=5.0)
    try:
        link.queue_segments(batch)
        link.wait_idle()
        assert link.device.record == expected_record(batch)
    finally:
        link.close()
