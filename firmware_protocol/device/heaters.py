"""First-order heater model with bang-bang control and runaway detection.

``dT/dt = (ambient + gain * u - T) / tau`` with the power ``u`` in {0, 1} held for
one control period and integrated exactly. Runaway is declared when the heater
has been at full power for ``runaway_period_s`` and the temperature rose less than
``runaway_min_rise_c``, or when a temperature that had reached its target stays
more than ``runaway_hysteresis_c`` below it for ``runaway_period_s`` (Marlin's two
thermal-protection rules).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class HeaterModel:
    name: str
    tau_s: float
    gain_c: float  # steady-state rise above ambient at full power
    max_c: float
    runaway_period_s: float
    runaway_hysteresis_c: float
    runaway_min_rise_c: float = 2.0
    ambient_c: float = 25.0
    control_period_s: float = 0.2
    reached_band_c: float = 1.0


HOTEND_MODEL = HeaterModel(
    "hotend",
    tau_s=30.0,
    gain_c=300.0,
    max_c=285.0,
    runaway_period_s=20.0,
    runaway_hysteresis_c=15.0,
)
BED_MODEL = HeaterModel(
    "bed", tau_s=90.0, gain_c=100.0, max_c=120.0, runaway_period_s=60.0, runaway_hysteresis_c=10.0
)


class Heater:
    """One heater. ``advance(t)`` returns the events that happened: ``reached``, ``runaway``, ``overtemp``."""

    def __init__(self, model: HeaterModel, t: float = 0.0):
        self.model = model
        self.temp = model.ambient_c
        self.target = 0.0
        self.power = 0.0
        self.element_ok = True
        self.reached = False
        self._t = t
        self._window: tuple[float, float] | None = None
        self._below_since: float | None = None

    def set_target(self, target_c: float, t: float) -> list[str]:
        events = self.advance(t)
        self.target = max(0.0, target_c)
        self.reached = False
        self._window = None
        self._below_since = None
        return events

    def off(self, t: float) -> None:
        self.advance(t)
        self.target = 0.0
        self.power = 0.0
        self.reached = False

    def _relax(self, dt: float) -> None:
        m = self.model
        steady = m.ambient_c + (m.gain_c * self.power if self.element_ok else 0.0)
        self.temp = steady + (self.temp - steady) * math.exp(-dt / m.tau_s)

    def advance(self, t: float) -> list[str]:
        m = self.model
        if t <= self._t:
            return []
        if self.target <= 0.0:
            self.power = 0.0
            self._relax(t - self._t)
            self._t = t
            return []
        events: list[str] = []
        while self._t + m.control_period_s <= t:
            self.power = 1.0 if self.temp < self.target else 0.0
            self._relax(m.control_period_s)
            self._t += m.control_period_s
            events += self._check(self._t)
            if "runaway" in events or "overtemp" in events:
                break
        return events

    def _check(self, t: float) -> list[str]:
        m = self.model
        if self.temp > m.max_c + 10.0:
            return ["overtemp"]
        out = []
        if not self.reached and self.temp >= self.target - m.reached_band_c:
            self.reached = True
            out.append("reached")
        if not self.reached:
            if self.power >= 1.0:
                if self._window is None:
                    self._window = (t, self.temp)
                elif t - self._window[0] >= m.runaway_period_s:
                    if self.temp - self._window[1] < m.runaway_min_rise_c:
                        return out + ["runaway"]
                    self._window = (t, self.temp)
            else:
                self._window = None
        elif self.temp < self.target - m.runaway_hysteresis_c:
            if self._below_since is None:
                self._below_since = t
            elif t - self._below_since >= m.runaway_period_s:
                return out + ["runaway"]
        else:
            self._below_since = None
        return out
