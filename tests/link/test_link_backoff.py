"""The host backs off on a silent device (PROTOCOL.md section 2, issue 32): the 25 ms floor
doubling to the ceiling, one probe frame at a time, about ten resends in the first 2 s of a
frozen device (it was 139 in 1.5 s), fewer on a clean fast path (500 ms floor)."""

from __future__ import annotations

import pytest

from cdprhost.link.tuning import CLEAN_RTO_FLOOR_S, RTO_FAST, RTO_FLOOR_S, RTO_MAX_BACKOFF
from firmware_protocol.endpoint import Endpoint


def _frozen(floor: float, seconds: float = 2.0) -> list[float]:
    """When the host resends to a device that stopped answering with ten frames in flight."""
    ep = Endpoint(
        window=32,
        rto_initial=0.05,  # as the link's (a quarter of its 2 s timeout, at most 50 ms)
        rto_floor=RTO_FLOOR_S,
        rto_ceiling=0.25,
        rto_max_backoff=RTO_MAX_BACKOFF,
        rto_fast=RTO_FAST,
        stale_after=0.02,
        renak=True,
    )
    ep._fast_path()  # a pty or USB: acknowledgements proved the path fast
    ep.sender.rto.floor = floor
    ep.sender.rto.ceiling = max(0.25, floor)  # as LinkCore raises it with the clean floor
    ep.sender.heard(-0.01)  # the last byte from the device came before the frames left
    for _ in range(10):
        ep.send(b"x" * 40, items=1)
    ep.flush(0.0)
    t, marks = 0.0, []
    while t < seconds:
        t += 0.001
        n = ep.retransmits
        ep.flush(t)
        marks += [t] * (ep.retransmits - n)
    return marks


@pytest.mark.parametrize(("floor", "most"), [(RTO_FLOOR_S, 11), (CLEAN_RTO_FLOOR_S, 4)])
def test_a_frozen_device_sees_few_resends_further_and_further_apart(floor, most):
    marks = _frozen(floor)
    assert 3 <= len(marks) <= most, marks
    gaps = [b - a for a, b in zip(marks, marks[1:], strict=False)]
    assert gaps == sorted(gaps, key=lambda g: round(g, 2))  # never closer together
    assert marks[0] >= floor - 1e-9  # nothing before the floor


def test_a_clean_fast_path_that_answers_late_is_not_retransmitted_to():
    """A pty on a loaded machine: nothing is lost, answers come up to 100 ms late. Each
    late answer cost resends (129 in 4000 segments: a report not yet acknowledging a frame
    resent it after 20 ms); now a timeout there makes the link wait longer instead."""
    from cdprhost.sim.embedded import open_embedded
    from firmware_protocol.streams import demo_stream, expected_record

    batch = demo_stream(4000, seed=3)
    link = open_embedded(faults="latency_ms=2,jitter_ms=100,seed=9", baud=None)
    try:
        link._core.ep._fast_path()  # as a pty's first early acknowledgement does
        link.queue_segments(batch)
        link.wait_idle()
        assert link.device.record == expected_record(batch)
        assert link.counters.retransmits <= 8, link.counters
    finally:
        link.close()


@pytest.mark.parametrize(("jitter_ms", "seed"), [(200, 9), (200, 10), (250, 9), (250, 10)])
def test_a_clean_path_waits_for_an_ack_up_to_a_quarter_second_late(jitter_ms, seed):
    """Answers up to 250 ms late on a path that loses nothing (a device process descheduled
    on a loaded machine: the cup at 1x resent twice after 221 and 400 ms of silence): no
    frame is resent while streaming (it was 1 to 8 in 3000 segments with the 150 ms floor);
    the device holds motion meanwhile, and the record is exact."""
    from cdprhost.sim.embedded import open_embedded
    from firmware_protocol.streams import demo_stream, expected_record

    batch = demo_stream(3000, seed=3)
    link = open_embedded(faults=f"latency_ms=2,jitter_ms={jitter_ms},seed={seed}", baud=None)
    try:
        link._core.ep._fast_path()
        before = link.counters.retransmits  # (the set-up's, before the path was known fast)
        link.queue_segments(batch)
        link.wait_idle()
        assert link.device.record == expected_record(batch)
        assert link.counters.retransmits == before, link.counters
    finally:
        link.close()


def test_each_resend_is_logged_with_its_cause(caplog):
    """When and why the host resent: a timer that expired (the answers here come 150 ms
    late, the first timeout is 50 ms), with the timing it went by; at INFO on a clean line,
    where each resend is news (a noisy line's are DEBUG: expected)."""
    import logging

    from cdprhost.sim.embedded import open_embedded

    with caplog.at_level(logging.INFO, logger="cdprhost.link.host_link"):
        link = open_embedded(faults="latency_ms=150", baud=None)
        link.close()
    said = [r for r in caplog.records if "resent" in r.getMessage()]
    assert said and link.counters.retransmits > 0
    first = said[0]
    assert first.levelno == logging.INFO
    assert "timeout" in first.getMessage() and "last byte from the device" in first.getMessage()
