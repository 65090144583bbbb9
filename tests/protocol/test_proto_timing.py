"""The device model in time: start rule (never backdated), FLUSH, flow reports by time,
the host watchdog, a queue sized in time, a record with no object per segment."""

from __future__ import annotations

import gc

import pytest

from cdprhost.link.host_link import HostLink
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.device.config import SimConfig
from firmware_protocol.device.firmware import SimDevice
from firmware_protocol.device.harness import VirtualBench
from firmware_protocol.device.machine import DeviceMachine
from firmware_protocol.device.queue_items import SEG, make_item
from firmware_protocol.device.record import SegmentRecord, read_record
from firmware_protocol.messages import ErrorCode, Flag, SetHeater
from firmware_protocol.ramp_profile import RAMP_CONSTANT, RAMP_TO_REST
from firmware_protocol.segments import SegmentBatch
from firmware_protocol.streams import demo_stream, expected_record


def seg(n: int, T: float, ticks: int = 10_000, ramp: int = RAMP_CONSTANT, d: int = 10):
    return make_item(SEG, n, T, seg=n, ticks=ticks, deltas=(d, 0, 0, 0), ramp=ramp)


def machine(**cfg) -> DeviceMachine:
    m = DeviceMachine(SimConfig(**cfg), SegmentRecord())
    m.start_ticks = 50_000  # 0.5 s
    return m


def test_a_deferred_start_is_dated_when_its_data_arrived_not_earlier():
    m = machine()
    m.enqueue(seg(1, 0.0, ramp=RAMP_TO_REST), 0.0)  # a whole block: starts at once
    m.advance(0.0)
    assert m.cur_start == 0.0
    m.advance(5.0)  # done at 0.1 s; then idle
    assert m.current is None and m.t_free == pytest.approx(0.1)
    for k, t in enumerate((5.0, 5.5, 6.0), start=2):  # a block arriving in pieces
        m.items_received += 1
        m.enqueue(seg(k, t), t)
        m.advance(t)
        assert m.current is None  # 0.1, 0.2, 0.3 s queued: below the 0.5 s threshold
    m.items_received += 2
    m.enqueue(seg(5, 7.0), 7.0)
    m.enqueue(seg(6, 7.0, ramp=RAMP_TO_REST), 7.0)  # now the block is whole
    m.advance(7.0)
    assert m.cur_start == 7.0  # not 0.1 (when the machine became free) nor 5.0


def test_the_start_threshold_starts_motion_at_the_arrival_that_reaches_it():
    m = machine()
    for k in range(1, 6):
        m.items_received += 1
        m.enqueue(seg(k, k * 1.0), k * 1.0)
        m.advance(k * 1.0)
    assert m.current is not None and m.cur_start == 5.0  # 5 x 0.1 s = the threshold


def test_flush_starts_what_is_queued_and_only_that():
    m = machine()
    m.items_received += 1
    m.enqueue(seg(1, 1.0), 1.0)
    m.advance(1.0)
    assert m.current is None
    m.flush(2.0)
    m.advance(2.0)
    assert m.current is not None and m.cur_start == 2.0
    m.advance(3.0)  # it ended moving with nothing behind: underrun
    assert m.fault == ErrorCode.UNDERRUN
    m.clear_fault()
    m.items_received += 1
    m.enqueue(seg(2, 4.0), 4.0)  # a later block is not covered by the old FLUSH
    m.advance(4.0)
    assert m.current is None


def test_the_queue_is_sized_in_time():
    assert SimConfig().slots == 128
    assert SimConfig(speedup=50).slots == 6400
    assert SimConfig(speedup=1000).slots == 65535  # a u16 on the wire
    assert SimConfig(speedup=0.5).slots == 128
    with pytest.raises(ValueError):
        SimConfig(speedup=float("nan"))


