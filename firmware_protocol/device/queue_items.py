"""The device's queue slots: item kinds and the plain tuple each slot holds."""

from __future__ import annotations

from typing import Any, NamedTuple

from firmware_protocol.messages import (
    DWELL_MAX_S,
    Autotune,
    Dwell,
    Enable,
    Home,
    Message,
    Segment,
    SetFan,
    SetHeater,
    SetPosition,
    WaitHeater,
)
from firmware_protocol.ramp_profile import RAMP_TO_REST

SEG, DWELL, HOME, SETPOS, ENABLE, HEATER, FAN, WAIT, TUNE = range(9)
TIMED = (SEG, DWELL, HOME)
HOLDING = (WAIT, TUNE)  # hold the queue until a heater says so
U32 = 0xFFFF_FFFF


class Item(NamedTuple):
    """One queue slot (a tuple: cheap to make, nothing for the garbage collector to follow).

    ``arg``: SEG (the mask of the axes its schedule block carries,) or ();
    SETPOS the four positions; ENABLE (mask,); HOME (mask, positions);
    HEATER/FAN/WAIT (index, value); TUNE (heater, target_dc, cycles)."""

    kind: int
    item: int  # queue item number
    seg: int  # segment number (segments only)
    ticks: int
    deltas: tuple[int, int, int, int]
    ramp: int
    arg: tuple[Any, ...]
    arrival: float  # device time it was queued


def make_item(
    kind: int,
    number: int,
    arrival: float,
    *,
    seg: int = 0,
    ticks: int = 0,
    deltas: tuple[int, int, int, int] = (0, 0, 0, 0),
    ramp: int = -1,
    arg: tuple[Any, ...] = (),
) -> Item:
    return Item(kind, number, seg, ticks, deltas, ramp, arg, arrival)


def _ends_block(item: Item) -> bool:
    """A segment that ends at rest, or any item that is not a segment."""
    return item.kind != SEG or item.ramp == RAMP_TO_REST or not any(item.deltas)


class BadValue(NamedTuple):
    """A queued command whose value is out of this device's range (``ERROR BAD_VALUE``)."""

    value: int


def item_of(
    msg: Message,
    n: int,
    T: float,
    seg: int,
    clock_hz: int,
    heaters: int,
    fans: int,
    min_ticks: int = 1,
) -> Item | BadValue:
    """The queue slot for queued command ``msg`` (item number ``n``, segment number ``seg``
    for a segment, arriving at device time ``T``), or the value the device refuses."""
    if isinstance(msg, Segment):
        if msg.ticks < min_ticks:
            return BadValue(msg.ticks)
        scheduled = sum(1 << axis for axis, _ in msg.schedules)
        return make_item(
            SEG,
            n,
            T,
            seg=seg,
            ticks=msg.ticks,
            deltas=msg.deltas,
            ramp=msg.ramp,
            arg=(scheduled,) if scheduled else (),
        )
    if isinstance(msg, Dwell):
        if msg.ticks > DWELL_MAX_S * clock_hz:
            return BadValue(msg.ticks)
        return make_item(DWELL, n, T, ticks=msg.ticks)
    if isinstance(msg, Home):
        return make_item(HOME, n, T, arg=(msg.mask, msg.positions))
    if isinstance(msg, SetPosition):
        return make_item(SETPOS, n, T, arg=msg.steps)
    if isinstance(msg, Enable):
        return make_item(ENABLE, n, T, arg=(msg.mask,))
    if isinstance(msg, (SetHeater, WaitHeater, Autotune)) and msg.heater >= heaters:
        return BadValue(msg.heater)
    if isinstance(msg, SetHeater):
        return make_item(HEATER, n, T, arg=(msg.heater, msg.target_dc))
    if isinstance(msg, WaitHeater):
        return make_item(WAIT, n, T, arg=(msg.heater, msg.tolerance_dc))
    if isinstance(msg, Autotune):
        return make_item(TUNE, n, T, arg=(msg.heater, msg.target_dc, msg.cycles))
    if isinstance(msg, SetFan):
        if msg.fan >= fans:
            return BadValue(msg.fan)
        return make_item(FAN, n, T, arg=(msg.fan, msg.value))
    return BadValue(0)  # not a queued command
