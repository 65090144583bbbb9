"""The wire form of a segment's schedule block (docs/step-engine.md, section 6; draft of
protocol 3.0): the step schedules of the axes the device cannot predict.

    mask     u8        axes carrying a schedule (bits 0..3; the others must be 0)
    for each axis in the mask, in axis order:
      lead     i32     first edge, against half the first chunk's interval
      interval i32     first chunk's interval, against the device's guess
      add      i32     first chunk's add
      more     u8      further chunks (0..MAX_CHUNKS - 1)
      for each further chunk:
        count    u16   1..65535
        interval i32   against the first chunk's interval
        add      i32

Every value is fixed point (``FRAC_BITS`` of a cycle) and signed ones are zigzag varints.
The first chunk's count is what the others leave of ``|n|`` (at least 1), so the counts
add up to the segment's steps whatever the bytes say. The device's guess for the first
interval is its prediction (:func:`step_schedule.predicted_interval`) where it makes one
(``|n|`` and ``D`` within its table), else 0.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from firmware_protocol.step_schedule import (
    MAX_COUNT,
    MAX_INTERVAL,
    PREDICT_MAX_STEPS,
    PREDICT_MAX_TICKS,
    AxisSchedule,
    Chunk,
    predicted_interval,
)
from firmware_protocol.varint import (
    VarintError,
    decode_sbounded,
    decode_ubounded,
    encode_svarint,
    encode_uvarint,
)

AXES = 4
MAX_CHUNKS = 32  # chunks of one axis in one segment
I32_MIN, I32_MAX = -(1 << 31), (1 << 31) - 1


class ScheduleBlockError(ValueError):
    """A malformed schedule block, or one that does not fit its segment."""


def guess_interval(steps: int, ticks: int, table: np.ndarray) -> int:
    """The device's guess for an axis's first interval: its prediction, else 0."""
    n = abs(steps)
    if 1 <= n <= PREDICT_MAX_STEPS and ticks <= PREDICT_MAX_TICKS:
        return int(predicted_interval(np.array(n), np.array(ticks), table))
    return 0


def _i32(value: int, what: str) -> bytes:
    if not I32_MIN <= value <= I32_MAX:
        raise ScheduleBlockError(f"{what} {value} does not fit 32 bits")
    return encode_svarint(value)


def _check(sched: AxisSchedule, steps: int, axis: int) -> None:
    chunks = sched.chunks
    if not 1 <= len(chunks) <= MAX_CHUNKS:
        raise ScheduleBlockError(f"axis {axis}: {len(chunks)} chunks, 1..{MAX_CHUNKS} allowed")
    if sched.count != abs(steps):
        raise ScheduleBlockError(
            f"axis {axis}: its chunks count {sched.count} steps of {abs(steps)}"
        )
    if sched.lead < 0:
        raise ScheduleBlockError(f"axis {axis}: first edge {sched.lead} before the segment")
    for c in chunks:
        if not 1 <= c.count <= MAX_COUNT:
            raise ScheduleBlockError(
                f"axis {axis}: chunk count {c.count} outside 1..{MAX_COUNT}"
                f" (its chunks count {sum(x.count for x in chunks[1:])} further steps"
                f" of {abs(steps)})"
            )
        if not 1 <= c.interval <= MAX_INTERVAL:
            raise ScheduleBlockError(f"axis {axis}: interval {c.interval} out of range")


def encode_block(
    deltas: Sequence[int],
    ticks: int,
    schedules: Mapping[int, AxisSchedule],
    table: np.ndarray,
) -> bytes:
    """The block for one segment (``deltas``, ``ticks``): ``schedules`` by axis."""
    if set(schedules) - set(range(AXES)):
        raise ScheduleBlockError(f"axes {sorted(schedules)}: 0..{AXES - 1} only")
    mask = 0
    out = bytearray()
    for axis in range(AXES):
        sched = schedules.get(axis)
        if sched is None:
            continue
        _check(sched, int(deltas[axis]), axis)
        mask |= 1 << axis
        first, *more = sched.chunks
        out += _i32(sched.lead - (first.interval >> 1), "lead")
        guess = guess_interval(int(deltas[axis]), ticks, table)
        out += _i32(first.interval - guess, "interval")
        out += _i32(first.add, "add")
        out += encode_uvarint(len(more))
        for c in more:
            out += encode_uvarint(c.count)
            out += _i32(c.interval - first.interval, "interval")
            out += _i32(c.add, "add")
    if not mask:
        raise ScheduleBlockError("a schedule block carries at least one axis")
    return bytes((mask,)) + bytes(out)


def decode_block(
    buf: bytes, pos: int, deltas: Sequence[int], ticks: int, table: np.ndarray
) -> tuple[dict[int, AxisSchedule], int]:
    """The block at ``buf[pos]`` for its segment; ``(schedules by axis, next_pos)``.

    Raises :class:`ScheduleBlockError` for anything a device must refuse: a truncated or
    overlong field, reserved mask bits, an axis without steps, counts that leave the first
    chunk nothing, an interval or first edge out of range."""
    schedules, pos = parse_block(buf, pos, deltas, ticks, table)
    check_block(schedules, deltas)
    return schedules, pos


def parse_block(
    buf: bytes, pos: int, deltas: Sequence[int], ticks: int, table: np.ndarray
) -> tuple[dict[int, AxisSchedule], int]:
    """The block at ``buf[pos]`` as its bytes say, checked only for its form (what makes a
    payload malformed: a truncated or overlong field, reserved mask bits, too many
    chunks); :func:`check_block` checks it against its segment (a device's ``BAD_VALUE``).
    The first chunk's count is what the others leave of ``|n|``, whatever that is."""
    try:
        return _parse(buf, pos, deltas, ticks, table)
    except VarintError as exc:
        raise ScheduleBlockError(str(exc)) from exc


def check_block(schedules: Mapping[int, AxisSchedule], deltas: Sequence[int]) -> None:
    """A parsed block against its segment: each axis has steps, its chunks are within
    their limits and count ``|n|``, its first edge is not before the segment. Raises
    :class:`ScheduleBlockError` naming the axis."""
    for axis, sched in schedules.items():
        steps = abs(int(deltas[axis]))
        if steps == 0:
            raise ScheduleBlockError(f"axis {axis} has a schedule but no steps")
        _check(sched, steps, axis)


def _parse(
    buf: bytes, pos: int, deltas: Sequence[int], ticks: int, table: np.ndarray
) -> tuple[dict[int, AxisSchedule], int]:
    if pos >= len(buf):
        raise ScheduleBlockError("truncated schedule block")
    mask = buf[pos]
    pos += 1
    if mask == 0 or mask >> AXES:
        raise ScheduleBlockError(f"schedule mask 0x{mask:02X}: axes 0..{AXES - 1}, at least one")
    out: dict[int, AxisSchedule] = {}
    for axis in range(AXES):
        if not mask >> axis & 1:
            continue
        steps = abs(int(deltas[axis]))
        lead_c, pos = decode_sbounded(buf, pos, 32)
        int_c, pos = decode_sbounded(buf, pos, 32)
        add, pos = decode_sbounded(buf, pos, 32)
        more, pos = decode_ubounded(buf, pos, 8)
        if more >= MAX_CHUNKS:
            raise ScheduleBlockError(f"axis {axis}: {more + 1} chunks, at most {MAX_CHUNKS}")
        interval = int_c + guess_interval(steps, ticks, table)
        rest: list[Chunk] = []
        for _ in range(more):
            count, pos = decode_ubounded(buf, pos, 16)
            d_int, pos = decode_sbounded(buf, pos, 32)
            c_add, pos = decode_sbounded(buf, pos, 32)
            rest.append(Chunk(count, interval + d_int, c_add))
        first_count = steps - sum(c.count for c in rest)
        out[axis] = AxisSchedule(
            (interval >> 1) + lead_c, (Chunk(first_count, interval, add), *rest)
        )
    return out, pos
