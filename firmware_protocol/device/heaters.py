"""First-order heater model with its control (bang-bang, PID, relay autotune) and
runaway detection.

``dT/dt = (ambient + gain * u - T) / tau`` with the power ``u`` (0..1; bang-bang
without gains, PID with ``SET_PID`` gains, the relay of an autotune) held for one
control period and integrated exactly. Runaway is declared when the heater
has been at full power for ``runaway_period_s`` and the temperature rose less than
``runaway_min_rise_c``, or when a temperature that had reached its target stays
more than ``runaway_hysteresis_c`` below it for ``runaway_period_s`` (Marlin's two
thermal-protection rules).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware_protocol.codes import ErrorCode
from firmware_protocol.device.heater_control import Pid, PidGains, RelayTune


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
    """One heater. ``advance(t)`` returns the events that happened: ``reached``, ``runaway``,
    ``overtemp``, ``tuned`` / ``tune_failed`` (``tuned`` holds the result)."""

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
        self.pid: Pid | None = None
        self.tune: RelayTune | None = None
        self.tuned: RelayTune | None = None  # the last autotune that ended

    def set_gains(self, gains: PidGains | None) -> None:
        self.pid = Pid(gains) if gains is not None else None

    def start_tune(self, target_c: float, cycles: int, t: float) -> list[str]:
        """Relay autotune around ``target_c`` (the heater goes off when it ends)."""
        events = self.set_target(target_c, t)
        self.tune = RelayTune(target_c, cycles, t)
        return events

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
        self.tune = None

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
            self.power = self._control(m.control_period_s)
            self._relax(m.control_period_s)
            self._t += m.control_period_s
            events += self._check(self._t)
            if "runaway" in events or "overtemp" in events:
                break
            tune = self.tune
            if tune is not None and tune.done:
                events.append("tuned" if tune.result is not None else "tune_failed")
                self.target = self.power = 0.0
                self.reached = False
                self.tune, self.tuned = None, tune
                if tune.result is not None:
                    self.set_gains(tune.result)
                break
        return events

    def _control(self, dt: float) -> float:
        if self.tune is not None:
            return self.tune.step(self._t, self.temp)
        if self.pid is not None:
            return self.pid.step(self.target, self.temp, dt)
        return 1.0 if self.temp < self.target else 0.0

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


def heater_outcomes(heaters: list[Heater], t: float) -> list[tuple[str, int, tuple[int, ...]]]:
    """Advance every heater to ``t``; what happened as (kind, heater, values): ``reached``
    (temperature in 0.1 C,), ``tuned`` (kp, ki, kd in thousandths), ``fault`` (ErrorCode,
    value): a runaway or overtemperature (the temperature) or a failed autotune (why)."""
    out: list[tuple[str, int, tuple[int, ...]]] = []
    for hid, h in enumerate(heaters):
        for ev in h.advance(t):
            temp_dc = round(h.temp * 10)
            if ev == "reached":
                out.append(("reached", hid, (temp_dc,)))
            elif ev == "runaway":
                out.append(("fault", hid, (ErrorCode.THERMAL_RUNAWAY, temp_dc)))
            elif ev == "overtemp":
                out.append(("fault", hid, (ErrorCode.OVERTEMP, temp_dc)))
            elif h.tuned is not None and h.tuned.result is not None:
                out.append(("tuned", hid, h.tuned.result.wire()))
            else:
                reason = int(h.tuned.failure or 0) if h.tuned is not None else 0
                out.append(("fault", hid, (ErrorCode.AUTOTUNE_FAILED, reason)))
    return out
