"""Protocol 3.2: the host counts the device's ring of schedule-block entries (RING) and
sends a block only where the device's rule places it without a wait, so the frames
behind a block are never refused for it (docs/step-engine.md section 8)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cdprhost.link.ring_room import RingReport, RingRoom
from cdprhost.link.wire_cuts import cut_for_blocks
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.device.config import SimConfig
from firmware_protocol.ramp_profile import RAMP_CONSTANT, RAMP_FROM_REST, RAMP_TO_REST
from firmware_protocol.segments import SegmentBatch, peak_step_rates
from firmware_protocol.streams import expected_record


def _ramps(rates: list[int], cycles: int, ticks: int = 4_000) -> SegmentBatch:
    """From rest to ``rates`` and back, one steady segment between, reversing each cycle."""
    d = np.array(rates, dtype=np.int64) * ticks // 100_000
    one = [RAMP_FROM_REST, RAMP_CONSTANT, RAMP_TO_REST]
    codes = np.array(one * cycles, dtype=np.int16)
    share = np.where(codes == RAMP_CONSTANT, 2, 1)
    sign = np.repeat(np.where(np.arange(cycles) % 2 == 0, 1, -1), len(one))
    deltas = (sign * share)[:, None] * (d[None, :] // 2)
    return SegmentBatch(np.full(len(codes), ticks), deltas, codes)


# the AVR's step engine: 26,000 steps/s from its blocks, 8,000 on its own stepping
ENGINE = {"max_step_rate": 26_000, "profile_step_rate": 8_000}


@pytest.mark.parametrize("entries", [128, 64])
def test_ramps_whose_blocks_overfill_the_ring_wait_on_the_host_and_none_is_refused(entries):
    batch = cut_for_blocks(_ramps([12_000, 9_000, 6_000, 800], cycles=10), 120)
    assert len(batch) > 3 * 30  # ramp pieces, each with its blocks
    link = open_embedded(config=SimConfig(**ENGINE, ring_entries=entries))
    try:
        link.queue_segments(batch)
        link.wait_idle()
        dev = link.device
        assert dev.ring is not None and dev.ring.rejects == 0
        assert dev.machine.overflow_rejects == 0
        assert dev.record == expected_record(batch)
        c = link.counters
        assert c.ring_held > 0  # the ring, not the queue, held the host back
        assert c.ring_disagreements == 0 and c.retransmits == 0
    finally:
        link.close()


def test_a_device_without_a_ring_sends_no_ring_and_the_host_counts_none():
    batch = cut_for_blocks(_ramps([12_000, 9_000, 6_000, 800], cycles=2), 120)
    link = open_embedded(config=SimConfig(**ENGINE))
    try:
        link.queue_segments(batch)
        link.wait_idle()
        assert link.device.record == expected_record(batch)
        assert link._core.dev.ring is None and link.counters.ring_held == 0
    finally:
        link.close()


def test_the_host_takes_the_head_only_from_a_report_that_counts_every_block_sent():
    room = RingRoom()
    report = RingReport(entries=128, head=40, tail=10, held=0, ack=3)
    assert room.admit(report, [0, 0, 12]) == 2  # not synced: up to the first block
    room.follow(report, in_flight_items=2)  # frames after its ACK: not every block counted
    assert room.head is None
    room.follow(RingReport(128, 40, 10, held=1, ack=3), 0)  # a frame not queued yet
    assert room.head is None
    room.follow(report, 0)
    assert room.head == 40
    # 12 at 40, 60 at 52 (76 to the end), then 16 to the end and 10 at the start: 30 waits
    assert room.admit(report, [12, 0, 60, 30]) == 3
    assert room.head == 112 and room.held == 1
    room.follow(RingReport(128, 100, 10, 0, 9), 0)  # the device says otherwise: counted
    assert room.disagreements == 1 and room.head == 100
    room.follow(None, 0)  # a new session without RING: nothing known
    assert room.head is None and room.admit(None, [12, 12]) == 2


def test_ring_rides_after_flow_only_in_a_32_session_of_a_device_with_a_ring():
    from firmware_protocol.device.firmware import SimDevice
    from firmware_protocol.message_codec import decode_messages
    from firmware_protocol.messages import Flow, Ring
    from firmware_protocol.segments import SegmentContext

    def kinds(dev: SimDevice, minor: int) -> list[type]:
        dev.session_minor = minor
        return [type(m) for m in decode_messages(dev._flow_payload(), SegmentContext())]

    ring = SimDevice(SimConfig(ring_entries=64))
    assert kinds(ring, 1) == [Flow]  # a 3.1 host never sees RING
    assert kinds(ring, 2) == [Flow, Ring]
    assert kinds(SimDevice(SimConfig()), 2) == [Flow]  # no ring: blocks need no room
    with pytest.raises(ValueError, match="power of two"):
        SimConfig(ring_entries=96)


def test_a_ramp_held_back_for_the_ring_is_fitted_once(monkeypatch):
    """The blocks fitted for segments the ring had no room for yet are kept for the next
    turn (a ramp's fit takes milliseconds in Python): each ramp piece is fitted once."""
    from cdprhost.link import segment_feed

    fitted: list[int] = []
    plan = segment_feed.plan_schedules

    def counted(batch, *args, **kw):
        if len(batch) == 1 and int(batch.ramps[0]) != RAMP_CONSTANT:
            fitted.append(int(batch.ticks[0]))
        return plan(batch, *args, **kw)

    monkeypatch.setattr(segment_feed, "plan_schedules", counted)
    batch = cut_for_blocks(_ramps([12_000, 9_000, 6_000, 800], cycles=4), 120)
    fitted.clear()  # (the cut's own fits)
    monkeypatch.setattr(segment_feed, "FIT_SHARE", 0.0)  # only the ramps that need a block
    link = open_embedded(config=SimConfig(**ENGINE, ring_entries=128))
    try:
        link.queue_segments(batch)
        link.wait_idle()
        assert link.counters.ring_held > 0 and link.device.ring.rejects == 0
        assert link.device.record == expected_record(batch)
    finally:
        link.close()
    peak = peak_step_rates(batch, 100_000).max(axis=1)
    needed = int(np.sum((batch.ramps != RAMP_CONSTANT) & (peak > ENGINE["profile_step_rate"])))
    assert len(fitted) == needed, (len(fitted), needed)


def test_sim_device_with_a_ring_on_a_pty_reports_it_and_the_stream_waits_for_it(tmp_path):
    """`cdprhost sim-device --ring-entries 128`, as the AVR's step engine: a host on its pty
    sees the ring and streams ramps that overfill it without a refusal. At half speed, as
    the AVR's ring test: the ring holds a few tens of ms of these ramps, and at 1x a host
    starved on a loaded PC (three test workers and a busy process on two cores) let the
    queue run dry once; what is checked is the ring's count, not the host's pace."""
    from cdprhost.link.connect import open_link
    from tests.e2e.processes import SimDeviceProcess

    batch = cut_for_blocks(_ramps([12_000, 9_000, 6_000, 800], cycles=4), 120)
    args = ("--speedup", "0.5", "--max-step-rate", "26000", "--profile-step-rate", "8000")
    with SimDeviceProcess(tmp_path, *args, "--ring-entries", "128") as dev:
        link = open_link(dev.path)
        try:
            assert link.ring is not None and link.ring.entries == 128
            link.queue_segments(batch)
            link.wait_idle(60)
            c = link.counters
            assert c.ring_held > 0 and c.naks_received == 0 and c.ring_disagreements == 0, c
        finally:
            link.close()
    record = [json.loads(x) for x in dev.record.read_text().splitlines() if x.strip()]
    assert record == expected_record(batch)
