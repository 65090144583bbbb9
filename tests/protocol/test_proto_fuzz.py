"""The device validates every field: bad frames get a NAK or an ERROR, never a crash or a
hang, and a clean handshake works afterwards (PROTOCOL.md section 8)."""

from __future__ import annotations

import contextlib
import random

import pytest

import firmware_protocol.messages as M
from firmware_protocol.device.firmware import SimDevice
from firmware_protocol.framing import Deframer, Kind, encode_frame
from firmware_protocol.message_codec import decode_messages, encode_message, encode_messages
from firmware_protocol.messages import (
    ErrorCode,
)
from firmware_protocol.segments import SegmentContext


class Session:
    """A hand-driven host: HELLO, then DATA frames with payloads of our choosing."""

    def __init__(self, device: SimDevice | None = None):
        self.dev = device or SimDevice()
        self.t = 0.0
        self.seq = 0
        self.expected = 0  # the device's next DATA sequence number
        self.deframer = Deframer()
        self.reports: list[M.Message] = []
        self.frames: list = []
        self.step(encode_frame(Kind.URGENT, 0, 0, encode_message(M.Hello(4242))))
        assert any(isinstance(m, M.Ident) for m in self.reports)

    def step(self, data: bytes = b"", dt: float = 0.001) -> None:
        self.t += dt
        for raw in self.dev.step(self.t, data):
            for f in self.deframer.feed(raw):
                self.frames.append(f)
                if f.kind == Kind.DATA:
                    if f.seq != self.expected:  # a retransmission: already counted
                        continue
                    self.expected = (self.expected + 1) % 256
                with contextlib.suppress(M.MessageError):
                    self.reports += decode_messages(f.payload, SegmentContext())

    def send(self, payload: bytes) -> None:
        self.step(encode_frame(Kind.DATA, self.seq, self.expected, payload))
        self.seq = (self.seq + 1) % 256

    def errors(self) -> list[M.Error]:
        return [m for m in self.reports if isinstance(m, M.Error)]


# the four frames that crashed 1.0's device model, a dwell that blocked its queue, fan 200
# (also sent to the AVR firmware by tests/conformance)
BAD_PAYLOADS = [
    (b"\x14\x00" + b"\xff" * 9 + b"\x01", ErrorCode.BAD_COMMAND),  # SET_HEATER target 2**64
    (b"\x10" + b"\xff" * 9 + b"\x02" + b"\x00" * 3, ErrorCode.BAD_COMMAND),  # SET_POSITION
    (b"\x9a" + b"\xff" * 10 + b"\x01\x00\x00\x00", ErrorCode.BAD_COMMAND),  # segment delta
    (b"\x13" + b"\xff" * 9 + b"\x01", ErrorCode.BAD_COMMAND),  # DWELL 2**64 - 1
    (encode_message(M.Dwell(4_000_000_000)), ErrorCode.BAD_VALUE),  # over 3600 s
    (b"\x15\x07\x10", ErrorCode.BAD_VALUE),  # fan 7: the device has one fan
    (b"\x15\xc8\x10", ErrorCode.BAD_COMMAND),  # fan 200: outside the table's 0..7
    (encode_message(M.SetHeater(1, 1300)), ErrorCode.HEATER_RANGE),  # bed 130 C over 120
    (encode_message(M.Hello(7)), ErrorCode.BAD_COMMAND),  # URGENT-only message in DATA
    (encode_message(M.Flow(0, 0, 0, 0)), ErrorCode.BAD_COMMAND),  # a device report
    # protocol 2.1 commands out of range
    (b"\x08\x03\x00\x02", ErrorCode.BAD_COMMAND),  # SET_LIMITS module 3
    (encode_message(M.SetLimits(1, 10, -10)), ErrorCode.BAD_VALUE),  # lo > hi
    (b"\x0a\x32", ErrorCode.BAD_COMMAND),  # HEATER_LEASE 50 ms, under 100
    (b"\x17\x00\xb4\x10\x02", ErrorCode.BAD_COMMAND),  # AUTOTUNE 2 cycles, under 3
    (encode_message(M.Health(0, 0, 0, 0)), ErrorCode.BAD_COMMAND),  # a device report
    (b"\xe2\x10", ErrorCode.BAD_COMMAND),  # a segment with a reserved flag bit
]


