"""A fast path (a pty, native USB) that is noisy or silent (issues 30 and 32): the timeout
backs off only while the peer is silent, and then resends only its oldest frame; a gap
that stays open draws another NAK; frames may go twice on a line that loses half of them."""

from __future__ import annotations

from firmware_protocol.endpoint import Endpoint
from firmware_protocol.framing import Kind, encode_frame
from firmware_protocol.reliability import RtoEstimator, Sender


def fast_endpoint() -> Endpoint:
    """The host's endpoint once an acknowledgement proved the path faster than its baud."""
    a = Endpoint(
        window=32,
        rto_initial=0.05,
        rto_floor=0.025,
        rto_ceiling=0.25,
        rto_max_backoff=8,
        byte_time=10 / 250_000,
        rto_fast=(0.025, 8),
    )
    a.send(b"?")
    a.flush(0.0)
    a.feed(encode_frame(Kind.ACK, 0, 1, b""), 0.0)  # before it could have left: fast
    assert a.byte_time == 0.0 and a.sender.silent_backoff
    return a


def resends_in(a: Endpoint, seconds: float, answer: bytes | None = None) -> list[int]:
    """Retransmitted frames per flush over ``seconds`` of virtual time, the peer silent
    (``answer`` None) or sending ``answer`` (a report acknowledging nothing) every 5 ms."""
    t, counts, before = 0.001, [], a.retransmits
    while t < seconds:
        if answer is not None:
            a.feed(answer, t)
        a.flush(t)
        counts.append(a.retransmits - before)
        deadline = a.next_deadline()
        step = 0.005 if answer is not None else max(1e-4, (deadline or t + 0.01) - t)
        t += step
    return counts


def test_a_silent_peer_gets_one_probe_per_backed_off_timeout():
    a = fast_endpoint()
    for i in range(20):
        a.send(bytes([i]) * 20, items=4)
    assert len(a.flush(0.001)) == 20  # nothing heard after this: the peer froze
    counts = resends_in(a, 2.0)
    # every 25 ms for the first 0.15 s (a device's reports can be that far apart), then
    # 50, 100, 200, 250 ms ...: about fifteen timeouts, each resending only the oldest
    # frame (it was a window of 20 frames every 3 ms: 139 retransmissions in 1.5 s)
    assert counts[-1] <= 16
    assert a.sender.timeouts == counts[-1]
    assert a.sender.rto.rto > 0.1


def test_a_peer_that_is_heard_gets_the_whole_window_again_without_backoff():
    a = fast_endpoint()
    for i in range(4):
        a.send(bytes([i]) * 20, items=4)
    a.flush(0.0)
    report = encode_frame(Kind.ACK, 0, 0, b"")  # alive, but lacks frame 0 (and no stale rule)
    a.sender.stale_after = None
    rto = a.sender.rto.rto
    resends_in(a, 0.3, report)
    # every timeout the four frames again, the timeout not doubled: a noisy line, not a
    # slow peer
    assert a.sender.timeouts >= 4
    assert a.retransmits == 4 * a.sender.timeouts
    assert a.sender.rto.rto == rto


def test_a_gap_that_stays_open_draws_another_nak_after_the_holdoff():
    b = Endpoint(window=8, nak_holdoff=0.01, renak=True)
    a = Endpoint(window=8)
    for i in range(4):
        a.send(bytes([i]))
    frames = a.flush(0.0)
    b.feed(frames[2], 0.001)  # 0 and 1 lost: a gap
    b.flush(0.001)
    assert b.counters.naks_sent == 1
    b.feed(frames[3], 0.003)  # the gap is still open, within the holdoff: no NAK yet
    assert b.flush(0.003) == [] and b.counters.naks_sent == 1
    assert b.next_deadline() == 0.011
    b.flush(0.011)
    assert b.counters.naks_sent == 2  # (the first NAK, or the go-back, may have been lost)


def test_a_nak_held_back_is_dropped_when_the_gap_closed_meanwhile():
    b = Endpoint(window=8, nak_holdoff=0.01, renak=True)
    a = Endpoint(window=8)
    for i in range(3):
        a.send(bytes([i]))
    f0, f1, f2 = a.flush(0.0)
    b.feed(f1, 0.001)
    b.flush(0.001)
    b.feed(f2, 0.002)  # held back
    b.feed(f0 + f1 + f2, 0.005)  # the go-back arrives: the gap is closed
    b.flush(0.005)
    b.flush(0.012)
    assert b.counters.naks_sent == 1


def test_two_copies_of_each_frame_deliver_once():
    a, b = Endpoint(window=8), Endpoint(window=8)
    a.sender.copies = 2
    for i in range(3):
        a.send(bytes([i]) * 5)
    frames = a.flush(0.0)
    assert len(frames) == 6 and a.sender.extra_copies == 3 and a.retransmits == 0
    got = [inc.payload for inc in b.feed(b"".join(frames[1:]), 0.001) if inc.kind == "data"]
    assert got == [bytes([i]) * 5 for i in range(3)]  # the first copy of frame 0 was lost
    assert b.counters.duplicates == 2


def test_a_report_that_only_waited_in_a_buffer_is_not_stale():
    """A report read 30 ms after a frame left, but written before that frame can have
    arrived (it waited in the port's buffer while the host was busy), says nothing about
    the frame: no resend. One written 20 ms after it left does."""
    s = Sender(window=4, rto=RtoEstimator(initial=0.1, floor=0.1, ceiling=1.0))
    s.stale_after = 0.02
    s.queue(b"segments", items=3, ticks=300)
    s.frames_to_send(0.0)
    s.on_report(0, 0.030, sent_after=0.001)
    assert s.frames_to_send(0.030) == [] and s.early_resends == 0
    s.on_report(0, 0.031, sent_after=0.021)
    assert s.frames_to_send(0.031) == [(0, b"segments")] and s.early_resends == 1