def test_flow_is_reported_by_time_while_moving():
    link = open_embedded()
    dev = link.device
    flows = []
    handle = link._dev.handle

    def spy(inc, now):
        before = link._dev.flows
        handle(inc, now)
        if link._dev.flows > before:
            flows.append(now)

    link._dev.handle = spy  # type: ignore[method-assign]
    link.queue_segments(demo_stream(400, seed=3))
    link.wait_idle()
    moving = [b - a for a, b in zip(flows, flows[1:])]
    interval = dev.flow_ticks / dev.config.clock_hz
    assert dev.flow_ticks > 0 and max(moving) <= interval * 1.05 + 0.06


def test_the_watchdog_stops_motion_and_heaters_when_the_host_goes_quiet():
    link = open_embedded()
    dev = link.device
    link.send(SetHeater(0, 2000))
    link.queue_segments(SegmentBatch([800_000], [[4000, 0, 0, 0]], [RAMP_TO_REST]))  # 8 s
    link.poll(0.2)
    assert dev.machine.flags() & Flag.MOVING
    bench = link._t
    t = bench.now()
    bench.run_until(t + 1.0)  # the host says nothing for 1 s: still fine
    assert not dev.machine.fault
    bench.run_until(t + 2.5)  # 2.5 s: the 2 s watchdog has tripped
    mc = dev.machine
    assert mc.fault == ErrorCode.WATCHDOG and mc.last_error == ErrorCode.WATCHDOG
    assert mc.heaters[0].target == 0 and mc.enabled_mask  # heaters off, motors held
    assert not mc.queue and mc.current is None
    assert dev.record[-1].get("error") == "watchdog"  # stopped mid-segment, recorded
    assert 0 < dev.record[-1]["steps"][0] < 4000
    assert mc.segments_done == 0  # the cut segment is not counted as executed


def test_keep_alives_hold_an_idle_session_with_heaters_on():
    link = open_embedded()
    link.send(SetHeater(0, 2000))
    link.poll(10.0)  # the host is idle but pumping: keep-alives go out
    assert not link.device.machine.fault
    assert link.device.machine.heaters[0].target == 200


def test_the_record_is_compact_and_streamed_to_its_file(tmp_path):
    path = tmp_path / "record.jsonl"
    dev = SimDevice(record_path=path)
    link = HostLink(VirtualBench(dev), device=dev)
    link.handshake()
    batch = demo_stream(20_000, seed=5)
    gc.collect()
    before = len(gc.get_objects())
    link.queue_segments(batch)
    link.wait_idle()
    gc.collect()
    assert len(gc.get_objects()) - before < 2_000  # not one object per executed segment
    dev.close()
    want = expected_record(batch)
    assert read_record(path) == want and dev.record == want
    assert dev.record.steps(last=3).tolist() == [r["steps"] for r in want[-3:]]


def test_motion_that_is_not_a_whole_block_waits_for_the_host():
    link = open_embedded()
    dev = link.device
    link.queue_segments(SegmentBatch([2000], [[100, 0, 0, 0]], [0]))  # ends moving
    link.poll(0.5)
    assert dev.record == [] and dev.machine.current is None  # never started: would underrun
    link.queue_segments(SegmentBatch([2000], [[100, 0, 0, 0]], [RAMP_TO_REST]))
    link.wait_idle(5)
    assert [r["steps"][0] for r in dev.record] == [100, 200]


def test_a_record_with_keep_holds_only_the_newest_and_streams_all(tmp_path):
    path = tmp_path / "rec.jsonl"
    rec = SegmentRecord(path, keep=8)
    for seq in range(1, 101):
        rec.append(seq, [seq, 2 * seq, 3 * seq, 0], 100 * seq)
        assert len(rec) <= 8 + 8 // 8
    rec.close()
    assert rec.dropped + len(rec) == 100
    assert rec[-1]["seq"] == 100 and rec[0]["seq"] == rec.dropped + 1
    assert rec.steps(last=2).tolist() == [[99, 198, 297, 0], [100, 200, 300, 0]]
    assert [e["seq"] for e in read_record(path)] == list(range(1, 101))
