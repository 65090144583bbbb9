"""Host -> device messages: the commands (PROTOCOL.md section 4), immediate, queued or
urgent, each with its wire table."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from firmware_protocol.fields import F, Field
from firmware_protocol.message_base import (
    AUTOTUNE_CYCLES_RANGE,
    DWELL_MAX_S,
    LEASE_MS_RANGE,
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    TOLERANCE_DC_RANGE,
    WATCHDOG_MS_DEFAULT,
    WATCHDOG_MS_RANGE,
    Message,
)
from firmware_protocol.segments import SEG_BASE
from firmware_protocol.step_schedule import AxisSchedule


@dataclass(frozen=True)
class Segment(Message):
    """One timed move segment (see segments.py); ``ramp`` -1 is constant speed;
    ``schedules`` (3.0) the ``(axis, schedule)`` pairs of its block, in axis order (none:
    the device predicts every moving axis)."""

    ticks: int
    deltas: tuple[int, int, int, int]
    ramp: int = -1
    schedules: tuple[tuple[int, AxisSchedule], ...] = ()
    OPCODE: ClassVar[int] = SEG_BASE
    CLASS: ClassVar[str] = "Q"
    QUEUED: ClassVar[bool] = True

    def __repr__(self) -> str:  # a segment without a block reads as in 2.x
        more = f", schedules={self.schedules!r}" if self.schedules else ""
        return f"Segment(ticks={self.ticks}, deltas={self.deltas}, ramp={self.ramp}{more})"


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


# host -> device, immediate, protocol 2.1
@dataclass(frozen=True)
class SetLimits(Message):
    """Soft travel limits of one module, in step counts (the frame HOME and SET_POSITION
    set), inclusive; checked for a homed module only."""

    module: int
    lo: int
    hi: int
    OPCODE: ClassVar[int] = 0x08
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("module", "u8", "0..2", hi=2),
        F("lo", "i32", "lowest allowed position"),
        F("hi", "i32", "highest allowed position (>= lo)"),
    )


@dataclass(frozen=True)
class SetPid(Message):
    """PID gains of one heater in thousandths: output 0..255 per degree C (kp), per
    degree C second (ki), per degree C per second (kd). All three 0: the device's own."""

    heater: int
    kp: int
    ki: int
    kd: int
    OPCODE: ClassVar[int] = 0x09
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("heater", "u8", "0 hotend, 1 bed", hi=1, limit="< heaters"),
        F("kp", "u32", "thousandths"),
        F("ki", "u32", "thousandths"),
        F("kd", "u32", "thousandths"),
    )


@dataclass(frozen=True)
class HeaterLease(Message):
    """Heater targets stay set for ``ms`` from receipt (renewed by the host's job, never
    by its bare keep-alive); run out with a heater on: ``ERROR HEATER_LEASE``."""

    ms: int
    OPCODE: ClassVar[int] = 0x0A
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("ms", "u16", "lease length", lo=LEASE_MS_RANGE[0], hi=LEASE_MS_RANGE[1]),
    )


@dataclass(frozen=True)
class GetCaps(Message):
    """Device replies ``CAPS``."""

    OPCODE: ClassVar[int] = 0x0B


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
        F(
            "flags",
            "u8",
            "EstopFlag: 0x01 keep heaters, 0x02 keep motors (the default), 0x04 release motors",
            hi=0x07,
        ),
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


@dataclass(frozen=True)
class Autotune(Message):
    """PID autotune (relay method) of one heater around ``target_dc`` for ``cycles``
    cycles; holds the queue like WAIT_HEATER, leaves the heater off, answers
    ``EVENT AUTOTUNE_DONE`` (and applies the gains) or ``ERROR AUTOTUNE_FAILED``."""

    heater: int
    target_dc: int
    cycles: int = 5
    OPCODE: ClassVar[int] = 0x17
    CLASS: ClassVar[str] = "Q"
    QUEUED: ClassVar[bool] = True
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("heater", "u8", "0 hotend, 1 bed", hi=1, limit="< heaters"),
        F("target_dc", "u16", "0.1 C", lo=1, limit="<= hotend_max_dc / bed_max_dc"),
        F("cycles", "u8", lo=AUTOTUNE_CYCLES_RANGE[0], hi=AUTOTUNE_CYCLES_RANGE[1]),
    )
