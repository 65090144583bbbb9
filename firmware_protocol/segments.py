"""Timed joint-space move segments and their vectorised wire encoder (the device side
decodes one segment at a time).

A segment is a duration ``D`` in device ticks, signed step deltas ``n`` for the four
axes (three slider modules, extruder) and a ramp code: the time profile every axis
follows (:mod:`firmware_protocol.ramp_profile`).

Protocol 3.0: a segment may carry a schedule block after its ramp byte (flag
``F_SCHEDULE``): the step schedules of the axes the device cannot predict
(:mod:`firmware_protocol.schedule_block`, :mod:`firmware_protocol.step_schedule`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from firmware_protocol.ramp_profile import RAMP_CONSTANT, RAMP_TO_REST, ramp_share
from firmware_protocol.schedule_block import ScheduleBlockError, encode_block, parse_block
from firmware_protocol.step_schedule import AxisSchedule, reciprocal_table
from firmware_protocol.varint import (
    VarintError,
    encode_uvarint,
    scatter_uvarints,
    uvarint_lengths,
    zigzag,
    zigzag_array,
)

AXES = 4
MAX_TICKS = (1 << 32) - 1  # durations are u32
MAX_DELTA = (1 << 31) - 1  # deltas (and positions) are i32

SEG_BASE = 0x80
F_RAMP = 0x01  # a ramp byte follows the deltas
F_DURATION = 0x02  # a duration varint follows the opcode; else the previous duration
F_PREDICTED = 0x04  # coded deltas are differences from the previous segment's deltas
F_SLIDERS = 0x08  # three slider svarints present; else coded values are 0
F_EXTRUDER = 0x10  # extruder svarint present; else coded value is 0
F_SCHEDULE = 0x20  # 3.0: a schedule block follows the ramp byte
#: a segment without its block takes at most this many bytes (section 5.2)
SEGMENT_MAX_BYTES = 27
F_RESERVED = 0x40
CYCLES_PER_TICK = 160  # cpu_hz / clock_hz of the AVR (16 MHz, 100 kHz): the default


@dataclass(frozen=True)
class SegmentBatch:
    """N segments as arrays: ``ticks`` (N,) int64, ``deltas`` (N, 4) int64, ``ramps`` (N,) int16."""

    ticks: np.ndarray
    deltas: np.ndarray
    ramps: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int16))

    def __post_init__(self) -> None:
        ticks = np.ascontiguousarray(self.ticks, dtype=np.int64).reshape(-1)
        deltas = np.ascontiguousarray(self.deltas, dtype=np.int64).reshape(-1, AXES)
        given = [] if self.ramps is None else self.ramps
        ramps = np.ascontiguousarray(given, dtype=np.int16).reshape(-1)
        if len(ramps) == 0 and len(ticks):  # none given: constant speed
            ramps = np.full(ticks.shape, RAMP_CONSTANT, dtype=np.int16)
        if not (len(ticks) == len(deltas) == len(ramps)):
            raise ValueError(
                f"segment arrays differ in length: {len(ticks)}, {len(deltas)}, {len(ramps)}"
            )
        if len(ticks) and (ticks.min() < 1 or ticks.max() > MAX_TICKS):
            raise ValueError(f"segment durations must be 1..{MAX_TICKS} ticks")
        if len(ticks) and np.abs(deltas).max() > MAX_DELTA:
            raise ValueError(f"segment step deltas must be within +-{MAX_DELTA}")
        if len(ticks) and (ramps.min() < RAMP_CONSTANT or ramps.max() > RAMP_TO_REST):
            raise ValueError("ramp codes must be -1 (constant) or 0..255")
        object.__setattr__(self, "ticks", ticks)
        object.__setattr__(self, "deltas", deltas)
        object.__setattr__(self, "ramps", ramps)

    def __len__(self) -> int:
        return len(self.ticks)

    def __getitem__(self, index: slice) -> SegmentBatch:
        return SegmentBatch(self.ticks[index], self.deltas[index], self.ramps[index])

    @staticmethod
    def concat(batches: list[SegmentBatch]) -> SegmentBatch:
        return SegmentBatch(
            np.concatenate([b.ticks for b in batches]),
            np.concatenate([b.deltas for b in batches]),
            np.concatenate([b.ramps for b in batches]),
        )


def segments_from_positions(
    positions: np.ndarray, ticks: np.ndarray, ramps: np.ndarray | None = None
) -> SegmentBatch:
    """Segments between consecutive absolute step positions ``positions`` (N+1, 4)."""
    pos = np.asarray(positions, dtype=np.int64)
    if ramps is None:
        return SegmentBatch(ticks, np.diff(pos, axis=0))
    return SegmentBatch(ticks, np.diff(pos, axis=0), ramps)


def peak_step_rates(batch: SegmentBatch, clock_hz: int) -> np.ndarray:
    """(N, 4) peak step rate of each axis in steps/s: the larger of start and end speed."""
    r = ramp_share(batch.ramps)
    factor = np.maximum(2.0 * r, 2.0 - 2.0 * r)
    return np.abs(batch.deltas) * (factor * clock_hz / batch.ticks)[:, None]


# ------------------------------------------------------------------ wire codec


@lru_cache(maxsize=8)
def _table(cycles_per_tick: int) -> np.ndarray:
    table = reciprocal_table(cycles_per_tick)
    table.setflags(write=False)
    return table


@dataclass
class SegmentContext:
    """Coder state shared by consecutive segments of one session (reset by HELLO), and
    the device's ``cpu_hz / clock_hz`` (IDENT), which its schedule blocks are coded
    against (the reciprocal table's prediction)."""

    prev_ticks: int = 0
    prev_deltas: tuple[int, int, int, int] = (0, 0, 0, 0)
    cycles_per_tick: int = CYCLES_PER_TICK

    def copy(self) -> SegmentContext:
        return SegmentContext(self.prev_ticks, self.prev_deltas, self.cycles_per_tick)

    @property
    def table(self) -> np.ndarray:
        """The device's table of reciprocals (step_schedule.reciprocal_table)."""
        return _table(self.cycles_per_tick)


Schedules = Mapping[int, AxisSchedule]


def encode_block_for(
    ticks: int, deltas: tuple[int, ...], schedules: Schedules, ctx: SegmentContext
) -> bytes:
    """The schedule block of one segment (empty when it carries none)."""
    if not schedules:
        return b""
    return encode_block(deltas, ticks, schedules, ctx.table)


def _coded_cost(z: np.ndarray) -> np.ndarray:
    """Bytes for coded values ``z`` (N, 4 zigzagged) under the omission flags."""
    lens = uvarint_lengths(z)
    sliders = np.where(z[:, :3].any(axis=1), lens[:, :3].sum(axis=1), 0)
    return sliders + np.where(z[:, 3] != 0, lens[:, 3], 0)


def encode_segments(
    batch: SegmentBatch,
    ctx: SegmentContext,
    schedules: Mapping[tuple[int, int], AxisSchedule] | None = None,
) -> tuple[bytes, np.ndarray]:
    """Encode a batch; returns ``(data, offsets)`` with segment i at ``data[offsets[i]:offsets[i+1]]``.

    Chooses per segment the shorter of plain and predicted deltas, omits a duration
    equal to the previous one, and advances ``ctx``. ``schedules`` by ``(segment, axis)``
    (:func:`step_schedule.plan_schedules`): each segment that has one carries its block.
    """
    data, offsets = _encode_plain(batch, ctx)
    if not schedules:
        return data, offsets
    by_segment: dict[int, dict[int, AxisSchedule]] = {}
    for (i, k), sched in schedules.items():
        by_segment.setdefault(int(i), {})[int(k)] = sched
    rows = sorted(by_segment)
    blocks = [
        encode_block_for(
            int(batch.ticks[i]), tuple(int(v) for v in batch.deltas[i]), by_segment[i], ctx
        )
        for i in rows
    ]
    out = np.frombuffer(data, dtype=np.uint8).copy()
    idx = np.asarray(rows, dtype=np.int64)
    out[offsets[idx]] |= F_SCHEDULE
    lens = np.zeros(len(batch), dtype=np.int64)
    lens[idx] = [len(b) for b in blocks]
    where = np.repeat(offsets[idx + 1], lens[idx])
    out = np.insert(out, where, np.frombuffer(b"".join(blocks), dtype=np.uint8))
    shifted = offsets.copy()
    shifted[1:] += np.cumsum(lens)
    return out.tobytes(), shifted


def _encode_plain(batch: SegmentBatch, ctx: SegmentContext) -> tuple[bytes, np.ndarray]:
    """The segments without their blocks."""
    n = len(batch)
    if n == 0:
        return b"", np.zeros(1, dtype=np.int64)
    d = batch.deltas
    prev_d = np.vstack([np.asarray(ctx.prev_deltas, dtype=np.int64)[None, :], d[:-1]])
    prev_t = np.concatenate([[ctx.prev_ticks], batch.ticks[:-1]])
    z_plain = zigzag_array(d)
    diff = d - prev_d
    z_pred = zigzag_array(diff)
    # a predicted value must itself fit the i32 field
    use_pred = (_coded_cost(z_pred) < _coded_cost(z_plain)) & (
        np.abs(diff).max(axis=1) <= MAX_DELTA
    )
    z = np.where(use_pred[:, None], z_pred, z_plain)
    has_dur = batch.ticks != prev_t
    has_sl = np.asarray(z[:, :3].any(axis=1))
    has_e = np.asarray(z[:, 3] != 0)
    has_r = np.asarray(batch.ramps != RAMP_CONSTANT)
    lens = uvarint_lengths(z)
    len_dur = np.where(has_dur, uvarint_lengths(batch.ticks.astype(np.uint64)), 0)
    len_sl = np.where(has_sl[:, None], lens[:, :3], 0)
    len_e = np.where(has_e, lens[:, 3], 0)
    seg_len = 1 + len_dur + len_sl.sum(axis=1) + len_e + has_r
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(seg_len, out=offsets[1:])
    out = np.zeros(int(offsets[-1]), dtype=np.uint8)
    start = offsets[:-1]
    out[start] = (
        SEG_BASE
        | F_RAMP * has_r
        | F_DURATION * has_dur
        | F_PREDICTED * use_pred
        | F_SLIDERS * has_sl
        | F_EXTRUDER * has_e
    ).astype(np.uint8)
    pos = start + 1
    scatter_uvarints(out, pos, batch.ticks.astype(np.uint64), len_dur)
    pos = pos + len_dur
    for k in range(3):
        scatter_uvarints(out, pos, z[:, k], len_sl[:, k])
        pos = pos + len_sl[:, k]
    scatter_uvarints(out, pos, z[:, 3], len_e)
    pos = pos + len_e
    out[pos[has_r]] = batch.ramps[has_r].astype(np.uint8)
    ctx.prev_ticks = int(batch.ticks[-1])
    ctx.prev_deltas = tuple(int(v) for v in d[-1])  # type: ignore[assignment]
    return out.tobytes(), offsets


def encode_one_segment(
    ticks: int,
    deltas: tuple[int, int, int, int],
    ramp: int,
    ctx: SegmentContext,
    schedules: Schedules | None = None,
) -> bytes:
    """One segment, scalar (the vectorised :func:`encode_segments` makes the same bytes);
    ``schedules`` by axis: its block."""
    if not 1 <= ticks <= MAX_TICKS or any(abs(d) > MAX_DELTA for d in deltas):
        raise ValueError(f"segment out of range: {ticks} ticks, deltas {deltas}")
    if not RAMP_CONSTANT <= ramp <= RAMP_TO_REST:
        raise ValueError(f"ramp code {ramp} outside -1..255")
    plain = [zigzag(d) for d in deltas]
    pred = [zigzag(d - p) for d, p in zip(deltas, ctx.prev_deltas)]

    def cost(z: list[int]) -> int:
        sl = sum(len(encode_uvarint(v)) for v in z[:3]) if any(z[:3]) else 0
        return sl + (len(encode_uvarint(z[3])) if z[3] else 0)

    fits = all(abs(d - p) <= MAX_DELTA for d, p in zip(deltas, ctx.prev_deltas))
    use_pred = fits and cost(pred) < cost(plain)
    z = pred if use_pred else plain
    op = SEG_BASE | (F_PREDICTED if use_pred else 0)
    out = bytearray()
    if ticks != ctx.prev_ticks:
        op |= F_DURATION
        out += encode_uvarint(ticks)
    if any(z[:3]):
        op |= F_SLIDERS
        for v in z[:3]:
            out += encode_uvarint(v)
    if z[3]:
        op |= F_EXTRUDER
        out += encode_uvarint(z[3])
    if ramp != RAMP_CONSTANT:
        op |= F_RAMP
        out.append(ramp)
    if schedules:
        op |= F_SCHEDULE
        out += encode_block_for(ticks, deltas, schedules, ctx)
    ctx.prev_ticks = ticks
    ctx.prev_deltas = (deltas[0], deltas[1], deltas[2], deltas[3])
    return bytes((op,)) + bytes(out)


class SegmentDecodeError(ValueError):
    pass


def _u32(buf: bytes, pos: int) -> tuple[int, int]:
    """A u32 varint: at most 5 bytes, value below 2**32 (what a firmware's parser accepts)."""
    value = 0
    shift = 0
    while True:
        if pos >= len(buf):
            raise VarintError("truncated varint")
        byte = buf[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        if byte < 0x80:
            if value > 0xFFFF_FFFF:
                raise VarintError(f"value {value} does not fit 32 bits")
            return value, pos
        shift += 7
        if shift >= 35:
            raise VarintError("varint longer than 5 bytes for a 32-bit field")


def decode_segment(
    buf: bytes, pos: int, ctx: SegmentContext
) -> tuple[int, tuple[int, int, int, int], int, dict[int, AxisSchedule], int]:
    """Decode the segment whose opcode is at ``buf[pos]``; returns ``(ticks, deltas, ramp,
    schedules, next_pos)``, ``schedules`` by axis (empty without a block).

    Every field is bounded as on the wire: the duration is a u32 of 1 or more, each coded
    delta an i32, and a predicted delta (coded + previous) must stay within i32. A block
    is checked for its form only (:func:`schedule_block.parse_block`); what it says of
    its segment is the device's check (``BAD_VALUE``, not a malformed payload)."""
    op = buf[pos]
    pos += 1
    if op & F_RESERVED:
        raise SegmentDecodeError(f"segment opcode 0x{op:02X} has reserved flag bits set")
    if op & F_DURATION:
        ticks, pos = _u32(buf, pos)
    else:
        ticks = ctx.prev_ticks
    if ticks < 1:
        raise SegmentDecodeError(f"segment duration {ticks} ticks out of range")
    c0 = c1 = c2 = c3 = 0
    if op & F_SLIDERS:
        c0, pos = _u32(buf, pos)
        c1, pos = _u32(buf, pos)
        c2, pos = _u32(buf, pos)
        c0 = (c0 >> 1) ^ -(c0 & 1)
        c1 = (c1 >> 1) ^ -(c1 & 1)
        c2 = (c2 >> 1) ^ -(c2 & 1)
    if op & F_EXTRUDER:
        c3, pos = _u32(buf, pos)
        c3 = (c3 >> 1) ^ -(c3 & 1)
    if op & F_PREDICTED:
        p = ctx.prev_deltas
        c0 += p[0]
        c1 += p[1]
        c2 += p[2]
        c3 += p[3]
    if max(abs(c0), abs(c1), abs(c2), abs(c3)) > MAX_DELTA:
        raise SegmentDecodeError("step delta outside -(2**31 - 1)..2**31 - 1")
    if op & F_RAMP:
        if pos >= len(buf):
            raise SegmentDecodeError("truncated ramp byte")
        ramp = buf[pos]
        pos += 1
    else:
        ramp = RAMP_CONSTANT
    deltas = (c0, c1, c2, c3)
    schedules: dict[int, AxisSchedule] = {}
    if op & F_SCHEDULE:
        try:
            schedules, pos = parse_block(buf, pos, deltas, ticks, ctx.table)
        except ScheduleBlockError as exc:
            raise SegmentDecodeError(f"schedule block: {exc}") from None
    ctx.prev_ticks = ticks
    ctx.prev_deltas = deltas
    return ticks, deltas, ramp, schedules, pos
