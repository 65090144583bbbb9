"""What the host tells a 2.1 device about the machine at every connect: each module's
travel (soft limits, in steps) and the heaters' PID gains (PROTOCOL.md 3.1 step 5).

Built from the machine profile (:func:`setup_from_profile`); the link keeps it and sends
it again after every handshake.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.profile.models import MachineProfile
from firmware_protocol.messages import BED, HOTEND, Message, SetLimits, SetPid

Gains = tuple[int, int, int]  # kp, ki, kd in thousandths


@dataclass(frozen=True)
class DeviceSetup:
    """``limits``: (lo, hi) steps per module (None: none sent); ``pid``: heater -> gains."""

    limits: tuple[tuple[int, int], ...] | None = None
    pid: tuple[tuple[int, Gains], ...] = ()

    def messages(self) -> list[Message]:
        out: list[Message] = []
        if self.limits is not None:
            out += [SetLimits(k, lo, hi) for k, (lo, hi) in enumerate(self.limits)]
        out += [SetPid(heater, *gains) for heater, gains in self.pid]
        return out


def travel_steps(profile: MachineProfile) -> tuple[tuple[int, int], ...]:
    """Each module's travel ``drive.travel_mm`` in motor steps, rounded as the planner
    rounds positions (so a move to the end of travel is inside)."""
    spm = np.asarray(profile.drive.steps_per_mm, dtype=float)
    travel = np.asarray(profile.drive.travel_mm, dtype=float)
    lo = np.rint(travel[:, 0] * spm).astype(np.int64)
    hi = np.rint(travel[:, 1] * spm).astype(np.int64)
    return tuple((int(a), int(b)) for a, b in zip(lo, hi))


def setup_from_profile(profile: MachineProfile) -> DeviceSetup:
    heaters = profile.heaters
    pid: list[tuple[int, Gains]] = []
    for heater, gains in ((HOTEND, heaters.hotend_pid), (BED, heaters.bed_pid)):
        if gains is not None:
            pid.append((heater, gains.wire()))
    return DeviceSetup(travel_steps(profile), tuple(pid))
