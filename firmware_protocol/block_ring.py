"""Where a device that keeps its schedule blocks in a ring of entries puts each block
(PROTOCOL.md 6, protocol 3.2: ``RING``).

The rule is the device's own (the AVR's ``blocks_sink``), so a host that knows the sizes
of the blocks it sent, in order, and a tail the device reported, knows where every block
lies and whether the next one fits without waiting:

- a block takes, for each of its axes, a header and its chunks (``1 + chunks``);
- it goes at the ring's head when it fits there, before the ring's end and before the
  tail;
- else at the ring's start, the entries up to the end skipped (freed with the block after
  them), when the free entries wrap past the end and the block fits in those after it;
- else it waits for the steppers to free room.

Head and tail are counters modulo 256 (``entries`` a power of two, at most 128); an
entry's place is ``counter % entries``. The tail only advances, so a tail read a while
ago understates the room and never overstates it: a block placed by an old tail goes to
the same place by the device's newer one.
"""

from __future__ import annotations

from collections.abc import Iterable

COUNTER = 256


def valid_entries(entries: int) -> bool:
    """A ring size the counters modulo 256 can address: a power of two, 2..128."""
    return 2 <= entries <= COUNTER // 2 and entries & (entries - 1) == 0


def block_entries(chunks_per_axis: Iterable[int]) -> int:
    """Entries a block takes: a header and the chunks of each axis it carries."""
    return sum(1 + int(n) for n in chunks_per_axis)


def most_entries(max_payload: int) -> int:
    """The most entries one block in a payload of ``max_payload`` bytes can take (the
    AVR's BLOCK_MOST): a header and a first chunk of at least 4 bytes an axis, 3 bytes
    each further chunk, after the segment's opcode and the block's mask."""
    return (max_payload + 6) // 3


def place(head: int, tail: int, need: int, entries: int) -> int | None:
    """The counter of the first entry a block of ``need`` entries takes, the ring's head
    at ``head`` and its tail at ``tail``; None when it would wait for room."""
    free = entries - (head - tail) % COUNTER
    to_end = entries - head % entries
    run = min(free, to_end)  # free entries from the head on
    if need <= run:
        return head
    if run < free and need <= free - to_end:
        return (head + to_end) % COUNTER
    return None


def admit(head: int, tail: int, needs: Iterable[int], entries: int) -> tuple[int, int]:
    """How many of the blocks ``needs`` (entries each, in order; 0: a segment without a
    block) the ring takes now without a wait, and the head after them."""
    n = 0
    for need in needs:
        if need:
            at = place(head, tail, need, entries)
            if at is None:
                break
            head = (at + need) % COUNTER
        n += 1
    return n, head
