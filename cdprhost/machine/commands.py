"""Firmware messages for machine commands (firmware_protocol/PROTOCOL.md): the one place
that knows how homing, enabling and heater control are spelled on the wire."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from cdprhost.gcode import items as g
from cdprhost.kinematics.machine import MachineModel
from firmware_protocol import messages as m

HEATER_IDS = {"hotend": m.HOTEND, "bed": m.BED}
ALL_AXES = 0b1111
ALL_MODULES = 0b111


def enable_all() -> m.Enable:
    return m.Enable(ALL_AXES)


def motors_off() -> m.Enable:
    return m.Enable(0)


def home_message(model: MachineModel, home_mm: Sequence[float]) -> m.Home:
    n1, n2, n3 = (int(v) for v in model.steps(np.asarray(home_mm, dtype=float).reshape(1, 3))[0])
    return m.Home(mask=ALL_MODULES, positions=(n1, n2, n3))


def home_commands(model: MachineModel, home_mm: Sequence[float]) -> list[m.Message]:
    """Homing needs the drivers on: enable every axis, then home the three modules."""
    return [enable_all(), home_message(model, home_mm)]


def heater_messages(
    hotend_c: float | None, bed_c: float | None, *, wait: bool = False
) -> list[m.Message]:
    """Targets in degrees C (None: leave that heater alone); ``wait`` adds a queue hold for
    each heater set above 0."""
    out: list[m.Message] = []
    for heater, target in ((m.HOTEND, hotend_c), (m.BED, bed_c)):
        if target is None:
            continue
        out.append(m.SetHeater(heater, int(round(target * 10))))
        if wait and target > 0:
            out.append(m.WaitHeater(heater))
    return out


def estop_flags(profile: Any) -> int:
    """The e-stop of a host that gives up: motors kept (a cable robot must not drop its
    effector), heaters off unless the profile's ``heaters.on_failure`` keeps them."""
    keep = m.EstopFlag.KEEP_MOTORS
    if profile.heaters.on_failure == "keep":
        keep |= m.EstopFlag.KEEP_HEATERS
    return int(keep)


def heaters_off() -> list[m.Message]:
    return heater_messages(0.0, 0.0)


def device_messages(
    item: g.Command, *, model: MachineModel, home_mm: Any, clock_hz: int
) -> list[m.Message]:
    """The queued messages that carry out one program command (may be none)."""
    match item:
        case g.SetTemperature(heater=heater_name, target_c=target, wait=wait):
            heater = HEATER_IDS[heater_name]
            out: list[m.Message] = [m.SetHeater(heater, int(round(target * 10)))]
            if wait and target > 0:
                out.append(m.WaitHeater(heater))
            return out
        case g.Fan(speed=speed, index=index):
            return [m.SetFan(index, int(round(max(0.0, min(1.0, speed)) * 255)))]
        case g.DwellCommand(seconds=seconds):
            ticks = int(round(seconds * clock_hz))
            return [m.Dwell(ticks)] if ticks > 0 else []
        case g.HomeCommand():
            return home_commands(model, home_mm)
        case g.MotorsOff():
            return [motors_off()]
        case _:
            return []
