"""G-code commands -> firmware messages (firmware_protocol/PROTOCOL.md)."""

from __future__ import annotations

from typing import Any

import numpy as np

from cdprhost.gcode import items as g
from firmware_protocol import messages as m

HEATER_IDS = {"hotend": m.HOTEND, "bed": m.BED}


def home_message(model: Any, home_mm: Any) -> m.Home:
    steps = model.steps(np.asarray(home_mm, dtype=float).reshape(1, 3))[0]
    return m.Home(mask=0b111, positions=tuple(int(v) for v in steps))


def device_messages(item: g.Command, *, model: Any, home_mm: Any, clock_hz: int) -> list[m.Message]:
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
            return [m.Enable(0b1111), home_message(model, home_mm)]
        case g.MotorsOff():
            return [m.Enable(0)]
        case _:
            return []


def heaters_off() -> list[m.Message]:
    return [m.SetHeater(m.HOTEND, 0), m.SetHeater(m.BED, 0)]
