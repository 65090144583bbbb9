"""Heater model: the plant of ``thermal_plant.py`` (first order with dead time, heat
loss and thermistor noise) with its control (PID, relay autotune) and
thermal protection.

``dT/dt = (ambient + gain * u(t - dead_time) - T) / tau`` with the power ``u`` (0..1;
PID with the model's default gains or ``SET_PID``'s, the relay of an autotune) held for
one control period and integrated exactly; control and protection see the thermistor's
reading (the temperature plus its noise), as the firmware does. Protection follows
Marlin's defaults (the firmware's ``config.h`` holds the same figures):

- heating failed: while heating towards the target, the reading must rise by
  ``watch_rise_c`` within each ``watch_period_s`` (WATCH_TEMP_PERIOD / _INCREASE);
- runaway: once the target was reached, a reading more than ``runaway_hysteresis_c``
  below it for ``runaway_period_s`` (THERMAL_PROTECTION_PERIOD / _HYSTERESIS);
- thermistor open: a reading below ``MINTEMP_C`` with a target set (MINTEMP);
- thermistor shorted or the heater stuck on: a reading above ``cutoff_c`` (MAXTEMP).
"""

from __future__ import annotations

import math
import random
from collections import deque
from dataclasses import dataclass, field

from firmware_protocol.codes import ErrorCode
from firmware_protocol.device.heater_control import Pid, PidGains, RelayTune
from firmware_protocol.device.thermal_plant import (
    BED_PLANT,
    HOTEND_PLANT,
    NOISE_HOLD_S,
    ThermalPlant,
)

MINTEMP_C = 5.0  # below this with a target set: the thermistor is open
#: what an open or a shorted thermistor reads (the ends of the firmware's table)
OPEN_READING_C = -20.0
SHORT_READING_C = 355.0


@dataclass(frozen=True)
class HeaterModel:
    name: str
    plant: ThermalPlant
    max_c: float  # the highest target
    cutoff_c: float  # OVERTEMP above this reading, whatever the target
    watch_period_s: float
    runaway_period_s: float
    runaway_hysteresis_c: float
    watch_rise_c: float = 2.0
    control_period_s: float = 0.1  # the firmware's HEATER_PERIOD_MS
    reached_band_c: float = 1.0
    #: the control without SET_PID gains (firmware/src/heater.c's kp0, ki0, kd0): what a
    #: relay autotune finds on the plant (None: bang-bang)
    default_gains: PidGains | None = None

    @property
    def ambient_c(self) -> float:
        return self.plant.ambient_c


# Marlin's defaults: WATCH_TEMP_PERIOD 40 s / WATCH_TEMP_INCREASE 2 C,
# THERMAL_PROTECTION_PERIOD 40 s / _HYSTERESIS 4 C; the bed's 60 s / 2 C and 20 s / 2 C
HOTEND_MODEL = HeaterModel(
    "hotend",
    HOTEND_PLANT,
    max_c=285.0,
    cutoff_c=300.0,
    watch_period_s=40.0,
    runaway_period_s=40.0,
    runaway_hysteresis_c=4.0,
    default_gains=PidGains(10.8, 0.80, 36.7),  # autotune at 210 C
)
BED_MODEL = HeaterModel(
    "bed",
    BED_PLANT,
    max_c=120.0,
    cutoff_c=130.0,
    watch_period_s=60.0,
    runaway_period_s=20.0,
    runaway_hysteresis_c=2.0,
    default_gains=PidGains(71.7, 5.73, 224.4),  # autotune at 60 C
)


@dataclass
class _Delay:
    """The powers on their way from the element to the thermistor, one per control period."""

    slots: int
    powers: deque[float] = field(default_factory=deque)

    def push(self, power: float) -> float:
        self.powers.append(power)
        return self.powers.popleft() if len(self.powers) > self.slots else 0.0

    @property
    def idle(self) -> bool:
        return not any(self.powers)