def _corrupt(frame: bytes, at: int) -> bytes:
    b = bytearray(frame)
    b[at] ^= 0x5A
    return bytes(b)


# Frames carrying a DWELL whose framing is damaged, built for the device's expected
# sequence number ``seq``: each must be dropped (or answered with a NAK), never executed,
# and the device must answer a clean frame after it.
MALFORMED_FRAMES = {
    "bad payload crc": lambda f: _corrupt(f, len(f) - 3),
    "bad header crc": lambda f: _corrupt(f, 5),
    "bad length": lambda f: _corrupt(f, 1),
    "length over 248": lambda f: f[:1] + bytes((249,)) + f[2:],
    "unknown kind": lambda f: f[:2] + bytes((9,)) + f[3:],
    "bad end byte": lambda f: f[:-1] + b"\x00",
    "a byte dropped": lambda f: f[:7] + f[8:],
    "a byte inserted": lambda f: f[:7] + b"\x00" + f[7:],
    "truncated": lambda f: f[: len(f) // 2],
    "sequence ahead": lambda f: f,  # built with seq + 5 by the caller
    "sync only": lambda f: b"\xa5" * 16,
}


def malformed_frame(name: str, seq: int, ack: int) -> bytes:
    """The named malformed frame (its payload a DWELL of 10 ticks)."""
    payload = encode_message(M.Dwell(10))
    if name == "sequence ahead":
        seq = (seq + 5) % 256
    return MALFORMED_FRAMES[name](encode_frame(Kind.DATA, seq, ack, payload))


@pytest.mark.parametrize("name", sorted(MALFORMED_FRAMES))
def test_malformed_frames_are_never_executed(name):
    s = Session()
    s.step(malformed_frame(name, s.seq, s.expected), dt=0.05)
    s.step(dt=0.05)
    assert s.dev.machine.items_received == 0 and not s.errors()
    s.send(encode_message(M.GetStatus()))
    s.step(dt=0.05)
    assert [m for m in s.reports if isinstance(m, M.Status)]


@pytest.mark.parametrize("payload, code", BAD_PAYLOADS)
def test_bad_fields_are_answered_with_an_error(payload, code):
    s = Session()
    s.send(payload)
    s.step(dt=0.05)
    assert [e.code for e in s.errors()] == [code]
    st = s.dev.status()
    assert st.flags & M.Flag.FAULT and st.last_error == code
    s.send(encode_message(M.ClearFault()))
    s.step(dt=0.05)
    assert not s.dev.status().flags & M.Flag.FAULT


def test_the_handshake_reports_the_hello_nonce_in_the_ident():
    s = Session()
    s.step(encode_frame(Kind.URGENT, 0, 0, encode_message(M.Hello(9))), dt=0.01)
    idents = [m for m in s.reports if isinstance(m, M.Ident)]
    assert idents[-1].nonce == 9 and idents[-1].major == M.PROTOCOL_MAJOR


def test_a_position_past_the_32_bit_range_is_refused():
    s = Session()
    s.send(encode_message(M.SetPosition((2**31 - 10, 0, 0, 0))))
    s.send(encode_messages([M.Segment(100_000, (20, 0, 0, 0), 255)], SegmentContext()))
    s.step(dt=0.05)
    assert [e.code for e in s.errors()] == [ErrorCode.BAD_VALUE]


def _mutate(rng: random.Random, frame: bytes) -> bytes:
    b = bytearray(frame)
    for _ in range(rng.randint(1, 4)):
        op = rng.random()
        if op < 0.5 and b:
            b[rng.randrange(len(b))] = rng.randrange(256)
        elif op < 0.75 and b:
            del b[rng.randrange(len(b))]
        else:
            b.insert(rng.randrange(len(b) + 1), rng.randrange(256))
    return bytes(b)


def _random_payload(rng: random.Random) -> bytes:
    """Plausible opcodes followed by random fields (long varints, odd values)."""
    op = rng.choice(
        [*(cls.OPCODE for cls in M.MESSAGES), *range(0x80, 0x100, 7), rng.randrange(256)]
    )
    body = bytes(rng.randrange(256) for _ in range(rng.randint(0, 24)))
    return bytes((op,)) + body


def fuzz_frames(n: int, seed: int):
    """``n`` frames: ``("data", payload)`` (to send in sequence) with random bytes after
    plausible opcodes or real messages with random in-range values, ``("urgent",
    payload)``, and raw bytes: mutated frames (bad CRC, slipped bytes) and garbage."""
    rng = random.Random(seed)
    for i in range(n):
        kind = rng.random()
        if kind < 0.35:  # random fields after plausible opcodes
            payload = b"".join(_random_payload(rng) for _ in range(rng.randint(1, 4)))
            yield ("data", payload[:248])
        elif kind < 0.60:  # a real message with random (in-range) values
            cls = rng.choice(M.MESSAGES)
            try:
                raw = encode_message(cls(**{f.name: _value(rng, f) for f in cls.FIELDS}))
            except (M.MessageError, TypeError):
                continue
            urgent = cls.CLASS == "U" or rng.random() < 0.2
            if cls is M.Hello and rng.random() < 0.9:
                continue  # mostly keep the session
            yield ("urgent" if urgent else "data", raw)
        elif kind < 0.85:
            good = encode_frame(
                rng.choice(list(Kind)), rng.randrange(256), i % 256, _random_payload(rng)
            )
            yield _mutate(rng, good)
        else:
            yield bytes(rng.randrange(256) for _ in range(rng.randint(1, 40)))


def _value(rng: random.Random, f: M.Field):
    if f.type == "text":
        return "x" * rng.randint(0, 40)
    lo, hi = f.range
    one = lambda: rng.choice([lo, hi, rng.randint(lo, hi)])  # noqa: E731
    if f.count == 1:
        return one()
    if f.counted:
        return tuple(one() for _ in range(rng.randint(0, f.count)))
    return tuple(one() for _ in range(f.count))


@pytest.mark.timeout(600)
def test_100000_fuzzed_frames_then_a_clean_handshake():
    s = Session()
    for k, frame in enumerate(fuzz_frames(100_000, seed=12)):
        if isinstance(frame, tuple):
            what, payload = frame
            if what == "data":
                s.send(payload)
            else:
                s.step(encode_frame(Kind.URGENT, 0, 0, payload), dt=0.0005)
        else:
            s.step(frame, dt=0.0005)
        if k % 5000 == 0:  # the host comes back now and then: a new session
            s.step(encode_frame(Kind.URGENT, 0, 0, encode_message(M.Hello(1 + k % 60000))))
            s.expected = 0
        s.reports.clear()
    # whatever happened, an e-stop, a clean handshake and a status round trip work
    s.step(encode_frame(Kind.URGENT, 0, 0, encode_message(M.EmergencyStop())), dt=0.01)
    s.step(encode_frame(Kind.URGENT, 0, 0, encode_message(M.Hello(60001))), dt=0.01)
    assert any(isinstance(m, M.Ident) and m.nonce == 60001 for m in s.reports)
    s.seq = s.expected = 0
    s.send(encode_message(M.ClearFault()))
    s.send(encode_message(M.GetStatus()))
    for _ in range(20):
        s.step(dt=0.05)
    status = [m for m in s.reports if isinstance(m, M.Status)]
    assert status and status[-1].flags & M.Flag.SYNCED
    assert s.dev.endpoint.bad_frames > 10_000  # the framing checks were reached
    assert s.dev.machine.items_received > 1000  # and so were the message checks
