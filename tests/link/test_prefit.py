"""While the device has no room (its ring of block entries, its slots, its window), the
feed fits the blocks of the next ramps that must carry one, so the send the next report
allows only encodes them: the AVR engine's ring of fast ramps holds about 30 ms, and a
send that fitted four blocks first took 5 ms idle and 18 ms on a loaded PC
(docs/step-engine.md section 11)."""

from __future__ import annotations

import cdprhost.link.segment_feed as segment_feed
from cdprhost.link.segment_feed import SegmentFeed
from cdprhost.link.wire_cuts import cut_for_blocks
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.device.config import SimConfig
from firmware_protocol.ramp_profile import RAMP_CONSTANT
from firmware_protocol.streams import expected_record
from tests.link.test_ring_credit import ENGINE, _ramps


def _stream(monkeypatch, prefit: bool) -> tuple[int, int]:
    """Ramps that overfill a ring of 64 entries: (ramps fitted inside a send, while waiting)."""
    batch = cut_for_blocks(_ramps([12_000, 9_000, 6_000, 800], cycles=10), 120)
    where = {"send": 0, "wait": 0}
    state = {"waiting": False}
    real_fit, real_prefit = segment_feed.plan_schedules, SegmentFeed._prefit

    def fit(some, *args, **kwargs):
        where["wait" if state["waiting"] else "send"] += int((some.ramps != RAMP_CONSTANT).sum())
        return real_fit(some, *args, **kwargs)

    def waiting_prefit(self, *args):
        state["waiting"] = True
        try:
            real_prefit(self, *args)
        finally:
            state["waiting"] = False

    monkeypatch.setattr(segment_feed, "plan_schedules", fit)
    monkeypatch.setattr(SegmentFeed, "_prefit", waiting_prefit if prefit else lambda *a: None)
    link = open_embedded(config=SimConfig(**ENGINE, ring_entries=64))
    try:
        link.queue_segments(batch)
        link.wait_idle()
        dev = link.device
        assert dev.record == expected_record(batch)
        assert dev.ring is not None and dev.ring.rejects == 0
        assert link.counters.ring_held > 0  # the ring held the host back: it waited
    finally:
        link.close()
    return where["send"], where["wait"]


def test_the_ramps_blocks_are_fitted_while_the_feed_waits_for_ring_room(monkeypatch):
    in_send, in_wait = _stream(monkeypatch, prefit=True)
    assert in_wait > 2 * in_send, (in_send, in_wait)


def test_without_the_waits_work_every_block_is_fitted_by_its_send(monkeypatch):
    in_send, in_wait = _stream(monkeypatch, prefit=False)
    assert in_wait == 0 and in_send > 0
