"""Time left of a print in wall-clock time, heating included (pure).

The planned motion time is machine time: the device executes it at ``rate`` machine seconds
per wall second (1 on a real machine, the speed-up on a simulated one), measured from the
job's progress while it prints. Waits for temperature are not in the plan: each wait still
ahead costs the time its heater needs from where it will be to its target, at the heater's
measured rate (learnt while it warmed up, in this job or an earlier one), else a nominal
one. The waits before the first move overlap (the heaters warm up together), so they cost
the longest of them, not their sum.

What is shown is smoothed (:class:`EtaSmoother`): it counts down with the clock and moves
toward each new estimate with a time constant, so a burst of progress or one odd sample does
not make it jump.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

NOMINAL_C_PER_S = {"hotend": 3.0, "bed": 0.6}
"""Typical heating rates of a hotend and a heated bed far from their targets (°C per second of
machine time); a measured rate replaces them once a heater warms up in front of us."""
RATE_WINDOW_S = 30.0
MIN_RATE_SPAN_S = 1.0


@dataclass(frozen=True)
class Eta:
    motion_left_s: float  # planned motion still to run, machine time
    heating_left_s: float  # waits for temperature still ahead, wall-clock
    rate: float  # machine seconds per wall second

    @property
    def wall_s(self) -> float:
        return self.motion_left_s / self.rate + self.heating_left_s


def machine_rate(samples: Sequence[tuple[float, float]], default: float) -> float:
    """Machine seconds per wall second from (wall time, machine time) samples taken while
    printing, over the last ``RATE_WINDOW_S``; ``default`` until they span a second."""
    if len(samples) < 2:
        return default
    s = np.asarray(samples, dtype=float)
    recent = s[s[:, 0] >= s[-1, 0] - RATE_WINDOW_S]
    wall = recent[-1, 0] - recent[0, 0]
    machine = recent[-1, 1] - recent[0, 1]
    if wall < MIN_RATE_SPAN_S or machine <= 0:
        return default
    return float(machine / wall)


def heating_rate(samples: Sequence[tuple[float, float]]) -> float | None:
    """°C per wall second from recent (wall time, temperature) samples of one heater that is
    warming up (None when it is not, or too few samples)."""
    if len(samples) < 3:
        return None
    s = np.asarray(samples[-20:], dtype=float)
    span = s[-1, 0] - s[0, 0]
    rise = s[-1, 1] - s[0, 1]
    if span < MIN_RATE_SPAN_S or rise <= 0:
        return None
    return float(rise / span)


def estimate(
    motion_left_s: float,
    *,
    line: int,
    temperatures: dict[str, float | None],
    heat_waits: Sequence[tuple[int, str, float]],
    rate: float,
    heating_now: dict[str, float] | None = None,
    first_move_line: int = 0,
) -> Eta:
    """Time left when the program has executed up to ``line``.

    ``temperatures``: each heater's current temperature; ``heat_waits``: the program's
    (line, heater, target) waits; ``heating_now``: measured °C per wall second of each heater
    (used for its waits still ahead); ``first_move_line``: the waits before it overlap.
    """
    expected = dict(temperatures)
    measured = dict(heating_now or {})
    wall, start_group = 0.0, 0.0
    for wait_line, heater, target in heat_waits:
        if wait_line <= line:
            expected[heater] = max(expected.get(heater) or 0.0, target)
            continue
        now = expected.get(heater)
        start = 25.0 if now is None else now
        gap = target - start
        if gap > 0:
            c_per_s = measured.get(heater)
            cost = gap / c_per_s if c_per_s else gap / NOMINAL_C_PER_S.get(heater, 1.0) / rate
            if wait_line < first_move_line:  # warming up together before the print moves
                start_group = max(start_group, cost)
            else:
                wall += cost
        expected[heater] = target
    return Eta(max(motion_left_s, 0.0), wall + start_group, rate)


class EtaSmoother:
    """The time left as shown: it counts down with the clock between estimates and moves
    toward each new one by ``1 - exp(-dt / tau_s)`` (pure but for its memory)."""

    def __init__(self, tau_s: float = 20.0):
        self.tau_s = tau_s
        self._left: float | None = None
        self._at = 0.0

    def reset(self) -> None:
        self._left = None

    def update(self, now: float, estimate_s: float) -> float:
        if self._left is None:
            self._left, self._at = estimate_s, now
            return estimate_s
        dt = max(now - self._at, 0.0)
        self._at = now
        predicted = max(self._left - dt, 0.0)
        self._left = predicted + (1.0 - math.exp(-dt / self.tau_s)) * (estimate_s - predicted)
        return self._left
