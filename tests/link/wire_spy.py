"""What a link writes to its device, frame by frame (the tests of frame length)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from firmware_protocol.framing import Deframer, Kind


@contextmanager
def data_frames(link) -> Iterator[list[tuple[int, int]]]:
    """The DATA frames ``link`` writes inside the block, as (payload length, first byte)."""
    frames: list[tuple[int, int]] = []
    deframer = Deframer()
    write = link._core.t.write

    def spy(data: bytes) -> None:
        frames.extend(
            (len(f.payload), f.payload[0])
            for f in deframer.feed(data)
            if f.kind == Kind.DATA and f.payload
        )
        write(data)

    link._core.t.write = spy
    try:
        yield frames
    finally:
        link._core.t.write = write
