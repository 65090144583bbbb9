"""Parameters of the simulated firmware (what it announces and how it behaves)."""

from __future__ import annotations

from dataclasses import dataclass, field

from firmware_protocol.device.heaters import BED_MODEL, HOTEND_MODEL, HeaterModel
from firmware_protocol.framing import MAX_PAYLOAD

FIRMWARE_NAME = "cdpr-sim"
FIRMWARE_VERSION = "0.1.0"


@dataclass(frozen=True)
class SimConfig:
    firmware_name: str = FIRMWARE_NAME
    firmware_version: str = FIRMWARE_VERSION
    queue_capacity: int = 128
    clock_hz: int = 100_000  # unit of segment and dwell durations
    max_step_rate: int = 100_000  # steps/s, any one axis
    max_payload: int = MAX_PAYLOAD
    window: int = 4  # device -> host DATA frames in flight
    # motion start from rest: start when start_buffer_s of real time worth of motion
    # is queued (link time: scaled by speedup), when a block that ends at rest is
    # complete, when the queue is full, or after start_delay_s without new items
    start_buffer_s: float = 0.25
    start_delay_s: float = 0.1
    flow_interval_s: float = 0.1  # link time between unsolicited flow updates
    settle_s: float = 0.2  # rest time before the observer's on_settled
    boot_announce_s: float = 0.25  # BOOT repeat period while no session (link time)
    homing_rate: float = 4000.0  # steps/s toward the switch
    homing_max_steps: int = 160_000  # give up (HOMING_FAILED) beyond this travel
    boot_physical: tuple[int, int, int] = (-8000, -8000, -8000)  # carriage vs switch at boot
    overtravel_steps: int = 16_400  # ENDSTOP_HIT when motion goes this far past the switch
    speedup: float = 1.0  # device time = link time * speedup
    hotend: HeaterModel = field(default=HOTEND_MODEL)
    bed: HeaterModel = field(default=BED_MODEL)
    seed: int = 0
