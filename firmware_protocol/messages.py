"""The message set: one table of typed, bounded fields, and its payload codec.

A DATA payload is a sequence of messages, each starting with an opcode byte.
Opcodes 0x80..0xFF are move segments (the low bits are flags, see
:mod:`firmware_protocol.segments`); 0x01..0x3F are host commands; 0x40..0x7F are
device reports. Temperatures are integers in tenths of a degree Celsius.

Every field has a wire type with a fixed width (``u8``; ``u16``/``u32`` unsigned
varints of at most 3/5 bytes; ``i16``/``i32`` zigzag varints; ``text`` a length byte
and ASCII) and, where the protocol fixes one, a value range. The table
(``Message.FIELDS``) is the single source for the codec, the device's checks and the
C header (:mod:`firmware_protocol.c_header`); PROTOCOL.md section 4 is its prose.
Ranges that depend on the device (heater count, maximum temperatures, clock) are
named by the ``Ident`` field that announces them and checked by the device.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum, IntFlag
from typing import Any, ClassVar

from firmware_protocol.segments import (
    SEG_BASE,
    SegmentContext,
    decode_segment,
    encode_one_segment,
)
from firmware_protocol.varint import (
    VarintError,
    decode_sbounded,
    decode_ubounded,
    encode_svarint,
    encode_uvarint,
)

PROTOCOL_MAJOR = 2
PROTOCOL_MINOR = 0

HOTEND, BED = 0, 1
MAX_TEXT = 32  # bytes of a text field
MAX_EVENT_VALUES = 4
DWELL_MAX_S = 3600  # longest DWELL, in seconds of the device clock
WATCHDOG_MS_RANGE = (100, 60_000)
WATCHDOG_MS_DEFAULT = 2000
TOLERANCE_DC_RANGE = (1, 1000)

# value ranges of each wire type
TYPE_RANGE: dict[str, tuple[int, int]] = {
    "u8": (0, 0xFF),
    "u16": (0, 0xFFFF),
    "u32": (0, 0xFFFF_FFFF),
    "i16": (-0x8000, 0x7FFF),
    "i32": (-0x8000_0000, 0x7FFF_FFFF),
}
_BITS = {"u16": 16, "u32": 32, "i16": 16, "i32": 32}


class MessageError(ValueError):
    """A payload that does not parse (unknown opcode, truncated or out-of-range field).

    ``offset`` is the payload byte where the offending message starts; ``opcode`` its opcode."""

    def __init__(self, text: str, *, offset: int = 0, opcode: int = 0):
        super().__init__(text)
        self.offset = offset
        self.opcode = opcode


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
    WATCHDOG = 11
    BAD_VALUE = 12


#: faults a host must not clear on its own (the heater or its sensor needs a look first)
THERMAL_ERRORS = frozenset({ErrorCode.THERMAL_RUNAWAY, ErrorCode.OVERTEMP})


class EventCode(IntEnum):
    HOMED = 1
    HEATER_REACHED = 2
    FAULT_CLEARED = 3


class BootCause(IntEnum):
    POWER_ON = 0
    WATCHDOG = 1
    SOFT_RESET = 2


class EstopFlag(IntFlag):
    """``EmergencyStop.flags``: what the stop leaves on (0: everything off)."""

    KEEP_HEATERS = 0x01
    KEEP_MOTORS = 0x02


@dataclass(frozen=True)
class Field:
    """One field of the table.

    ``type``: u8, u16, u32, i16, i32 or text. ``count`` > 1: a fixed array; with ``mask``
    only the entries whose bit is set in the named earlier field are on the wire; with
    ``counted`` a u8 count (0..count) precedes the entries. ``lo``/``hi``: the value
    range the protocol fixes (within the type's own range), checked by every decoder;
    ``limit``: a further bound that depends on the device (named by the ``Ident`` field
    that announces it), checked by the device when it executes the command.
    """

    name: str
    type: str
    count: int = 1
    mask: str | None = None
    counted: bool = False
    lo: int | None = None
    hi: int | None = None
    limit: str = ""
    doc: str = ""

    @property
    def range(self) -> tuple[int, int]:
        """The statically known range (type range narrowed by lo/hi when numeric)."""
        lo, hi = TYPE_RANGE.get(self.type, (0, MAX_TEXT))
        if self.lo is not None:
            lo = max(lo, self.lo)
        if self.hi is not None:
            hi = min(hi, self.hi)
        return lo, hi


def F(name: str, type_: str, doc: str = "", **kw: Any) -> Field:
    return Field(name, type_, doc=doc, **kw)


# ------------------------------------------------------------------ messages


@dataclass(frozen=True)
class Message:
    """Base: ``OPCODE``, ``FIELDS`` (the wire table), ``CLASS`` (Q queued, I immediate,
    U urgent, D device report)."""

    OPCODE: ClassVar[int] = 0
    FIELDS: ClassVar[tuple[Field, ...]] = ()
    CLASS: ClassVar[str] = "I"
    QUEUED: ClassVar[bool] = False  # occupies a move-queue slot


@dataclass(frozen=True)
class Segment(Message):
    """One timed move segment (see segments.py); ``ramp`` -1 is constant speed."""

    ticks: int
    deltas: tuple[int, int, int, int]
    ramp: int = -1
    OPCODE: ClassVar[int] = SEG_BASE
    CLASS: ClassVar[str] = "Q"
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


@dataclass(frozen=True)
class Flush(Message):
    """Start the queued motion now: nothing more is coming soon (end of file, pause)."""

    OPCODE: ClassVar[int] = 0x04


@dataclass(frozen=True)
class Configure(Message):
    """Session settings: host watchdog, start threshold, flow-report interval."""

    watchdog_ms: int = WATCHDOG_MS_DEFAULT
    start_ticks: int = 0
    flow_ticks: int = 0
    OPCODE: ClassVar[int] = 0x07
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("watchdog_ms", "u16", "host watchdog", lo=WATCHDOG_MS_RANGE[0], hi=WATCHDOG_MS_RANGE[1]),
        F("start_ticks", "u32", "start from rest once this much motion is queued"),
        F("flow_ticks", "u32", "unsolicited FLOW every this much executed motion (0: off)"),
    )


# host -> device, URGENT frames only
@dataclass(frozen=True)
class Hello(Message):
    nonce: int
    major: int = PROTOCOL_MAJOR
    minor: int = PROTOCOL_MINOR
    OPCODE: ClassVar[int] = 0x05
    CLASS: ClassVar[str] = "U"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("nonce", "u16", "random, not 0", lo=1),
        F("major", "u8"),
        F("minor", "u8"),
    )


@dataclass(frozen=True)
class EmergencyStop(Message):
    flags: int = 0
    OPCODE: ClassVar[int] = 0x06
    CLASS: ClassVar[str] = "U"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("flags", "u8", "EstopFlag: 0x01 keep heaters, 0x02 keep motors", hi=0x03),
    )


# host -> device, queued (executed in order with the segments)
@dataclass(frozen=True)
class SetPosition(Message):
    steps: tuple[int, int, int, int]
    OPCODE: ClassVar[int] = 0x10
    CLASS: ClassVar[str] = "Q"
    QUEUED: ClassVar[bool] = True
    FIELDS: ClassVar[tuple[Field, ...]] = (F("steps", "i32", "absolute step counters", count=4),)


@dataclass(frozen=True)
class Enable(Message):
    """Bit k of ``mask`` enables axis k; axes not in the mask are disabled."""

    mask: int
    OPCODE: ClassVar[int] = 0x11
    CLASS: ClassVar[str] = "Q"
    QUEUED: ClassVar[bool] = True
    FIELDS: ClassVar[tuple[Field, ...]] = (F("mask", "u8", "bits 0..3", hi=0x0F),)


@dataclass(frozen=True)
class Home(Message):
    """Move the modules in ``mask`` (bits 0..2) to their endstops; set them to ``positions``."""

    mask: int
    positions: tuple[int, int, int] = (0, 0, 0)
    OPCODE: ClassVar[int] = 0x12
    CLASS: ClassVar[str] = "Q"
    QUEUED: ClassVar[bool] = True
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("mask", "u8", "modules, bits 0..2", lo=1, hi=0x07),
        F("positions", "i32", "position of each module in the mask", count=3, mask="mask"),
    )


@dataclass(frozen=True)
class Dwell(Message):
    ticks: int
    OPCODE: ClassVar[int] = 0x13
    CLASS: ClassVar[str] = "Q"
    QUEUED: ClassVar[bool] = True
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("ticks", "u32", "ticks of clock_hz", lo=1, limit=f"<= {DWELL_MAX_S} * clock_hz"),
    )


@dataclass(frozen=True)
class SetHeater(Message):
    heater: int
    target_dc: int
    OPCODE: ClassVar[int] = 0x14
    CLASS: ClassVar[str] = "Q"
    QUEUED: ClassVar[bool] = True
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("heater", "u8", "0 hotend, 1 bed", hi=1, limit="< heaters"),
        F("target_dc", "u16", "0.1 C, 0 = off", limit="<= hotend_max_dc / bed_max_dc"),
    )


@dataclass(frozen=True)
class SetFan(Message):
    fan: int
    value: int
    OPCODE: ClassVar[int] = 0x15
    CLASS: ClassVar[str] = "Q"
    QUEUED: ClassVar[bool] = True
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("fan", "u8", hi=7, limit="< fans"),
        F("value", "u8", "0..255"),
    )


@dataclass(frozen=True)
class WaitHeater(Message):
    """Hold the queue until ``|T - target| <= tolerance_dc`` (motion must be at rest)."""

    heater: int
    tolerance_dc: int = 20
    OPCODE: ClassVar[int] = 0x16
    CLASS: ClassVar[str] = "Q"
    QUEUED: ClassVar[bool] = True
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("heater", "u8", hi=1, limit="< heaters"),
        F("tolerance_dc", "u16", "0.1 C", lo=TOLERANCE_DC_RANGE[0], hi=TOLERANCE_DC_RANGE[1]),
    )


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
    rx_window: int
    heaters: int
    fans: int
    hotend_max_dc: int
    bed_max_dc: int
    watchdog_ms: int
    start_ticks: int
    items_received: int
    items_done: int
    segments_received: int
    segments_done: int
    clock: int
    OPCODE: ClassVar[int] = 0x41
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("nonce", "u16", "the HELLO's nonce (0: IDENTIFY)"),
        F("major", "u8"),
        F("minor", "u8"),
        F("boot_id", "u32", "new at every boot"),
        F("firmware_name", "text"),
        F("firmware_version", "text"),
        F("axes", "u8", "4: three modules and the extruder", lo=4, hi=4),
        F("queue_capacity", "u16", "move-queue slots", lo=1),
        F("clock_hz", "u32", "unit of segment, dwell and clock ticks", lo=1000),
        F("max_step_rate", "u32", "steps/s on any one axis", lo=1),
        F("max_payload", "u8", "largest DATA payload it accepts", lo=48, hi=248),
        F("rx_window", "u16", "bytes of unacknowledged frames it can buffer", lo=64),
        F("heaters", "u8", "heater indices 0..heaters-1", hi=2),
        F("fans", "u8", "fan indices 0..fans-1", hi=8),
        F("hotend_max_dc", "u16", "highest hotend target, 0.1 C"),
        F("bed_max_dc", "u16", "highest bed target, 0.1 C"),
        F("watchdog_ms", "u16", "current host watchdog"),
        F("start_ticks", "u32", "current start threshold"),
        F("items_received", "u32"),
        F("items_done", "u32"),
        F("segments_received", "u32"),
        F("segments_done", "u32"),
        F("clock", "u32", "free-running device clock, ticks of clock_hz, wraps"),
    )

    @property
    def dwell_max_ticks(self) -> int:
        return DWELL_MAX_S * self.clock_hz


@dataclass(frozen=True)
class Status(Message):
    flags: int
    queue_free: int
    items_received: int
    items_done: int
    segments_done: int
    buffered_ticks: int
    motion_ticks: int
    clock: int
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
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("flags", "u8"),
        F("queue_free", "u16"),
        F("items_received", "u32"),
        F("items_done", "u32"),
        F("segments_done", "u32"),
        F("buffered_ticks", "u32", "queued motion not yet executed (saturates)"),
        F("motion_ticks", "u32", "sum of executed durations, wraps"),
        F("clock", "u32", "free-running device clock, wraps"),
        F("steps", "i32", "absolute step counters now", count=4),
        F("hotend_dc", "i16"),
        F("hotend_target_dc", "u16"),
        F("bed_dc", "i16"),
        F("bed_target_dc", "u16"),
        F("fan", "u8"),
        F("enabled_mask", "u8", hi=0x0F),
        F("homed_mask", "u8", hi=0x07),
        F("last_error", "u8", "ErrorCode of the last fault (0: none since boot)"),
        F("bad_frames", "u32", "wraps"),
        F("retransmits", "u32", "wraps"),
        F("naks_sent", "u32", "wraps"),
        F("duplicates", "u32", "wraps"),
    )


@dataclass(frozen=True)
class Event(Message):
    code: int
    item: int
    values: tuple[int, ...] = field(default=())
    OPCODE: ClassVar[int] = 0x43
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("code", "u8", "EventCode"),
        F("item", "u32"),
        F("values", "i32", "a u8 count, then the values", count=MAX_EVENT_VALUES, counted=True),
    )


@dataclass(frozen=True)
class Error(Message):
    """``item``/``segment``: the queue item and segment number where it happened (0: none)."""

    code: int
    item: int
    segment: int
    axis: int = 0xFF
    value: int = 0
    OPCODE: ClassVar[int] = 0x44
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("code", "u8", "ErrorCode"),
        F("item", "u32"),
        F("segment", "u32"),
        F("axis", "u8", "axis, heater or opcode it concerns (255: none)"),
        F("value", "i32"),
    )


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
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("boot_id", "u32"),
        F("cause", "u8", "BootCause"),
        F("major", "u8"),
        F("minor", "u8"),
        F("prev_valid", "u8", hi=1),
        F("prev_items_done", "u32"),
        F("prev_segments_done", "u32"),
    )


@dataclass(frozen=True)
class EstopAck(Message):
    items_done: int
    segments_done: int
    OPCODE: ClassVar[int] = 0x46
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (F("items_done", "u32"), F("segments_done", "u32"))


@dataclass(frozen=True)
class Flow(Message):
    """Carried by the device's ACK and NAK frames: flow control, progress and clock."""

    flags: int
    queue_free: int
    items_done: int
    segments_done: int
    buffered_ticks: int = 0
    clock: int = 0
    OPCODE: ClassVar[int] = 0x47
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("flags", "u8"),
        F("queue_free", "u16"),
        F("items_done", "u32"),
        F("segments_done", "u32"),
        F("buffered_ticks", "u32", "queued motion not yet executed (saturates)"),
        F("clock", "u32", "free-running device clock, wraps"),
    )


