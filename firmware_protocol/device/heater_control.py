"""Heater control laws of the simulated firmware: PID (``SET_PID``) and the relay autotune
(``AUTOTUNE``, PROTOCOL.md section 4), in Marlin's units: output 0..255, error in degrees
C, time in seconds.

Both are stepped once per control period with the measured temperature and return the
heater power as a share 0..1 of full power.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware_protocol.codes import AutotuneFailure

PWM_MAX = 255.0
RELAY_D = PWM_MAX / 2  # half the relay's output swing (0 <-> 255)
TUNE_TIMEOUT_S = 20 * 60.0
TUNE_OVERSHOOT_C = 20.0
#: the relay holds each state at least this long, so that the thermistor's noise around
#: the target cannot chatter it (Marlin's M303 waits 5 s likewise)
RELAY_MIN_HOLD_S = 5.0


@dataclass(frozen=True)
class PidGains:
    kp: float
    ki: float
    kd: float

    @classmethod
    def from_wire(cls, kp: int, ki: int, kd: int) -> PidGains | None:
        """Thousandths on the wire; all three 0: the device's own default gains."""
        if not (kp or ki or kd):
            return None
        return cls(kp / 1000.0, ki / 1000.0, kd / 1000.0)

    def wire(self) -> tuple[int, int, int]:
        return round(self.kp * 1000), round(self.ki * 1000), round(self.kd * 1000)


class Pid:
    """Positional PID with the integral clamped to the output range and the derivative
    on the measurement (no kick when the target changes)."""

    def __init__(self, gains: PidGains):
        self.gains = gains
        self.integral = 0.0
        self.prev: float | None = None

    def reset(self) -> None:
        self.integral = 0.0
        self.prev = None

    def step(self, target: float, temp: float, dt: float) -> float:
        g = self.gains
        e = target - temp
        if g.ki > 0:
            self.integral = min(max(self.integral + e * dt, 0.0), PWM_MAX / g.ki)
        slope = 0.0 if self.prev is None else (temp - self.prev) / dt
        self.prev = temp
        u = g.kp * e + g.ki * self.integral - g.kd * slope
        return min(max(u / PWM_MAX, 0.0), 1.0)


class RelayTune:
    """Marlin's M303: full power below the target, off above it; after the first rise
    each cycle (a switch back to heating) yields the swing and the period; after
    ``cycles`` of them the classic Ziegler-Nichols gains from their means. Each state holds
    for at least ``RELAY_MIN_HOLD_S``."""

    def __init__(self, target: float, cycles: int, t0: float):
        self.target = target
        self.cycles = cycles
        self.t0 = t0
        self.heating = True
        self.t_on = t0  # when the relay last switched on
        self.t_off: float | None = None
        self.hi = -math.inf
        self.lo = math.inf
        self.periods: list[float] = []
        self.swings: list[float] = []
        self.result: PidGains | None = None
        self.failure: AutotuneFailure | None = None

    @property
    def done(self) -> bool:
        return self.result is not None or self.failure is not None

    def step(self, t: float, temp: float) -> float:
        if self.done:
            return 0.0
        if temp > self.target + TUNE_OVERSHOOT_C:
            self.failure = AutotuneFailure.OVERSHOOT
            return 0.0
        if t - self.t0 > TUNE_TIMEOUT_S:
            self.failure = AutotuneFailure.TIMEOUT
            return 0.0
        self.hi = max(self.hi, temp)
        self.lo = min(self.lo, temp)
        last = self.t_on if self.heating else (self.t_off if self.t_off is not None else t)
        if t - last < RELAY_MIN_HOLD_S:
            pass
        elif self.heating and temp > self.target:
            self.heating = False
            self.t_off = t
        elif not self.heating and temp < self.target:
            self.heating = True
            if self.t_off is not None and self.lo < math.inf and self.t_on > self.t0:
                self.periods.append(t - self.t_on)
                self.swings.append((self.hi - self.lo) / 2)
            self.t_on = t
            self.hi = self.lo = temp
            if len(self.periods) >= self.cycles:
                self._finish()
                return 0.0
        return 1.0 if self.heating else 0.0

    def _finish(self) -> None:
        tu = sum(self.periods) / len(self.periods)
        a = sum(self.swings) / len(self.swings)
        if a <= 0 or tu <= 0:
            self.failure = AutotuneFailure.NO_OSCILLATION
            return
        ku = 4 * RELAY_D / (math.pi * a)
        kp = 0.6 * ku
        self.result = PidGains(kp, 2 * kp / tu, kp * tu / 8)