class Heater:
    """One heater. ``advance(t)`` returns the events that happened: ``reached``, ``runaway``
    (heating failed, runaway or an open thermistor), ``overtemp``, ``tuned`` /
    ``tune_failed`` (``tuned`` holds the result). ``temp`` is the plant's temperature,
    ``reading`` what the thermistor reads (what control, protection and reports see);
    ``sensor`` is ``ok``, ``open`` or ``short``."""

    def __init__(self, model: HeaterModel, t: float = 0.0):
        self.model = model
        plant = model.plant
        self.temp = plant.ambient_c
        self.reading = plant.ambient_c
        self.sensor = "ok"
        self.target = 0.0
        self.power = 0.0
        self.element_ok = True
        self.reached = False
        self._t = t
        self._delay = _Delay(round(plant.dead_time_s / model.control_period_s))
        self._noise = random.Random(model.name)
        self._next_noise = t
        self._noise_c = 0.0
        self._window: tuple[float, float] | None = None
        self._below_since: float | None = None
        self.pid: Pid | None = None
        self.set_gains(None)
        self.tune: RelayTune | None = None
        self.tuned: RelayTune | None = None  # the last autotune that ended

    def warm_start(self, temp_c: float) -> None:
        """The plant at ``temp_c`` now (a printer still warm from a print)."""
        self.temp = self.reading = temp_c

    def set_gains(self, gains: PidGains | None) -> None:
        """SET_PID's gains; None: the model's defaults."""
        gains = gains if gains is not None else self.model.default_gains
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
        self._window = (t, self.reading) if self.target > 0 else None
        self._below_since = None
        return events

    def off(self, t: float) -> None:
        self.advance(t)
        self.target = 0.0
        self.power = 0.0
        self.reached = False
        self.tune = None

    def _relax(self, dt: float, power: float) -> None:
        plant = self.model.plant
        steady = plant.ambient_c + (plant.gain_c * power if self.element_ok else 0.0)
        self.temp = steady + (self.temp - steady) * math.exp(-dt / plant.tau_s)

    def _read(self, t: float) -> None:
        if t >= self._next_noise:
            self._noise_c = self._noise.gauss(0.0, self.model.plant.noise_c)
            self._next_noise = t + NOISE_HOLD_S - 1e-9
        if self.sensor == "open":
            self.reading = OPEN_READING_C
        elif self.sensor == "short":
            self.reading = SHORT_READING_C
        else:
            self.reading = self.temp + self._noise_c

    def advance(self, t: float) -> list[str]:
        m = self.model
        if t <= self._t:
            return []
        events: list[str] = []
        cp = m.control_period_s
        while self._t + cp <= t:
            if self.target <= 0.0 and self._delay.idle:
                # off, nothing left on its way: relax to ``t`` at once
                self.power = 0.0
                self._relax(t - self._t, 0.0)
                self._t = t
                self._read(t)
                return events + (["overtemp"] if self.reading > m.cutoff_c else [])
            self.power = self._control(cp) if self.target > 0.0 else 0.0
            self._relax(cp, self._delay.push(self.power))
            self._t += cp
            self._read(self._t)
            if self.target <= 0.0:
                if self.reading > m.cutoff_c:
                    return events + ["overtemp"]
                continue
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
            return self.tune.step(self._t, self.reading)
        if self.pid is not None:
            return self.pid.step(self.target, self.reading, dt)
        return 1.0 if self.reading < self.target else 0.0

    def _check(self, t: float) -> list[str]:
        m, r = self.model, self.reading
        if r > m.cutoff_c:
            return ["overtemp"]
        if r < MINTEMP_C:
            return ["runaway"]
        out = []
        if not self.reached and r >= self.target - m.reached_band_c:
            self.reached = True
            out.append("reached")
        if not self.reached:
            window = self._window or (t, r)
            if t - window[0] >= m.watch_period_s - 1e-9:
                if r < window[1] + m.watch_rise_c:
                    return out + ["runaway"]
                window = (t, r)
            self._window = window
        elif r < self.target - m.runaway_hysteresis_c:
            if self._below_since is None:
                self._below_since = t
            elif t - self._below_since >= m.runaway_period_s - 1e-9:
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
            temp_dc = round(h.reading * 10)
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
