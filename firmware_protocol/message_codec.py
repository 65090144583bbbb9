"""The payload codec of the message table (:mod:`firmware_protocol.messages`).

A DATA payload is a sequence of messages, each an opcode byte and its fields in table
order; move segments (opcodes 0x80..0xFF) go through :mod:`firmware_protocol.segments`.
Every value is checked against its field's range on the way out and on the way in.
"""

from __future__ import annotations

from typing import Any

from firmware_protocol.fields import _BITS
from firmware_protocol.messages import (
    _BY_OPCODE,
    MAX_TEXT,
    Field,
    Message,
    MessageError,
    Segment,
)
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
            out += encode_one_segment(msg.ticks, msg.deltas, msg.ramp, ctx, dict(msg.schedules))
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
                ticks, deltas, ramp, scheds, nxt = decode_segment(payload, pos, work)
                out.append(Segment(ticks, deltas, ramp, tuple(sorted(scheds.items()))))
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
