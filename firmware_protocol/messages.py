"""The message set: small frozen dataclasses and their payload codec.

A DATA payload is a sequence of messages, each starting with an opcode byte.
Opcodes 0x80..0xFF are move segments (the low bits are flags, see
:mod:`firmware_protocol.segments`); 0x01..0x3F are host commands; 0x40..0x7F are
device reports. Temperatures are integers in tenths of a degree Celsius.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from enum import IntEnum, IntFlag
from typing import ClassVar

from firmware_protocol.segments import (
    SEG_BASE,
    SegmentBatch,
    SegmentContext,
    decode_segment,
    encode_segments,
)
from firmware_protocol.varint import (
    VarintError,
    decode_svarint,
    decode_uvarint,
    encode_svarint,
    encode_uvarint,
)

PROTOCOL_MAJOR = 1
PROTOCOL_MINOR = 0

HOTEND, BED = 0, 1


class MessageError(ValueError):
    """A payload that does not parse (unknown opcode, truncated field, bad value)."""


class Flag(IntFlag):
    MOVING = 0x01
    FAULT = 0x02
    ESTOP = 0x04
    HOMED = 0x08
    ENABLED = 0x10
    HEATING = 0x20
    SYNCED = 0x40
    WAITING = 0x80


class ErrorCode(IntEnum):
    UNDERRUN = 1
    THERMAL_RUNAWAY = 2
    ENDSTOP_HIT = 3
    STEP_RATE = 4
    QUEUE_OVERFLOW = 5
    BAD_COMMAND = 6
    ESTOP = 7
    HEATER_RANGE = 8
    HOMING_FAILED = 9
    OVERTEMP = 10


class EventCode(IntEnum):
    HOMED = 1
    HEATER_REACHED = 2
    FAULT_CLEARED = 3


class BootCause(IntEnum):
    POWER_ON = 0
    WATCHDOG = 1
    SOFT_RESET = 2


# ------------------------------------------------------------------ reader / writer helpers


class _Reader:
    __slots__ = ("buf", "pos")

    def __init__(self, buf: bytes, pos: int = 0):
        self.buf = buf
        self.pos = pos

    def u8(self) -> int:
        if self.pos >= len(self.buf):
            raise MessageError("truncated byte field")
        self.pos += 1
        return self.buf[self.pos - 1]

    def uv(self) -> int:
        value, self.pos = decode_uvarint(self.buf, self.pos)
        return value

    def sv(self) -> int:
        value, self.pos = decode_svarint(self.buf, self.pos)
        return value

    def text(self) -> str:
        n = self.u8()
        if self.pos + n > len(self.buf):
            raise MessageError("truncated string")
        self.pos += n
        return self.buf[self.pos - n : self.pos].decode("ascii", "replace")


def _text(s: str) -> bytes:
    raw = s.encode("ascii", "replace")[:255]
    return bytes((len(raw),)) + raw


# ------------------------------------------------------------------ messages


@dataclass(frozen=True)
class Message:
    """Base: ``OPCODE`` and ``LAYOUT`` (one codec kind per field, in order)."""

    OPCODE: ClassVar[int] = 0
    LAYOUT: ClassVar[tuple[str, ...]] = ()
    QUEUED: ClassVar[bool] = False  # occupies a move-queue slot


@dataclass(frozen=True)
class Segment(Message):
    """One timed move segment (see segments.py); ``ramp`` -1 is constant speed."""

    ticks: int
    deltas: tuple[int, int, int, int]
    ramp: int = -1
    QUEUED: ClassVar[bool] = True


# host -> device, immediate
@dataclass(frozen=True)
class Identify(Message):
    OPCODE: ClassVar[int] = 0x01


@dataclass(frozen=True)
class GetStatus(Message):
    OPCODE: ClassVar[int] = 0x02


@dataclass(frozen=True)
class ClearFault(Message):
    OPCODE: ClassVar[int] = 0x03


# host -> device, URGENT frames only
@dataclass(frozen=True)
class Hello(Message):
    nonce: int
    major: int = PROTOCOL_MAJOR
    minor: int = PROTOCOL_MINOR
    OPCODE: ClassVar[int] = 0x05
    LAYOUT: ClassVar[tuple[str, ...]] = ("uv", "u8", "u8")


@dataclass(frozen=True)
class EmergencyStop(Message):
    OPCODE: ClassVar[int] = 0x06


# host -> device, queued (executed in order with the segments)
@dataclass(frozen=True)
class SetPosition(Message):
    steps: tuple[int, int, int, int]
    OPCODE: ClassVar[int] = 0x10
    LAYOUT: ClassVar[tuple[str, ...]] = ("sv4",)
    QUEUED: ClassVar[bool] = True


@dataclass(frozen=True)
class Enable(Message):
    """Bit k of ``mask`` enables axis k; axes not in the mask are disabled."""

    mask: int
    OPCODE: ClassVar[int] = 0x11
    LAYOUT: ClassVar[tuple[str, ...]] = ("u8",)
    QUEUED: ClassVar[bool] = True


@dataclass(frozen=True)
class Home(Message):
    """Move the modules in ``mask`` (bits 0..2) to their endstops; set them to ``positions``."""

    mask: int
    positions: tuple[int, int, int] = (0, 0, 0)
    OPCODE: ClassVar[int] = 0x12
    LAYOUT: ClassVar[tuple[str, ...]] = ("u8", "sv3m")
    QUEUED: ClassVar[bool] = True


@dataclass(frozen=True)
class Dwell(Message):
    ticks: int
    OPCODE: ClassVar[int] = 0x13
    LAYOUT: ClassVar[tuple[str, ...]] = ("uv",)
    QUEUED: ClassVar[bool] = True


@dataclass(frozen=True)
class SetHeater(Message):
    heater: int
    target_dc: int
    OPCODE: ClassVar[int] = 0x14
    LAYOUT: ClassVar[tuple[str, ...]] = ("u8", "uv")
    QUEUED: ClassVar[bool] = True


@dataclass(frozen=True)
class SetFan(Message):
    fan: int
    value: int
    OPCODE: ClassVar[int] = 0x15
    LAYOUT: ClassVar[tuple[str, ...]] = ("u8", "u8")
    QUEUED: ClassVar[bool] = True


@dataclass(frozen=True)
class WaitHeater(Message):
    """Hold the queue until ``|T - target| <= tolerance_dc`` (motion must be at rest)."""

    heater: int
    tolerance_dc: int = 20
    OPCODE: ClassVar[int] = 0x16
    LAYOUT: ClassVar[tuple[str, ...]] = ("u8", "uv")
    QUEUED: ClassVar[bool] = True


# device -> host
@dataclass(frozen=True)
class Ident(Message):
    nonce: int
    major: int
    minor: int
    boot_id: int
    firmware_name: str
    firmware_version: str
    axes: int
    queue_capacity: int
    clock_hz: int
    max_step_rate: int
    max_payload: int
    heaters: int
    fans: int
    items_received: int
    items_done: int
    segments_received: int
    segments_done: int
    OPCODE: ClassVar[int] = 0x41
    LAYOUT: ClassVar[tuple[str, ...]] = (
        "uv",
        "u8",
        "u8",
        "uv",
        "text",
        "text",
        "u8",
        "uv",
        "uv",
        "uv",
        "u8",
        "u8",
        "u8",
        "uv",
        "uv",
        "uv",
        "uv",
    )


@dataclass(frozen=True)
class Status(Message):
    flags: int
    queue_free: int
    items_done: int
    segments_done: int
    motion_ticks: int
    steps: tuple[int, int, int, int]
    hotend_dc: int
    hotend_target_dc: int
    bed_dc: int
    bed_target_dc: int
    fan: int
    enabled_mask: int
    homed_mask: int
    last_error: int
    bad_frames: int
    retransmits: int
    naks_sent: int
    duplicates: int
    OPCODE: ClassVar[int] = 0x42
    LAYOUT: ClassVar[tuple[str, ...]] = (
        "u8",
        "uv",
        "uv",
        "uv",
        "uv",
        "sv4",
        "sv",
        "uv",
        "sv",
        "uv",
        "u8",
        "u8",
        "u8",
        "u8",
        "uv",
        "uv",
        "uv",
        "uv",
    )


@dataclass(frozen=True)
class Event(Message):
    code: int
    item: int
    values: tuple[int, ...] = field(default=())
    OPCODE: ClassVar[int] = 0x43


@dataclass(frozen=True)
class Error(Message):
    """``item``/``segment``: the queue item and segment number where it happened (0: none)."""

    code: int
    item: int
    segment: int
    axis: int = 0xFF
    value: int = 0
    OPCODE: ClassVar[int] = 0x44
    LAYOUT: ClassVar[tuple[str, ...]] = ("u8", "uv", "uv", "u8", "sv")


@dataclass(frozen=True)
class Boot(Message):
    """Sent by a device that has (re)started and has no session; ``prev_*`` survive a soft reset."""

    boot_id: int
    cause: int
    major: int
    minor: int
    prev_valid: int
    prev_items_done: int
    prev_segments_done: int
    OPCODE: ClassVar[int] = 0x45
    LAYOUT: ClassVar[tuple[str, ...]] = ("uv", "u8", "u8", "u8", "u8", "uv", "uv")


@dataclass(frozen=True)
class EstopAck(Message):
    items_done: int
    segments_done: int
    OPCODE: ClassVar[int] = 0x46
    LAYOUT: ClassVar[tuple[str, ...]] = ("uv", "uv")


@dataclass(frozen=True)
class Flow(Message):
    """Carried by the device's ACK and NAK frames: flow control and progress."""

    flags: int
    queue_free: int
    items_done: int
    segments_done: int
    OPCODE: ClassVar[int] = 0x47
    LAYOUT: ClassVar[tuple[str, ...]] = ("u8", "uv", "uv", "uv")


