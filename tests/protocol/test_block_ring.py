"""The ring of schedule-block entries (protocol 3.2, firmware_protocol/block_ring.py):
the device's placement rule, and why a host that places by an old tail agrees with it."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol.block_ring import (
    COUNTER,
    admit,
    block_entries,
    most_entries,
    place,
    valid_entries,
)


def test_a_block_goes_at_the_head_when_it_fits_before_the_end():
    assert place(head=10, tail=10, need=20, entries=128) == 10
    assert place(head=100, tail=90, need=28, entries=128) == 100  # up to the end exactly


def test_a_block_that_does_not_fit_before_the_end_goes_at_the_start():
    # head at 120: 8 entries to the end, 40 free after it (tail at 40 + 128)
    assert place(head=120, tail=40, need=20, entries=128) == 128
    # the counters wrap modulo 256: the same ring a lap on
    assert place(head=(120 + 128) % 256, tail=(40 + 128) % 256, need=20, entries=128) == 0


def test_a_block_waits_when_neither_place_has_room():
    assert place(head=120, tail=20, need=21, entries=128) is None  # 8 at the end, 20 at the start
    assert place(head=50, tail=60 - 128, need=11, entries=128) is None  # 10 free before the tail
    assert place(head=0, tail=0 - 128, need=2, entries=128) is None  # full


def test_admit_stops_at_the_first_block_that_would_wait_and_moves_the_head():
    # segments without a block (0) go between the blocks; the block of 30 waits (8 left)
    n, head = admit(0, 0, [0, 40, 0, 40, 40, 0, 30, 0], entries=128)
    assert (n, head) == (6, 120)
    assert admit(0, 0, [], entries=128) == (0, 0)


def test_block_sizes_and_ring_sizes():
    assert block_entries([1, 3]) == 2 + 4  # a header and the chunks of each axis
    assert [valid_entries(n) for n in (1, 2, 96, 128, 256)] == [False, True, False, True, False]
    assert most_entries(120) == 42  # the AVR's BLOCK_MOST at its 120-byte payload


@settings(max_examples=300, deadline=None)
@given(
    needs=st.lists(st.integers(2, 42), min_size=1, max_size=60),
    lags=st.lists(st.integers(0, 6), min_size=60, max_size=60),
    entries=st.sampled_from([64, 128]),
)
def test_a_host_placing_by_an_old_tail_places_every_block_where_the_device_does(
    needs, lags, entries
):
    """The host admits each block by the tail it last heard of; the device places it
    later, by its own newer tail (the steppers freed some blocks meanwhile). The places
    agree, and no block ever lies on entries still held."""
    needs = [n for n in needs if n <= entries // 2]
    host_head = dev_head = 0
    held: list[tuple[int, int]] = []  # the device's blocks: (first counter, need), oldest first
    dev_tail = heard_tail = 0
    for k, need in enumerate(needs):
        at = place(host_head, heard_tail, need, entries)
        while at is None:  # the host waits: the oldest block ends, a report comes
            assert held, "an empty ring refused a block"
            first, n = held.pop(0)
            dev_tail = heard_tail = (first + n) % COUNTER
            at = place(host_head, heard_tail, need, entries)
        host_head = (at + need) % COUNTER
        # meanwhile the device freed more than the host heard of
        for _ in range(min(lags[k % len(lags)], len(held))):
            first, n = held.pop(0)
            dev_tail = (first + n) % COUNTER
        dev_at = place(dev_head, dev_tail, need, entries)
        assert dev_at == at
        dev_head = (dev_at + need) % COUNTER
        # within the ring's live span: from the tail, no further than `entries` on
        assert (dev_head - dev_tail) % COUNTER <= entries
        held.append((dev_at, need))  # (a skipped end is freed with it: by its end)
    assert host_head == dev_head
