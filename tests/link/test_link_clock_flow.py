"""Clock synchronisation and the time watermarks (pure bookkeeping)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cdprhost.link.clock_sync import QUICK_LEAK, ClockSync
from cdprhost.link.flow import FlowReport, TimeFlow, Watermarks
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.device.config import SimConfig
from firmware_protocol.messages import Flag


@given(st.floats(1e3, 1e9), st.integers(0, 2**32 - 1))
def test_the_clock_rate_is_measured_across_wraps(rate, start):
    sync = ClockSync(100_000)
    assert sync.rate() == 100_000  # the nominal clock until measured
    for k in range(60):
        t = k * 0.01
        sync.add(t, int(start + rate * t) & 0xFFFF_FFFF)
    assert sync.rate() == pytest.approx(rate, rel=1e-3)


def test_stale_clock_samples_are_ignored():
    sync = ClockSync(100_000)
    sync.add(0.0, 1000)
    sync.add(0.1, 11_000)
    sync.add(0.11, 5_000)  # an older report, late
    assert sync.rate() == pytest.approx(100_000)


def test_a_simulated_device_at_a_speed_up_is_measured_as_such():
    link = open_embedded(config=SimConfig(speedup=250.0))
    assert link.clock_rate == pytest.approx(250 * 100_000, rel=0.02)


def test_watermarks_refill_from_low_to_high_with_hysteresis():
    flow = TimeFlow(Watermarks(0.5, 1.0))
    rate = 1000.0
    assert flow.room_ticks(0, rate) == 1000  # empty: fill to the high watermark
    assert flow.room_ticks(1000, rate) == 0  # full
    assert flow.room_ticks(700, rate) == 0  # draining, still above the low watermark
    assert flow.room_ticks(500, rate) == 500  # at the low watermark: refill
    assert flow.room_ticks(800, rate) == 200  # refilling until full again
    # a device at rest waits for its start threshold: fill past it whatever the hysteresis
    flow.room_ticks(1000, rate)
    assert flow.room_ticks(900, rate, moving=False, start_ticks=1000) > 100


def test_the_estimate_of_motion_ahead_follows_the_device_clock():
    flow = TimeFlow(Watermarks(0.5, 1.0))
    report = FlowReport(free=10, ack=0, buffered_ticks=100_000, flags=int(Flag.MOVING), t=5.0)
    assert flow.ahead_ticks(report, 5.4, 100_000.0, 0) == pytest.approx(60_000)
    assert flow.ahead_ticks(report, 9.0, 100_000.0, 2000) == 2000  # drained; in flight only
    at_rest = FlowReport(10, 0, 100_000, 0, 5.0)
    assert flow.ahead_ticks(at_rest, 9.0, 100_000.0, 0) == 100_000  # not consumed while at rest
    assert flow.wake_in(60_000, 100_000.0, True) == pytest.approx(0.1)
    assert flow.wake_in(60_000, 100_000.0, False) is None


@pytest.mark.parametrize("low, high", [(0.0, 1.0), (0.5, 0.5), (float("nan"), 1.0), (1, 100)])
def test_bad_watermarks_are_refused(low, high):
    with pytest.raises(ValueError):
        Watermarks(low, high)


def test_a_report_read_late_is_dated_when_it_was_sent():
    """Reports every 10 ms, each 1 ms on the way; one waits 300 ms in the port's buffer (a
    busy host): it is dated when it was sent, not when it was read, so the motion it
    reports is not counted as 300 ms fresher than it is. Prompt ones keep their receipt."""
    sync = ClockSync(100_000)
    for k in range(100):
        sent = sync.add(k * 0.01 + 0.001, k * 1000)
        assert sent == pytest.approx(k * 0.01 + 0.001)
    late = sync.add(1.0 + 0.3, 100 * 1000)  # sent at 1.0
    assert late == pytest.approx(1.001, abs=0.002)
    assert sync.add(1.011, 101 * 1000) == pytest.approx(1.011)  # back to prompt


@given(st.floats(0.0, 2.0), st.floats(0.0005, 0.005))
def test_a_late_reports_date_is_never_later_than_its_receipt(delay, line):
    sync = ClockSync(100_000)
    for k in range(50):
        sync.add(k * 0.02 + line, k * 2000)
    sent = sync.add(1.0 + line + delay, 100_000)
    assert sent <= 1.0 + line + delay
    # the quickest sample 20 ms before it, forgotten by QUICK_LEAK a second since
    forgotten = QUICK_LEAK * (0.02 + delay)
    assert sent == pytest.approx(1.0 + line + min(delay, forgotten), abs=1e-6)
