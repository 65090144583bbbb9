"""Parameters of the simulated firmware (what it announces and how it behaves)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from firmware_protocol.block_ring import valid_entries
from firmware_protocol.device.heaters import BED_MODEL, HOTEND_MODEL, HeaterModel
from firmware_protocol.framing import MAX_PAYLOAD
from firmware_protocol.messages import WATCHDOG_MS_DEFAULT

FIRMWARE_NAME = "cdpr-sim"
FIRMWARE_VERSION = "0.2.0"
MAX_QUEUE = 0xFFFF  # queue_capacity is a u16
MAX_SPEEDUP = 100_000.0


@dataclass(frozen=True)
class SimConfig:
    """``speedup``: device time (motion, heaters, dwell, clock) runs this many times faster
    than link time; the link's timers (retransmission, flow interval, watchdog) stay in
    link time. The move queue is sized in time: ``queue_capacity`` slots at 1x, scaled by
    the speed-up (at most 65535), so it holds as many seconds of wall-clock motion at any
    speed-up (see ``slots``)."""

    firmware_name: str = FIRMWARE_NAME
    firmware_version: str = FIRMWARE_VERSION
    queue_capacity: int = 128  # slots at 1x
    scale_queue: bool = True  # scale the slots with the speed-up
    clock_hz: int = 100_000  # unit of segment and dwell durations
    cpu_hz: int = 16_000_000  # unit of step schedules (the AVR's clock: 160 cycles a tick)
    max_step_rate: int = 100_000  # steps/s, any one axis
    #: STEPPING (3.1): the peak rate of an axis it steps from the profile, without a
    #: schedule block (None: max_step_rate; this model steps every axis exactly)
    profile_step_rate: int | None = None
    #: STEP_BUDGET (3.3): peak steps/s summed over the four axes (None: no budget beyond
    #: each axis's, and no STEP_BUDGET sent)
    total_step_rate: int | None = None
    max_payload: int = MAX_PAYLOAD
    #: RING (3.2): entries of a ring its schedule blocks take room in, as the AVR's step
    #: engine keeps (a power of two, at most 128; None: blocks need no room)
    ring_entries: int | None = None
    rx_window: int = 4096  # bytes of unacknowledged host frames it buffers (a pty holds 4 KB)
    window: int = 4  # device -> host DATA frames in flight
    fans: int = 1
    watchdog_ms: int = WATCHDOG_MS_DEFAULT
    start_s: float = 0.25  # default start threshold (device seconds) until CONFIGURE
    flow_s: float = 0.1  # default time-based flow interval (device seconds) until CONFIGURE
    flow_interval_s: float = 0.1  # link time before other report changes are sent
    settle_s: float = 0.2  # rest time before the observer's on_settled
    boot_announce_s: float = 0.25  # BOOT repeat period while no session (link time)
    homing_rate: float = 4000.0  # steps/s toward the switch
    homing_max_steps: int = 160_000  # give up (HOMING_FAILED) beyond this travel
    boot_physical: tuple[int, int, int] = (-8000, -8000, -8000)  # carriage vs switch at boot
    overtravel_steps: int = 16_400  # ENDSTOP_HIT when motion goes this far past the switch
    min_segment_ticks: int = 1  # CAPS: every segment of 1 tick or more runs exactly
    segment_rate: int = 0  # CAPS: segments/s sustained (0: not stated)
    late_tolerance_us: int = 0  # CAPS: every pulse is issued at its exact time
    schedule_tolerance_cycles: int = 16  # CAPS: a schedule's edges within 1 us of ideal
    speedup: float = 1.0  # device time = link time * speedup
    hotend: HeaterModel = field(default=HOTEND_MODEL)
    bed: HeaterModel = field(default=BED_MODEL)
    seed: int = 0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.speedup) and 0 < self.speedup <= MAX_SPEEDUP):
            raise ValueError(
                f"speedup must be a number in (0, {MAX_SPEEDUP:g}], got {self.speedup}"
            )
        if self.cpu_hz % self.clock_hz:
            raise ValueError(f"cpu_hz {self.cpu_hz} is not a multiple of clock_hz {self.clock_hz}")
        if self.ring_entries is not None and not valid_entries(self.ring_entries):
            raise ValueError(f"ring_entries must be a power of two 2..128, got {self.ring_entries}")
        if self.total_step_rate is not None and self.total_step_rate < self.max_step_rate:
            raise ValueError(
                f"total_step_rate {self.total_step_rate} is under max_step_rate "
                f"{self.max_step_rate}: one axis alone takes the per-axis rate"
            )
        if not 1 <= self.queue_capacity <= MAX_QUEUE:
            raise ValueError(f"queue_capacity must be 1..{MAX_QUEUE}")

    @property
    def cycles_per_tick(self) -> int:
        return self.cpu_hz // self.clock_hz

    @property
    def min_step_interval_cycles(self) -> int:
        """CAPS: the shortest schedule interval it runs, in whole cycles: the period of
        ``max_step_rate`` less what a schedule within its tolerance may take off it (an
        edge early by the tolerance after one late by it, and the rounding of both)."""
        return max(1, self.cpu_hz // self.max_step_rate - 2 * self.schedule_tolerance_cycles - 1)

    @property
    def profile_rate(self) -> int:
        """STEPPING's ``profile_step_rate``."""
        return self.max_step_rate if self.profile_step_rate is None else self.profile_step_rate

    @property
    def slots(self) -> int:
        """The queue's capacity in slots, as announced."""
        if not self.scale_queue:
            return self.queue_capacity
        return max(1, min(MAX_QUEUE, round(self.queue_capacity * max(1.0, self.speedup))))
