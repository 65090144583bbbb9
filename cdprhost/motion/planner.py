"""Streaming motion planner: bounded lookahead over blocks of moves.

Moves are pushed in blocks; the planner keeps a pending buffer and plans it as a
whole (vectorised), committing every move whose speeds no longer depend on what
may follow: a junction is final once the moves after it are long enough to brake
from any allowed speed to rest (smoothed acceleration, so the hump grouping is
final too). The rest is held back and replanned with the next block. ``flush``
plans everything to a stop (end of program, dwell, waits, homing).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cdprhost.motion.junction import junction_v2
from cdprhost.motion.limits import Caps, move_caps
from cdprhost.motion.lookahead import plan_profile
from cdprhost.motion.moves import MoveBlock
from cdprhost.motion.trapezoid import PlannedMoves, move_durations

#: Klipper's default minimum_cruise_ratio
DEFAULT_MIN_CRUISE_RATIO = 0.5


@dataclass
class PlannerStats:
    moves: int = 0
    module_limited: int = 0
    replans: int = 0
    start_speed_drops: int = 0  # committed speed the next plan could not keep (should stay 0)
    flushes: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


class Planner:
    """Lookahead planner. ``push`` and ``flush`` return planned moves, in order."""

    def __init__(
        self,
        caps: Caps,
        outlets: np.ndarray,
        *,
        min_cruise_ratio: float = DEFAULT_MIN_CRUISE_RATIO,
        batch_moves: int = 8192,
        max_pending: int = 262144,
        t0: float = 0.0,
        chord: bool = True,
    ):
        self.caps = caps
        self.outlets = np.asarray(outlets, dtype=float)
        self.min_cruise_ratio = float(min_cruise_ratio)
        self.batch_moves = int(batch_moves)
        self.chord = bool(chord)  # False: no chord steps (time estimates only, no segmenting)
        self.max_pending = int(max_pending)
        self.time = float(t0)  # end time of everything committed so far (s)
        self.stats = PlannerStats()
        self._pending: list[MoveBlock] = []
        self._pending_n = 0
        self._v0 = 0.0  # speed at the start of the first pending move (committed)
        self._sv0: float | None = None  # the smoothed profile there

    @property
    def pending(self) -> int:
        return self._pending_n

    def push(self, block: MoveBlock) -> list[PlannedMoves]:
        if len(block):
            self._pending.append(block)
            self._pending_n += len(block)
        if self._pending_n < self.batch_moves:
            return []
        return self._plan(final=self._pending_n >= self.max_pending)

    def flush(self) -> list[PlannedMoves]:
        """Plan everything pending to a stop."""
        self.stats.flushes += 1
        return self._plan(final=True) if self._pending_n else []

    def add_time(self, seconds: float) -> None:
        """A pause (dwell) between flushed moves."""
        self.time += float(seconds)

    # ------------------------------------------------------------------ core
    def _plan(self, *, final: bool) -> list[PlannedMoves]:
        block = MoveBlock.concat(self._pending)
        n = len(block)
        self.stats.replans += 1
        mc = move_caps(block, self.outlets, self.caps, chord=self.chord)
        delta = 2.0 * mc.accel * mc.length
        jd: float | np.ndarray = self.caps.junction_deviation
        if block.junction_limit is not None:
            jd = np.minimum(jd, np.minimum(block.junction_limit[:-1], block.junction_limit[1:]))
        jv2 = junction_v2(mc.unit, mc.kinematic, mc.accel, mc.length, jd)
        v2_start = min(self._v0**2, float(mc.v2_cap[0]))
        v2, cruise, smooth, hump_start = plan_profile(
            jv2,
            mc.v2_cap,
            delta,
            v2_start,
            0.0,
            min_cruise_ratio=self.min_cruise_ratio,
            smooth_v2_start=self._sv0,
        )
        if v2[0] < v2_start * (1.0 - 1e-9) - 1e-9:
            self.stats.start_speed_drops += 1
        cut = n if final else self._commit_point(mc.v2_cap, delta, jv2, hump_start)
        if cut == 0:
            return []
        speeds = np.sqrt(v2)
        v_cruise = np.sqrt(cruise[:cut])
        dur = move_durations(
            mc.length[:cut], mc.accel[:cut], speeds[:cut], v_cruise, speeds[1 : cut + 1]
        )
        t_start = np.empty(cut)
        t_start[0] = self.time
        np.cumsum(dur[:-1], out=t_start[1:])
        t_start[1:] += self.time
        self.time = float(t_start[-1] + dur[-1])
        head = slice(0, cut)
        planned = PlannedMoves(
            block.take(head),
            mc.length[head],
            mc.kinematic[head],
            mc.accel[head],
            speeds[:cut],
            v_cruise,
            speeds[1 : cut + 1],
            t_start,
            mc.chord_step[head],
            mc.module_limited[head],
        )
        self.stats.moves += cut
        self.stats.module_limited += int(np.count_nonzero(planned.module_limited))
        rest = block.take(slice(cut, n))
        self._pending = [rest] if len(rest) else []
        self._pending_n = len(rest)
        self._v0 = float(speeds[cut]) if len(rest) else 0.0
        self._sv0 = float(smooth[cut]) if (len(rest) and smooth is not None) else None
        return [planned]

    def _commit_point(
        self, v2_cap: np.ndarray, delta: np.ndarray, jv2: np.ndarray, hump_start: np.ndarray
    ) -> int:
        """Index of the last junction whose plan can no longer change (0: none).

        Junction j qualifies when the moves after junction j+1 can brake from any
        allowed speed at the smoothed deceleration (so every smoothed value up to
        j+1, hence the hump grouping up to j, is final) and a hump starts at j.
        """
        reach = np.cumsum((delta * (1.0 - self.min_cruise_ratio))[::-1])[
            ::-1
        ]  # braking room after junction j
        need = float(v2_cap.max()) * 1.000001
        room = np.zeros(
            reach.shape[0], dtype=bool
        )  # room[j]: junction j+1 has enough room after it
        room[:-1] = reach[1:] >= need
        ok = np.flatnonzero(room[1:] & hump_start[1:]) + 1
        if not ok.size:
            return 0
        last = int(ok[-1])
        # prefer a junction where the machine stops anyway (plans on both sides decouple)
        stops = np.flatnonzero(jv2[:last] <= 0.0) + 1
        if stops.size and stops[-1] * 2 >= last:
            return int(stops[-1])
        return last
