"""The message table's vocabulary: protocol versions, the bounds fixed by the protocol,
and the base every message derives from (opcode, wire fields, class)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from firmware_protocol.fields import Field

PROTOCOL_MAJOR = 3
PROTOCOL_MINOR = 3
# the first minor version with soft limits, PID gains and autotune, the heater lease,
# CAPS and HEALTH (2.1; every 3.x has them, so 0 in this major)
MINOR_SAFETY = 0
# the first minor version whose CAPS is followed by STEPPING (3.1)
MINOR_STEPPING = 1
# the first minor version whose ACK and NAK carry RING after FLOW, from a device that
# keeps its schedule blocks in a ring of entries (3.2)
MINOR_RING = 2
# the first minor version whose STEPPING is followed by STEP_BUDGET, the step rate the
# axes share (3.3)
MINOR_BUDGET = 3

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