_BY_OPCODE: dict[int, type[Message]] = {
    cls.OPCODE: cls
    for cls in (
        Identify,
        GetStatus,
        ClearFault,
        Hello,
        EmergencyStop,
        SetPosition,
        Enable,
        Home,
        Dwell,
        SetHeater,
        SetFan,
        WaitHeater,
        Ident,
        Status,
        Event,
        Error,
        Boot,
        EstopAck,
        Flow,
    )
}


def _encode_fields(msg: Message) -> bytes:
    out = bytearray((msg.OPCODE,))
    values = [getattr(msg, f.name) for f in fields(msg)]
    if isinstance(msg, Event):
        out += bytes((msg.code,)) + encode_uvarint(msg.item) + bytes((len(msg.values),))
        for v in msg.values:
            out += encode_svarint(v)
        return bytes(out)
    for kind, value in zip(msg.LAYOUT, values):
        if kind == "u8":
            if not 0 <= value <= 255:
                raise MessageError(f"{type(msg).__name__}: byte field out of range: {value}")
            out.append(value)
        elif kind == "uv":
            out += encode_uvarint(value)
        elif kind == "sv":
            out += encode_svarint(value)
        elif kind == "text":
            out += _text(value)
        elif kind == "sv4":
            for v in value:
                out += encode_svarint(v)
        elif kind == "sv3m":  # only the entries selected by the preceding mask byte
            mask = out[-1]
            for k in range(3):
                if mask >> k & 1:
                    out += encode_svarint(value[k])
    return bytes(out)


