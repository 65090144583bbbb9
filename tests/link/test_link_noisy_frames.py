"""Frame length on a noisy line (issue 30): frames stay as short as the line carries."""

from __future__ import annotations

from cdprhost.link.tuning import CLEAN_RTO_FLOOR_S
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.streams import demo_stream
from tests.link.wire_spy import data_frames


def test_frames_stay_short_on_a_one_percent_line():
    # At 1 % corruption + 1 % drop per byte a 100-byte frame gets through whole one time in
    # eight. The loss rate was counted per byte sent (go-backs resend whole windows, so it
    # read far too low) and its floor raised the limit to full frames at the first loss.
    link = open_embedded(faults="corrupt=0.01,drop=0.01,seed=3", baud=None)
    _fast(link)  # as on a pty (a UART keeps its old rule: the AVR's frames)
    try:
        with data_frames(link) as frames:
            link.queue_segments(demo_stream(1500, seed=4))
            link.wait_idle(timeout=120)
        assert link.progress.segments_done == 1500
    finally:
        link.close()
    sizes = [n for n, _ in frames]
    late = sizes[len(sizes) // 3 :]
    assert max(late) <= 64 and link._core.payload_limit <= 48
    assert link.counters.retransmits > 50  # the faults did bite


def _fast(link):
    """As on a pty: an acknowledgement proved the path faster than its baud."""
    link._core.ep._fast_path()
    link.request_status()
    return link._core.ep.sender.rto.floor


def test_a_clean_fast_path_keeps_a_longer_floor_and_a_noisy_one_the_25_ms_floor():
    clean = open_embedded(baud=None)
    noisy = open_embedded(faults="corrupt=0.01,drop=0.01,seed=1", baud=None)
    try:
        # a pty loses nothing: a 25 ms timeout there is a scheduling delay (spurious)
        assert _fast(clean) == CLEAN_RTO_FLOOR_S  # 0.5 s (a quarter of the 2 s link timeout)
        assert _fast(noisy) == 0.025
    finally:
        clean.close()
        noisy.close()
