"""What the link tells its users: identity, progress, status, events, counters."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Union

from firmware_protocol.codes import ALL_AXES
from firmware_protocol.messages import (
    AutotuneFailure,
    Caps,
    Error,
    ErrorCode,
    Event,
    EventCode,
    Flag,
    Health,
    Ident,
    Status,
)


@dataclass(frozen=True)
class Identity:
    """What the device announced at the handshake: its limits, which the host respects."""

    protocol: tuple[int, int]
    firmware_name: str
    firmware_version: str
    axes: int
    queue_capacity: int
    clock_hz: int
    max_step_rate: int
    max_payload: int
    boot_id: int
    heaters: int
    fans: int
    rx_window: int = 4096
    hotend_max_c: float = 0.0
    bed_max_c: float = 0.0
    watchdog_ms: int = 2000
    cpu_hz: int = 16_000_000  # 3.0: the unit of step schedules

    @classmethod
    def from_message(cls, m: Ident) -> Identity:
        return cls(
            (m.major, m.minor),
            m.firmware_name,
            m.firmware_version,
            m.axes,
            m.queue_capacity,
            m.clock_hz,
            m.max_step_rate,
            m.max_payload,
            m.boot_id,
            m.heaters,
            m.fans,
            m.rx_window,
            m.hotend_max_dc / 10,
            m.bed_max_dc / 10,
            m.watchdog_ms,
            m.cpu_hz,
        )


@dataclass(frozen=True)
class DeviceProgress:
    """Executed so far (device counters since boot): queue items and move segments.

    ``segments_done`` is the last segment whose motion completed (never a discarded one)."""

    items_done: int
    segments_done: int
    queue_free: int
    flags: int

    @property
    def moving(self) -> bool:
        return bool(self.flags & Flag.MOVING)

    @property
    def fault(self) -> bool:
        return bool(self.flags & Flag.FAULT)


@dataclass(frozen=True)
class DeviceHealth:
    """A 2.1 device's timing and receive figures (HEALTH, after every STATUS): pulses
    issued later than its tolerance, the worst lateness, received bytes lost, the longest
    main-loop turn."""

    late_pulses: int = 0
    late_worst_us: int = 0
    rx_overruns: int = 0
    loop_worst_us: int = 0
    lost_steps: int = 0  # pulses a tick had no room for
    tick_overruns: int = 0  # step ticks that overran their boundary
    plan_stalls: int = 0  # step ticks that waited for a plan

    @classmethod
    def from_message(cls, m: Health) -> DeviceHealth:
        return cls(
            m.late_pulses,
            m.late_worst_us,
            m.rx_overruns,
            m.loop_worst_us,
            m.lost_steps,
            m.tick_overruns,
            m.plan_stalls,
        )


@dataclass(frozen=True)
class DeviceCaps:
    """What a device announced in CAPS (2.1; 3.0 adds the schedule's tolerance and its
    shortest interval, in cycles of ``Identity.cpu_hz``)."""

    min_segment_ticks: int = 1
    segment_rate: int = 0
    late_tolerance_us: int = 0
    schedule_tolerance_cycles: int = 16
    min_step_interval_cycles: int = 1
    #: STEPPING (3.1, after CAPS): the peak rate of an axis it steps without a schedule
    #: block (None: a 3.0 device, which steps such an axis at any rate it announces)
    profile_step_rate: int | None = None
    #: STEP_BUDGET (3.3, after STEPPING): the peak steps/s its four axes take summed
    #: (None: no budget beyond each axis's, or a device before 3.3)
    total_step_rate: int | None = None

    @classmethod
    def from_message(cls, m: Caps) -> DeviceCaps:
        return cls(
            m.min_segment_ticks,
            m.segment_rate,
            m.late_tolerance_us,
            m.schedule_tolerance_cycles,
            m.min_step_interval_cycles,
        )


@dataclass(frozen=True)
class DeviceStatus:
    flags: int
    queue_free: int
    items_done: int
    segments_done: int
    motion_time_s: float
    steps: tuple[int, int, int, int]
    hotend_c: float
    hotend_target_c: float
    bed_c: float
    bed_target_c: float
    fan: int
    enabled_mask: int
    homed_mask: int
    last_error: int
    device_bad_frames: int
    device_retransmits: int
    device_naks_sent: int
    device_duplicates: int
    received_at: float  # host link time
    items_received: int = 0
    buffered_s: float = 0.0  # queued motion not yet executed, device seconds
    health: DeviceHealth | None = None  # a 2.1 device's HEALTH (None: a 2.0 device)

    @property
    def faulted(self) -> bool:
        return bool(self.flags & Flag.FAULT)

    @property
    def busy(self) -> bool:
        """Motion executing or queued, or a heater wait holding the queue."""
        return bool(self.flags & (Flag.MOVING | Flag.WAITING)) or (
            self.items_received > self.items_done
        )

    @classmethod
    def from_message(cls, m: Status, identity: Identity | None, now: float) -> DeviceStatus:
        clock = identity.clock_hz if identity else 100_000
        return cls(
            m.flags,
            m.queue_free,
            m.items_done,
            m.segments_done,
            m.motion_ticks / clock,
            m.steps,
            m.hotend_dc / 10,
            m.hotend_target_dc / 10,
            m.bed_dc / 10,
            m.bed_target_dc / 10,
            m.fan,
            m.enabled_mask,
            m.homed_mask,
            m.last_error,
            m.bad_frames,
            m.retransmits,
            m.naks_sent,
            m.duplicates,
            now,
            m.items_received,
            m.buffered_ticks / clock,
        )


@dataclass(frozen=True)
class DeviceEvent:
    """HOMED (values: the three module positions), HEATER_REACHED (heater, temp in 0.1 C), FAULT_CLEARED."""

    name: str
    item: int
    values: tuple[int, ...]


@dataclass(frozen=True)
class DeviceErrorEvent:
    name: str
    code: int
    item: int
    segment: int
    axis: int
    value: int
    text: str


@dataclass(frozen=True)
class LinkCounters:
    retransmits: int
    timeouts: int
    naks_received: int
    naks_sent: int
    bad_frames: int
    frames_sent: int
    frames_received: int
    bytes_sent: int
    bytes_received: int
    duplicates: int
    # the device's own figures from its latest HEALTH (2.1; 0 without)
    late_pulses: int = 0
    late_worst_us: int = 0
    rx_overruns: int = 0
    # the device's ring of block entries (3.2, RING): turns a block waited on the host for
    # room, and heads the device reported where the host had counted another
    ring_held: int = 0
    ring_disagreements: int = 0
    # the host's own timeliness (flow.py): the latest it came to a refill that fell due
    # (seconds below the low watermark), and the highest low watermark it kept for it
    host_late_worst_s: float = 0.0
    lead_low_max_s: float = 0.0


LinkEvent = Union[DeviceProgress, DeviceEvent, DeviceErrorEvent]  # noqa: UP007


def _name(enum: type[ErrorCode] | type[EventCode], code: int) -> str:
    try:
        return enum(code).name.lower()
    except ValueError:
        return f"code_{code}"


def error_name(code: int) -> str:
    """``THERMAL_RUNAWAY`` for 2, ``code 99`` for a code this host does not know."""
    try:
        return ErrorCode(code).name
    except ValueError:
        return f"code {code}"


def _failure(value: int) -> str:
    try:
        return AutotuneFailure(value).name.lower().replace("_", " ")
    except ValueError:
        return f"reason {value}"


def error_text(m: Error) -> str:
    name = _name(ErrorCode, m.code)
    axis = (
        ""
        if m.axis == 0xFF
        or m.code in (ErrorCode.BAD_VALUE, ErrorCode.BAD_COMMAND)
        or (m.code == ErrorCode.STEP_RATE and m.axis == ALL_AXES)
        else f", axis {m.axis}"
    )
    details: dict[int, str] = {
        ErrorCode.UNDERRUN: "the move queue ran empty while moving",
        ErrorCode.THERMAL_RUNAWAY: f"heater temperature {m.value / 10:g} C not following its target",
        ErrorCode.ENDSTOP_HIT: (
            f"the motion would take the module past the end of its travel (step {m.value})"
        ),
        ErrorCode.STEP_RATE: (
            f"the four axes' step rates add up to {m.value}/s, over the board's total"
            if m.axis == ALL_AXES
            else f"step rate {m.value}/s over the limit"
        ),
        ErrorCode.OVERTEMP: f"temperature {m.value / 10:g} C over the maximum",
        ErrorCode.HEATER_RANGE: f"target {m.value / 10:g} C over the maximum",
        ErrorCode.HOMING_FAILED: f"no endstop within travel ({m.value} steps)",
        ErrorCode.WATCHDOG: f"no word from the host for {m.value} ms: motion stopped, heaters off",
        ErrorCode.BAD_VALUE: f"value {m.value} out of range in command 0x{m.axis:02X}",
        ErrorCode.BAD_COMMAND: f"malformed command 0x{m.axis:02X} at byte {m.value}",
        ErrorCode.PLANNER_LATE: (
            f"the device's segment preparation fell {m.value} ticks behind"
            if m.value
            else "the device could not prepare the segment's steps in time"
        ),
        ErrorCode.HEATER_LEASE: f"the host did not renew its {m.value} ms heater lease: heaters off",
        ErrorCode.ESTOP: "emergency stop",
        ErrorCode.AUTOTUNE_FAILED: f"PID autotune failed ({_failure(m.value)})",
    }

    detail = details.get(m.code, "")
    return f"{name} at item {m.item}, segment {m.segment}{axis}" + (f": {detail}" if detail else "")


def device_event(m: Error | Event) -> DeviceEvent | DeviceErrorEvent:
    if isinstance(m, Error):
        return DeviceErrorEvent(
            _name(ErrorCode, m.code), m.code, m.item, m.segment, m.axis, m.value, error_text(m)
        )
    return DeviceEvent(_name(EventCode, m.code), m.item, m.values)
