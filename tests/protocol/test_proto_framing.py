"""Frames: round trip, certain detection of single-byte damage, resynchronisation."""

from __future__ import annotations

import random

from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol.framing import (
    END,
    MAX_PAYLOAD,
    OVERHEAD,
    SYNC,
    Deframer,
    Frame,
    Kind,
    encode_frame,
)

frames_st = st.builds(
    Frame,
    st.sampled_from(list(Kind)),
    st.integers(0, 255),
    st.integers(0, 255),
    st.binary(max_size=MAX_PAYLOAD),
)


def wire(f: Frame) -> bytes:
    return encode_frame(f.kind, f.seq, f.ack, f.payload)


@given(frames_st)
def test_every_frame_round_trips(frame):
    data = wire(frame)
    assert len(data) == OVERHEAD + len(frame.payload)
    assert data[0] == SYNC and data[-1] == END
    assert Deframer().feed(data) == [frame]


@given(frames_st, st.data())
def test_frames_survive_arbitrary_chunking(frame, data):
    raw = wire(frame) * 3
    cuts = sorted(data.draw(st.lists(st.integers(0, len(raw)), max_size=10)))
    d = Deframer()
    out = []
    for a, b in zip([0] + cuts, cuts + [len(raw)]):
        out += d.feed(raw[a:b])
    assert out == [frame] * 3


@settings(max_examples=60)
@given(frames_st.filter(lambda f: len(f.payload) <= 40))
def test_every_single_byte_corruption_is_detected(frame):
    """Every position, every wrong value: the damaged frame is never delivered, and
    the intact frame after it still is."""
    good = wire(frame)
    follower = encode_frame(Kind.ACK, 7, 9, b"next")
    for pos in range(len(good)):
        for value in range(256):
            if value == good[pos]:
                continue
            bad = bytearray(good)
            bad[pos] = value
            got = Deframer().feed(bytes(bad) + follower)
            assert got == [Frame(Kind.ACK, 7, 9, b"next")], (pos, value)


@given(frames_st)
def test_every_single_byte_drop_is_detected(frame):
    good = wire(frame)
    follower = encode_frame(Kind.DATA, 1, 2, b"after")
    for pos in range(len(good)):
        got = Deframer().feed(good[:pos] + good[pos + 1 :] + follower)
        assert got == [Frame(Kind.DATA, 1, 2, b"after")]


@given(
    st.lists(frames_st, min_size=1, max_size=6),
    st.lists(st.binary(max_size=300), min_size=1, max_size=7),
    st.randoms(use_true_random=False),
)
def test_resync_after_random_garbage(frames, garbage, rnd):
    """Frames interleaved with random garbage (rich in SYNC bytes) are all recovered, in order."""
    stream = bytearray()
    for i, f in enumerate(frames):
        g = bytearray(garbage[i % len(garbage)])
        for k in range(0, len(g), 7):
            g[k] = SYNC  # plenty of false starts
        stream += g + wire(f)
    stream += garbage[-1]
    d = Deframer()
    out = []
    pos = 0
    while pos < len(stream):
        step = rnd.randint(1, 64)
        out += d.feed(bytes(stream[pos : pos + step]))
        pos += step
    # a frame can only be lost if garbage ends inside... never: garbage precedes each frame entirely
    assert out[-len(frames) :] == frames or out == frames
    assert [f for f in out if f in frames] == frames


def test_deframer_counts_damage():
    d = Deframer()
    good = encode_frame(Kind.DATA, 0, 0, b"hello")
    bad = bytearray(good)
    bad[8] ^= 0x10
    assert d.feed(bytes(bad) + good) == [Frame(Kind.DATA, 0, 0, b"hello")]
    assert d.bad_frames == 1 and d.frames == 1
    assert d.rejected == [(Kind.DATA, 0)]


def test_random_garbage_alone_yields_nothing():
    rnd = random.Random(5)
    d = Deframer()
    total = []
    for _ in range(200):
        total += d.feed(bytes(rnd.randrange(256) for _ in range(500)))
    assert total == []


def test_corruption_of_a_full_size_frame_is_detected_everywhere():
    rnd = random.Random(11)
    good = encode_frame(Kind.DATA, 200, 13, bytes(rnd.randrange(256) for _ in range(MAX_PAYLOAD)))
    for pos in range(len(good)):
        for value in rnd.sample(range(256), 12):
            if value != good[pos]:
                bad = bytearray(good)
                bad[pos] = value
                assert Deframer().feed(bytes(bad)) == []
