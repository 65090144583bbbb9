"""What a link writes to its device, frame by frame (the tests of frame length)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from firmware_protocol.framing import HEADER_LEN, OVERHEAD

DATA = 1  # a frame's kind byte


def _data_frames(wire: bytes) -> list[tuple[int, int]]:
    """Each DATA frame's payload length and first byte in one write (it may hold several)."""
    out, pos = [], 0
    while pos + HEADER_LEN < len(wire):
        length, kind = wire[pos + 1], wire[pos + 2]
        if kind == DATA and length:
            out.append((length, wire[pos + HEADER_LEN]))
        pos += OVERHEAD + length
    return out


@contextmanager
def data_frames(link) -> Iterator[list[tuple[int, int]]]:
    """The DATA frames ``link`` writes inside the block, as (payload length, first byte)."""
    frames: list[tuple[int, int]] = []
    write = link._core.t.write

    def spy(data: bytes) -> None:
        frames.extend(_data_frames(data))
        write(data)

    link._core.t.write = spy
    try:
        yield frames
    finally:
        link._core.t.write = write
