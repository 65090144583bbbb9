"""The message set: one table of typed, bounded fields, and its payload codec.

A DATA payload is a sequence of messages, each starting with an opcode byte.
Opcodes 0x80..0xFF are move segments (the low bits are flags, see
:mod:`firmware_protocol.segments`); 0x01..0x3F are host commands; 0x40..0x7F are
device reports. Temperatures are integers in tenths of a degree Celsius.

Every field has a wire type with a fixed width (``u8``; ``u16``/``u32`` unsigned
varints of at most 3/5 bytes; ``i16``/``i32`` zigzag varints; ``text`` a length byte
and ASCII) and, where the protocol fixes one, a value range. The table
(``Message.FIELDS``) is the single source for the codec (:mod:`firmware_protocol.message_codec`), the device's checks and the
C header (:mod:`firmware_protocol.c_header`); PROTOCOL.md section 4 is its prose.
Ranges that depend on the device (heater count, maximum temperatures, clock) are
named by the ``Ident`` field that announces them and checked by the device.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

# the codes and field types are part of the message table's vocabulary: re-exported here
from firmware_protocol.codes import (
    HEATERS_OFF,
    THERMAL_ERRORS,
    AutotuneFailure,
    BootCause,
    ErrorCode,
    EstopFlag,
    EventCode,
    Flag,
)
from firmware_protocol.fields import (
    MAX_TEXT,
    TYPE_RANGE,
    F,
    Field,
    MessageError,
)
from firmware_protocol.segments import SEG_BASE

PROTOCOL_MAJOR = 2
PROTOCOL_MINOR = 1
# the first minor version with soft limits, PID gains and autotune, the heater lease,
# CAPS and HEALTH (a host sends those commands only to a device that announces it)
MINOR_SAFETY = 1

HOTEND, BED = 0, 1
MAX_EVENT_VALUES = 4
DWELL_MAX_S = 3600  # longest DWELL, in seconds of the device clock
WATCHDOG_MS_RANGE = (100, 60_000)
WATCHDOG_MS_DEFAULT = 2000
TOLERANCE_DC_RANGE = (1, 1000)
LEASE_MS_RANGE = (100, 60_000)
AUTOTUNE_CYCLES_RANGE = (3, 20)
GAIN_SCALE = 1000  # PID gains travel in thousandths

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


@dataclass(frozen=True)
class Health(Message):
    """Protocol 2.1: follows every STATUS (same payload) in a session of minor >= 1."""

    late_pulses: int
    late_worst_us: int
    rx_overruns: int
    loop_worst_us: int
    OPCODE: ClassVar[int] = 0x48
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("late_pulses", "u32", "step pulses issued later than late_tolerance_us, wraps"),
        F("late_worst_us", "u32", "the worst lateness of a pulse against its ideal time"),
        F("rx_overruns", "u32", "received bytes lost (receive ring full or UART overrun), wraps"),
        F("loop_worst_us", "u32", "the longest main-loop turn"),
    )


@dataclass(frozen=True)
class Caps(Message):
    """Protocol 2.1: the answer to ``GET_CAPS``."""

    min_segment_ticks: int
    segment_rate: int
    late_tolerance_us: int
    OPCODE: ClassVar[int] = 0x49
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("min_segment_ticks", "u32", "shortest segment it takes (shorter: BAD_VALUE)", lo=1),
        F("segment_rate", "u32", "segments/s it sustains (0: not stated)"),
        F("late_tolerance_us", "u16", "a pulse later than this counts as late"),
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
    SetLimits,
    SetPid,
    HeaterLease,
    GetCaps,
    Autotune,
    Ident,
    Status,
    Event,
    Error,
    Boot,
    EstopAck,
    Flow,
    Health,
    Caps,
)
_BY_OPCODE: dict[int, type[Message]] = {cls.OPCODE: cls for cls in MESSAGES}

__all__ = [
    "AUTOTUNE_CYCLES_RANGE",
    "BED",
    "DWELL_MAX_S",
    "GAIN_SCALE",
    "HEATERS_OFF",
    "HOTEND",
    "LEASE_MS_RANGE",
    "MAX_EVENT_VALUES",
    "MAX_TEXT",
    "MESSAGES",
    "MINOR_SAFETY",
    "PROTOCOL_MAJOR",
    "PROTOCOL_MINOR",
    "THERMAL_ERRORS",
    "TOLERANCE_DC_RANGE",
    "TYPE_RANGE",
    "WATCHDOG_MS_DEFAULT",
    "WATCHDOG_MS_RANGE",
    "Autotune",
    "AutotuneFailure",
    "Boot",
    "BootCause",
    "Caps",
    "ClearFault",
    "Configure",
    "Dwell",
    "EmergencyStop",
    "Enable",
    "Error",
    "ErrorCode",
    "EstopAck",
    "EstopFlag",
    "Event",
    "EventCode",
    "F",
    "Field",
    "Flag",
    "Flow",
    "Flush",
    "GetCaps",
    "GetStatus",
    "Health",
    "HeaterLease",
    "Hello",
    "Home",
    "Ident",
    "Identify",
    "Message",
    "MessageError",
    "Segment",
    "SetFan",
    "SetHeater",
    "SetLimits",
    "SetPid",
    "SetPosition",
    "Status",
    "WaitHeater",
]