def _decode_fields(cls: type[Message], r: _Reader) -> Message:
    if cls is Event:
        code, item, n = r.u8(), r.uv(), r.u8()
        return Event(code, item, tuple(r.sv() for _ in range(n)))
    values: list = []
    for kind in cls.LAYOUT:
        if kind == "u8":
            values.append(r.u8())
        elif kind == "uv":
            values.append(r.uv())
        elif kind == "sv":
            values.append(r.sv())
        elif kind == "text":
            values.append(r.text())
        elif kind == "sv4":
            values.append(tuple(r.sv() for _ in range(4)))
        elif kind == "sv3m":
            mask = values[-1]
            values.append(tuple(r.sv() if mask >> k & 1 else 0 for k in range(3)))
    return cls(*values)


def encode_messages(messages: list[Message] | tuple[Message, ...], ctx: SegmentContext) -> bytes:
    """Encode messages into one payload, advancing the segment context."""
    out = bytearray()
    for msg in messages:
        if isinstance(msg, Segment):
            data, _ = encode_segments(SegmentBatch([msg.ticks], [msg.deltas], [msg.ramp]), ctx)
            out += data
        else:
            out += _encode_fields(msg)
    return bytes(out)


def encode_message(msg: Message) -> bytes:
    """A single non-segment message."""
    return _encode_fields(msg)


def decode_messages(payload: bytes, ctx: SegmentContext) -> list[Message]:
    """Decode a whole payload; the context advances only if the payload parses."""
    work = ctx.copy()
    out: list[Message] = []
    pos = 0
    try:
        while pos < len(payload):
            op = payload[pos]
            if op >= SEG_BASE:
                ticks, deltas, ramp, pos = decode_segment(payload, pos, work)
                out.append(Segment(ticks, deltas, ramp))
                continue
            cls = _BY_OPCODE.get(op)
            if cls is None:
                raise MessageError(f"unknown opcode 0x{op:02X} at payload byte {pos}")
            r = _Reader(payload, pos + 1)
            out.append(_decode_fields(cls, r))
            pos = r.pos
    except (VarintError, IndexError, ValueError) as exc:
        if isinstance(exc, MessageError):
            raise
        raise MessageError(f"bad payload at byte {pos}: {exc}") from exc
    ctx.prev_ticks, ctx.prev_deltas = work.prev_ticks, work.prev_deltas
    return out
