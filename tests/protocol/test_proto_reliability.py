"""Go-back-N delivery between two endpoints over a damaging channel, no device involved."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol.device.faults import FaultSpec, FaultyChannel
from firmware_protocol.endpoint import Endpoint
from firmware_protocol.framing import Kind, encode_frame
from firmware_protocol.reliability import Receiver, RtoEstimator, Sender


def run_pair(payloads, spec: FaultSpec, window=8, horizon=600.0):
    """Endpoint a sends ``payloads`` to b; returns what b delivered and the two endpoints."""
    a, b = Endpoint(window=window), Endpoint(window=window)
    ab = FaultyChannel(spec, seed_offset=1, baud=250_000)
    ba = FaultyChannel(spec, seed_offset=2, baud=250_000)
    got: list[bytes] = []
    for p in payloads:
        a.send(p)
    t = 0.0
    while t < horizon:
        for f in a.flush(t):
            ab.send(f, t)
        for inc in b.feed(ab.receive(t), t):
            if inc.kind == "data":
                got.append(inc.payload)
        for f in b.flush(t):
            ba.send(f, t)
        a.feed(ba.receive(t), t)
        if len(got) == len(payloads) and a.sender.idle():
            break
        times = [
            x
            for x in (ab.next_delivery(), ba.next_delivery(), a.next_deadline(), b.next_deadline())
            if x is not None
        ]
        t = max(t + 1e-6, min(times)) if times else t + 0.01
    return got, a, b


def test_clean_channel_delivers_in_order_without_retransmission():
    payloads = [bytes([i % 256]) * (1 + i % 200) for i in range(300)]
    got, a, b = run_pair(payloads, FaultSpec())
    assert got == payloads
    assert a.retransmits == 0 and a.counters.naks_received == 0


@settings(max_examples=12)
@given(st.integers(0, 10_000), st.sampled_from([1, 4, 8, 32]))
def test_lossy_channel_delivers_each_payload_exactly_once_in_order(seed, window):
    payloads = [i.to_bytes(2, "big") * 30 for i in range(200)]
    spec = FaultSpec(corrupt=0.003, drop=0.003, dup=0.02, latency_ms=3, jitter_ms=2, seed=seed)
    got, a, b = run_pair(payloads, spec, window=window)
    assert got == payloads
    assert a.retransmits > 0


def test_gap_triggers_a_nak_and_fast_retransmission():
    a, b = Endpoint(window=8), Endpoint(window=8)
    for i in range(3):
        a.send(bytes([i]))
    f0, f1, f2 = a.flush(0.0)
    b.feed(f0 + f2, 0.001)  # frame 1 lost: frame 2 reveals the gap
    replies = b.flush(0.001)
    assert b.counters.naks_sent == 1
    a.feed(b"".join(replies), 0.002)
    resent = a.flush(0.002)
    assert len(resent) == 2 and a.retransmits == 2  # go-back-N from frame 1
    got = [inc.payload for inc in b.feed(b"".join(resent), 0.003) if inc.kind == "data"]
    assert got == [b"\x01", b"\x02"]


def test_receiver_classifies_sequence_numbers():
    r = Receiver()
    r.expected = 250
    assert r.classify(250) == Receiver.NEW
    assert r.classify(3) == Receiver.GAP  # ahead, across the wrap
    assert r.classify(249) == Receiver.DUPLICATE
    r.accept()
    assert r.expected == 251


def test_sender_window_and_cumulative_ack():
    s = Sender(window=3)
    for i in range(5):
        s.queue(bytes([i]), items=2)
    sent = s.frames_to_send(0.0)
    assert [seq for seq, _ in sent] == [0, 1, 2] and s.window_free == 0
    assert s.unacked_items() == 10
    assert s.on_ack(2, 0.05) == 2  # frames 0 and 1
    assert [seq for seq, _ in s.frames_to_send(0.05)] == [3, 4]
    assert s.on_ack(200, 0.06) == 0  # nonsense ack ignored


def test_rto_adapts_backs_off_and_respects_bounds():
    rto = RtoEstimator(initial=0.25, floor=0.02, ceiling=1.0)
    assert rto.rto == 0.25
    for _ in range(20):
        rto.sample(0.010)
    assert 0.02 <= rto.rto < 0.03
    base = rto.rto
    for _ in range(8):
        rto.back_off()
    assert rto.rto == pytest.approx(4 * base)  # a serial line: backoff stays short
    rto = RtoEstimator(initial=0.4, floor=0.02, ceiling=1.0)
    for _ in range(8):
        rto.back_off()
    assert rto.rto == 1.0
    rto.sample(0.5)
    assert rto.rto == pytest.approx(min(1.0, rto.srtt + 4 * rto.rttvar))


def test_retransmission_on_timeout_uses_karn_rule():
    s = Sender(window=2, rto=RtoEstimator(initial=0.1, floor=0.01, ceiling=1.0))
    s.queue(b"x")
    s.frames_to_send(0.0)
    assert s.frames_to_send(0.05) == []
    assert s.frames_to_send(0.11) == [(0, b"x")] and s.timeouts == 1
    s.on_ack(1, 0.12)
    assert s.rto.srtt is None  # no sample from a retransmitted frame


def test_the_timer_restarts_at_each_acknowledgement_that_releases_frames():
    """A receiver working through a backlog acknowledges one frame after another: the
    frames behind are not resent while it does (RFC 6298 5.3)."""
    s = Sender(window=4, rto=RtoEstimator(initial=0.03, floor=0.03, ceiling=1.0))
    for i in range(3):
        s.queue(bytes([i]), items=1)
    s.frames_to_send(0.0)
    s.on_ack(1, 0.025)
    rto = s.rto.rto
    assert s.next_deadline() == pytest.approx(0.025 + rto)
    assert s.frames_to_send(rto + 0.001) == []  # frame 1 left at 0: due without the restart
    assert [seq for seq, _ in s.frames_to_send(0.026 + rto)] == [1, 2] and s.timeouts == 1


def test_a_stale_report_resends_the_last_frame_before_its_timeout():
    s = Sender(window=4, rto=RtoEstimator(initial=0.1, floor=0.1, ceiling=1.0))
    s.stale_after = 0.02
    s.queue(b"segments", items=3, ticks=300)
    s.frames_to_send(0.0)
    s.on_report(0, 0.015)  # too soon: the frame may still wait for the peer's next turn
    assert s.frames_to_send(0.015) == []
    s.on_report(0, 0.021)
    assert s.frames_to_send(0.021) == [(0, b"segments")] and s.timeouts == 0
    s.on_report(0, 0.05)  # a resent frame waits twice as long (40 ms)
    assert s.frames_to_send(0.05) == [] and s.early_resends == 1
    s.on_report(0, 0.062)  # the peer still reports without it: its copy was lost too
    assert s.frames_to_send(0.062) == [(0, b"segments")] and s.timeouts == 0
    assert s.early_resends == 2
    s.on_report(1, 0.07)
    s.queue(b"status")  # no queue items in flight: only the timeout resends it
    s.frames_to_send(0.07)
    s.on_report(1, 0.1)
    assert s.frames_to_send(0.1) == []


def test_items_after_an_ack_point():
    s = Sender(window=4)
    for items in (3, 0, 5, 2):
        s.queue(b"p", items=items)
    s.frames_to_send(0.0)
    assert s.items_after(0) == 10  # nothing acknowledged yet
    assert s.items_after(1) == 7 and s.items_after(3) == 2 and s.items_after(4) == 0
    s.on_ack(3, 0.01)  # releasing frames does not change what a report at ack 1 covers
    assert s.items_after(1) == 7


def test_a_frame_without_queue_items_waits_for_the_calm_floor_before_a_resend():
    """On a fast path (3 ms floor) a keep-alive or status request is not resent before the
    slow floor: a clean idle link must not count scheduling hiccups as losses; a frame of
    queue items still is, at the fast timeout."""
    s = Sender(window=8, rto=RtoEstimator(initial=0.003, floor=0.003))
    s.calm_floor = 0.025
    s.queue(b"keep-alive")
    assert [seq for seq, _ in s.frames_to_send(0.0)] == [0]
    assert s.frames_to_send(0.010) == [] and s.next_deadline() == pytest.approx(0.025)
    assert [seq for seq, _ in s.frames_to_send(0.026)] == [0]  # resent at the calm floor
    s.on_ack(1, 0.027)
    s.queue(b"segments", items=3, ticks=100)
    assert [seq for seq, _ in s.frames_to_send(0.030)] == [1]
    assert [seq for seq, _ in s.frames_to_send(0.040)] == [1]  # the fast timeout


def test_a_status_request_ahead_of_segments_keeps_the_fast_timeout():
    s = Sender(window=8, rto=RtoEstimator(initial=0.003, floor=0.003))
    s.calm_floor = 0.025
    s.queue(b"status")
    s.queue(b"segments", items=3, ticks=100)
    assert [seq for seq, _ in s.frames_to_send(0.0)] == [0, 1]
    assert [seq for seq, _ in s.frames_to_send(0.004)] == [0, 1]  # segments wait behind it


def test_only_an_unresent_frame_acknowledged_too_early_proves_a_fast_wire():
    """On a 250000-baud line the acknowledgement of a frame's first copy can arrive while
    its resent copy still waits for the wire: no proof that the wire beats its baud (taken
    as one, it put the AVR's UART on the 3 ms timing without backoff, and go-backs stormed
    it). A frame acknowledged before its only copy can have left is proof (USB, a pty)."""
    byte_time = 10 / 250_000
    a = Endpoint(byte_time=byte_time, rto_floor=0.025, rto_fast=(0.003, 1))
    a.send(b"x" * 100)
    a.send(b"y" * 100)
    a.flush(0.0)  # both on the wire until about 8.6 ms
    a.feed(encode_frame(Kind.NAK, 0, 0, b""), 0.009)  # the first lost: both go again
    assert len(a.flush(0.009)) == 2  # the first copy's end now about 13 ms
    a.feed(encode_frame(Kind.ACK, 0, 1, b""), 0.010)  # its first copy got through after all
    assert a.byte_time == byte_time and a.sender.rto.floor == 0.025

    b = Endpoint(byte_time=byte_time, rto_floor=0.025, rto_fast=(0.003, 1))
    b.send(b"x" * 100)
    b.flush(0.0)  # on the wire until about 4.4 ms
    b.feed(encode_frame(Kind.ACK, 0, 1, b""), 0.001)
    assert b.byte_time == 0.0 and b.sender.rto.floor == 0.003
