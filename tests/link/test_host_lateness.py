"""A host that comes late to its refills (a busy print PC, a front end holding the
interpreter) keeps more motion ahead instead of letting the device run dry (flow.py).

The embedded device runs on virtual time, which moves only while the host waits on the
transport; a stall is injected there, deterministically: the device runs on for the
stall's length after a wait the host took while it held back for the low watermark."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from hypothesis import given
from hypothesis import strategies as st

import cdprhost.link.flow as flow_mod
from cdprhost.link.errors import LinkError
from cdprhost.link.flow import (
    LEAD_HALF_LIFE_S,
    LEAD_MARGIN,
    LEAD_MAX_LOW_S,
    TimeFlow,
    Watermarks,
)
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.streams import demo_stream, expected_record

RATE = 100_000.0  # device ticks a host second


def test_a_prompt_host_keeps_the_configured_watermarks():
    flow = TimeFlow(Watermarks(0.5, 1.0))
    t, ahead = 0.0, 1.0 * RATE
    for _ in range(50):  # drains to the low watermark, refills there, exactly on time
        flow.room_ticks(ahead, RATE, now=t)
        t += 0.5
        ahead = 0.5 * RATE
        room = flow.room_ticks(ahead, RATE, now=t)
        assert room == pytest.approx(0.5 * RATE)
        ahead += room
    assert flow.late_worst_s == pytest.approx(0.0)
    assert flow.lead_s(t) == (0.5, 1.0)


def test_a_late_refill_raises_both_watermarks_and_the_raise_decays():
    flow = TimeFlow(Watermarks(0.5, 1.0))
    flow.room_ticks(1.0 * RATE, RATE, now=0.0)  # full: waits for the low watermark
    room = flow.room_ticks(0.2 * RATE, RATE, now=0.8)  # came 0.3 s after it was reached
    assert flow.late_worst_s == pytest.approx(0.3)
    low, high = flow.lead_s(0.8)
    assert (low, high) == pytest.approx((0.9, 1.4))  # three times the lateness, the gap kept
    assert room == pytest.approx(1.2 * RATE)  # filled to the raised high watermark
    assert flow.wake_in(1.4 * RATE, RATE, True, 0.8) == pytest.approx(0.5)
    assert flow.lead_s(0.8 + 2 * LEAD_HALF_LIFE_S)[0] == pytest.approx(0.5)  # back to the floor
    assert flow.lead_s(0.8 + 0.1 * LEAD_HALF_LIFE_S)[0] > 0.8


def test_the_raise_is_capped():
    flow = TimeFlow(Watermarks(0.5, 1.0))
    flow.room_ticks(1.0 * RATE, RATE, now=0.0)
    flow.room_ticks(0.0, RATE, now=30.0)  # a host gone for half a minute
    assert flow.lead_s(30.0) == (LEAD_MAX_LOW_S, LEAD_MAX_LOW_S + 0.5)


def test_a_host_held_by_the_device_or_already_topping_up_is_not_late():
    flow = TimeFlow(Watermarks(0.5, 1.0))
    flow.room_ticks(1.0 * RATE, RATE, now=0.0)
    flow.held_by_device()  # no slot free meanwhile: the device, not the host, held it back
    flow.room_ticks(0.1 * RATE, RATE, now=0.9)
    flow.room_ticks(0.05 * RATE, RATE, now=1.0)  # topping up (filling) is not a new refill
    flow.room_ticks(0.2 * RATE, RATE, moving=False, now=2.0)  # at rest: nothing drains
    assert flow.late_worst_s == 0.0 and flow.lead_s(2.0) == (0.5, 1.0)


@given(st.lists(st.floats(0.0, 2.0), min_size=1, max_size=30))
def test_the_low_watermark_covers_a_margin_over_the_recent_lateness(stalls):
    """Refills each late by a stall: the low watermark in force afterwards covers
    LEAD_MARGIN times the worst of them, decayed, within the floor and the cap (a stall
    longer than the lead runs the device dry: still measured, from when it fell due)."""
    flow = TimeFlow(Watermarks(0.5, 1.0))
    t, at = 0.0, []
    for stall in stalls:
        low, high = flow.lead_s(t)
        flow.room_ticks(high * RATE, RATE, now=t)  # full
        t += high - low + stall  # drained to the low watermark, and the stall on top
        flow.room_ticks(max(0.0, low - stall) * RATE, RATE, now=t)
        at.append(t)
    decayed = [s * 0.5 ** ((t - when) / LEAD_HALF_LIFE_S) for s, when in zip(stalls, at)]
    low, high = flow.lead_s(t)
    assert flow.late_worst_s == pytest.approx(max(stalls), abs=1e-9)
    assert low == pytest.approx(max(0.5, min(LEAD_MAX_LOW_S, LEAD_MARGIN * max(decayed))), rel=1e-6)
    assert high - low == pytest.approx(0.5)


def _late_host(link, stalls: Iterator[float]) -> None:
    """The host is held up by the next of ``stalls`` whenever a wait of its reaches the
    moment a refill falls due: the device runs on meanwhile, the host sees nothing."""
    bench, flow = link._t, link._core.flow
    read = bench.read
    met: set[int] = set()  # the refills already held up (one stall each)

    def late_read(timeout: float) -> bytes:
        due = flow.refill_due
        data = read(timeout)
        if timeout > 0 and due is not None and bench.t >= due and flow.refills not in met:
            met.add(flow.refills)
            bench.run_until(bench.t + next(stalls))
        return data

    bench.read = late_read


def _stream_with_stalls(first: float, later: float) -> object:
    # 15-25 ms segments, 30 s: the device's 128 slots hold more than the watermarks ask
    batch = demo_stream(1_500, seed=5, min_ticks=1500, max_ticks=2500)
    link = open_embedded(baud=None, timeout_s=5.0)
    stalls = iter([first] * 4 + [later] * 1000)
    _late_host(link, stalls)
    link.queue_segments(batch)
    link.wait_idle()
    assert link.device.record == expected_record(batch)
    return link


def test_a_host_late_by_more_than_the_low_watermark_keeps_the_device_fed():
    """Late by 0.35 s at first, then by 0.6 s (more than the configured 0.5 s low
    watermark): the first lateness raised the low watermark to 1.05 s, so the longer stalls
    leave the device 0.45 s of motion, and every segment executes."""
    link = _stream_with_stalls(0.35, 0.6)
    c = link.counters
    assert c.host_late_worst_s == pytest.approx(0.6, abs=0.03)
    assert c.lead_low_max_s == pytest.approx(3 * 0.6, abs=0.09)  # covering the 0.6 s ones


def test_with_the_configured_watermarks_alone_the_same_host_runs_the_device_dry(monkeypatch):
    """The same stream and stalls with the lead frozen at the configured watermarks: the
    device underruns (what the test above guards against)."""
    monkeypatch.setattr(flow_mod, "LEAD_MARGIN", 0.0)
    with pytest.raises(LinkError):
        _stream_with_stalls(0.35, 0.6)