MESSAGES: tuple[type[Message], ...] = (
    Identify,
    GetStatus,
    ClearFault,
    Flush,
    Hello,
    EmergencyStop,
    Configure,
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
_BY_OPCODE: dict[int, type[Message]] = {cls.OPCODE: cls for cls in MESSAGES}


# ------------------------------------------------------------------ codec


def _check(msg: Message, f: Field, value: int) -> None:
    lo, hi = f.range
    if not (isinstance(value, int) and lo <= value <= hi):
        raise MessageError(
            f"{type(msg).__name__}.{f.name}: {value!r} outside {lo}..{hi}", opcode=msg.OPCODE
        )


def _put(out: bytearray, msg: Message, f: Field, value: int) -> None:
    _check(msg, f, value)
    if f.type == "u8":
        out.append(value)
    elif f.type[0] == "u":
        out += encode_uvarint(value)
    else:
        out += encode_svarint(value)


def _encode_fields(msg: Message) -> bytes:
    out = bytearray((msg.OPCODE,))
    for f in msg.FIELDS:
        value = getattr(msg, f.name)
        if f.type == "text":
            raw = str(value).encode("ascii", "replace")[:MAX_TEXT]
            out.append(len(raw))
            out += raw
        elif f.count == 1:
            _put(out, msg, f, value)
        elif f.counted:
            if len(value) > f.count:
                raise MessageError(f"{type(msg).__name__}.{f.name}: more than {f.count} values")
            out.append(len(value))
            for v in value:
                _put(out, msg, f, v)
        else:
            if len(value) != f.count:
                raise MessageError(f"{type(msg).__name__}.{f.name}: needs {f.count} values")
            mask = getattr(msg, f.mask) if f.mask else (1 << f.count) - 1
            for k, v in enumerate(value):
                if mask >> k & 1:
                    _put(out, msg, f, v)
    return bytes(out)


class _Reader:
    __slots__ = ("buf", "pos")

    def __init__(self, buf: bytes, pos: int):
        self.buf = buf
        self.pos = pos

    def value(self, f: Field) -> int:
        if f.type == "u8":
            if self.pos >= len(self.buf):
                raise MessageError(f"{f.name}: truncated byte field")
            v = self.buf[self.pos]
            self.pos += 1
        elif f.type[0] == "u":
            v, self.pos = decode_ubounded(self.buf, self.pos, _BITS[f.type])
        else:
            v, self.pos = decode_sbounded(self.buf, self.pos, _BITS[f.type])
        lo, hi = f.range
        if not lo <= v <= hi:
            raise MessageError(f"{f.name}: {v} outside {lo}..{hi}")
        return v

    def text(self, f: Field) -> str:
        n = self.value(_TEXT_LEN)
        if self.pos + n > len(self.buf):
            raise MessageError(f"{f.name}: truncated text")
        self.pos += n
        return self.buf[self.pos - n : self.pos].decode("ascii", "replace")


_TEXT_LEN = Field("length", "u8", hi=MAX_TEXT)


def _decode_fields(cls: type[Message], r: _Reader) -> Message:
    values: dict[str, Any] = {}
    for f in cls.FIELDS:
        if f.type == "text":
            values[f.name] = r.text(f)
        elif f.count == 1:
            values[f.name] = r.value(f)
        elif f.counted:
            n = r.value(Field(f.name, "u8", hi=f.count))
            values[f.name] = tuple(r.value(f) for _ in range(n))
        else:
            mask = values[f.mask] if f.mask else (1 << f.count) - 1
            values[f.name] = tuple(r.value(f) if mask >> k & 1 else 0 for k in range(f.count))
    return cls(**values)


def encode_messages(messages: list[Message] | tuple[Message, ...], ctx: SegmentContext) -> bytes:
    """Encode messages into one payload, advancing the segment context."""
    out = bytearray()
    for msg in messages:
        if isinstance(msg, Segment):
            out += encode_one_segment(msg.ticks, msg.deltas, msg.ramp, ctx)
        else:
            out += _encode_fields(msg)
    return bytes(out)


def encode_message(msg: Message) -> bytes:
    """A single non-segment message."""
    return _encode_fields(msg)


def decode_messages(payload: bytes, ctx: SegmentContext) -> list[Message]:
    """Decode a whole payload; the context advances only if the payload parses.

    Raises :class:`MessageError` (with the offset and opcode of the bad message) for an
    unknown opcode, a truncated field, a varint longer than its field allows, or a value
    outside its field's fixed range."""
    work = ctx.copy()
    out: list[Message] = []
    pos = 0
    op = 0
    try:
        while pos < len(payload):
            op = payload[pos]
            if op >= SEG_BASE:
                ticks, deltas, ramp, nxt = decode_segment(payload, pos, work)
                out.append(Segment(ticks, deltas, ramp))
                pos = nxt
                continue
            cls = _BY_OPCODE.get(op)
            if cls is None:
                raise MessageError(f"unknown opcode 0x{op:02X}")
            r = _Reader(payload, pos + 1)
            out.append(_decode_fields(cls, r))
            pos = r.pos
    except (VarintError, MessageError, ValueError) as exc:
        raise MessageError(
            f"bad message 0x{op:02X} at payload byte {pos}: {exc}", offset=pos, opcode=op
        ) from None
    ctx.prev_ticks, ctx.prev_deltas = work.prev_ticks, work.prev_deltas
    return out
