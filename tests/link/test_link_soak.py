"""Soak: 100,000 segments through a damaging link execute exactly as on a clean one."""

from __future__ import annotations

import pytest

from cdprhost.sim.embedded import open_embedded
from firmware_protocol.streams import demo_stream, expected_record


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_soak_100k_segments_with_corruption_and_drops():
    batch = demo_stream(100_000, seed=21)
    link = open_embedded(faults="corrupt=0.001,drop=0.001,seed=21")
    segs = link.queue_segments(batch)
    link.wait_idle()
    record = link.device.record
    # the clean-link record is fully determined by the segments (checked below on a clean run)
    assert record == expected_record(batch)  # zero lost, zero duplicated, same order and times
    assert segs == range(1, 100_001)
    c = link.counters
    assert c.retransmits > 100 and c.bad_frames > 100  # the faults did bite
    dev = link.device
    assert dev.machine.overflow_rejects == 0 and dev.endpoint.bad_frames > 100


def test_clean_link_record_is_the_expected_record():
    batch = demo_stream(20_000, seed=21)
    link = open_embedded()
    link.queue_segments(batch)
    link.wait_idle()
    assert link.device.record == expected_record(batch)
    assert link.counters.retransmits == 0 and link.counters.bad_frames == 0


def test_duplicates_latency_and_jitter_change_nothing():
    batch = demo_stream(5_000, seed=3)
    link = open_embedded(faults="corrupt=0.002,drop=0.002,dup=0.01,latency_ms=4,jitter_ms=3,seed=9")
    link.queue_segments(batch)
    link.wait_idle()
    assert link.device.record == expected_record(batch)
    assert link.device.endpoint.counters.duplicates > 0
