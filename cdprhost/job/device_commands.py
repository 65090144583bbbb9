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


def device_messages(item: Any, *, model: Any, home_mm: Any, clock_hz: int) -> list[m.Message]:
    """The queued messages that carry out one program command (may be none)."""
    if isinstance(item, g.SetTemperature):
        heater = HEATER_IDS[item.heater]
        out: list[m.Message] = [m.SetHeater(heater, int(round(item.target_c * 10)))]
        if item.wait and item.target_c > 0:
            out.append(m.WaitHeater(heater))
        return out
    if isinstance(item, g.Fan):
        return [m.SetFan(item.index, int(round(max(0.0, min(1.0, item.speed)) * 255)))]
    if isinstance(item, g.Dwell):
        ticks = int(round(item.seconds * clock_hz))
        return [m.Dwell(ticks)] if ticks > 0 else []
    if isinstance(item, g.Home):
        return [m.Enable(0b1111), home_message(model, home_mm)]
    if isinstance(item, g.MotorsOff):
        return [m.Enable(0)]
    return []


def heaters_off() -> list[m.Message]:
    return [m.SetHeater(m.HOTEND, 0), m.SetHeater(m.BED, 0)]
