"""Device -> host messages: identity, status, events, errors, boot, flow, health and
capabilities (PROTOCOL.md section 4), each with its wire table."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from firmware_protocol.fields import F, Field
from firmware_protocol.message_base import (
    DWELL_MAX_S,
    MAX_EVENT_VALUES,
    Message,
)


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
    cpu_hz: int
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
        F("cpu_hz", "u32", "3.0: unit of step schedules, a multiple of clock_hz", lo=1000),
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
    lost_steps: int = 0
    tick_overruns: int = 0
    plan_stalls: int = 0
    OPCODE: ClassVar[int] = 0x48
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("late_pulses", "u32", "step pulses issued later than late_tolerance_us, wraps"),
        F("late_worst_us", "u32", "the worst lateness of a pulse against its ideal time"),
        F("rx_overruns", "u32", "received bytes lost (receive ring full or UART overrun), wraps"),
        F("loop_worst_us", "u32", "the longest main-loop turn"),
        F("lost_steps", "u32", "step pulses a tick had no room for, wraps"),
        F("tick_overruns", "u32", "step ticks whose computation overran the next boundary, wraps"),
        F("plan_stalls", "u32", "step ticks that waited for a segment's plan, wraps"),
    )


@dataclass(frozen=True)
class Caps(Message):
    """Protocol 2.1: the answer to ``GET_CAPS``; 3.0 adds the schedule's tolerance and
    shortest interval (cycles of ``cpu_hz``)."""

    min_segment_ticks: int
    segment_rate: int
    late_tolerance_us: int
    schedule_tolerance_cycles: int
    min_step_interval_cycles: int
    OPCODE: ClassVar[int] = 0x49
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("min_segment_ticks", "u32", "shortest segment it takes (shorter: BAD_VALUE)", lo=1),
        F("segment_rate", "u32", "segments/s it sustains (0: not stated)"),
        F("late_tolerance_us", "u16", "a pulse later than this counts as late"),
        F(
            "schedule_tolerance_cycles",
            "u16",
            "3.0: a step schedule's edges lie within this of their ideal time",
            lo=1,
        ),
        F(
            "min_step_interval_cycles",
            "u32",
            "3.0: shortest interval of a schedule it runs (shorter: BAD_VALUE)",
            lo=1,
        ),
    )


@dataclass(frozen=True)
class Stepping(Message):
    """Protocol 3.1: what the device steps without a schedule block, sent after ``CAPS``
    in a session whose minor is 1 or more. An axis the host leaves without its block (a
    ramp: section 5.5's fallback) is stepped from the segment's profile by the device's
    own means, which may be slower than its schedules: the host sends a block for every
    ramp axis faster than ``profile_step_rate`` at its peak."""

    profile_step_rate: int
    OPCODE: ClassVar[int] = 0x4A
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F(
            "profile_step_rate",
            "u32",
            "3.1: peak steps/s it takes on an axis stepped from the profile, without a block",
            lo=1,
        ),
    )


@dataclass(frozen=True)
class Ring(Message):
    """Protocol 3.2: the ring of entries a device keeps its schedule blocks in (the AVR's
    step engine), carried right after ``FLOW`` in every ``ACK``/``NAK`` of a session whose
    minor is 2 or more, by a device that keeps one (none: blocks need no room). ``head``
    and ``tail`` are counters modulo 256 (an entry lies at ``counter % entries``), read
    when the report is sent; ``held``: queue items of frames acknowledged and not queued
    yet, whose blocks are not in ``head`` (PROTOCOL.md 6: the host places each block by
    the device's rule, :mod:`firmware_protocol.block_ring`, and sends it only when it
    fits)."""

    entries: int
    head: int
    tail: int
    held: int
    OPCODE: ClassVar[int] = 0x4B
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F("entries", "u8", "3.2: the ring's entries, a power of two (2..128)", lo=2, hi=128),
        F("head", "u8", "3.2: where the next block goes, counted modulo 256"),
        F("tail", "u8", "3.2: the first entry still held, counted modulo 256"),
        F("held", "u8", "3.2: items acknowledged and not queued yet (saturates)"),
    )


@dataclass(frozen=True)
class StepBudget(Message):
    """Protocol 3.3: the step rate the axes share, sent after ``STEPPING`` in a session
    whose minor is 3 or more, by a device that has such a budget (none: no budget beyond
    each axis's own). ``max_step_rate`` (``IDENT``) holds for any one axis; a device whose
    axes draw on one CPU (the AVR's step engine: four steppers in step hold less each than
    one alone) also caps their sum: a segment whose axes' peak rates add up to more is
    refused (``STEP_RATE``, axis 4), and the host plans under it."""

    total_step_rate: int
    OPCODE: ClassVar[int] = 0x4C
    CLASS: ClassVar[str] = "D"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        F(
            "total_step_rate",
            "u32",
            "3.3: peak steps/s summed over the four axes",
            lo=1,
        ),
    )
