"""A G-code program's items -> planned moves and commands, in program order.

The G-code frame is the machine frame shifted by the profile's ``bed_origin``.
Homing (G28) drives the three slider modules to their endstops, which puts the
effector at ``model.home_point(drive.home_mm)``; the program starts there too, so
the first move (and the first move after any G28) starts at the home point.

Commands that need the machine at rest flush the lookahead: dwell (G4), waits for
temperature (M109/M190), M400, homing, motors off. Other commands (fan, heater
targets without wait, layer changes, messages) keep their place between the moves
without stopping the motion.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdprhost.gcode.items import Dwell, Home, MotorsOff, MoveChunk, SetTemperature, WaitMoves
from cdprhost.kinematics.machine import MachineModel
from cdprhost.motion.limits import Caps
from cdprhost.motion.moves import MoveBlock, block_from_chunk, chain_from, drop_noops
from cdprhost.motion.planner import DEFAULT_MIN_CRUISE_RATIO, Planner
from cdprhost.motion.trapezoid import PlannedMoves
from cdprhost.profile.models import MachineProfile


def flushes_motion(item: Any) -> bool:
    """True for commands that must wait until the machine is at rest."""
    if isinstance(item, (Dwell, Home, MotorsOff, WaitMoves)):
        return True
    return isinstance(item, SetTemperature) and item.wait


def home_position(profile: MachineProfile, model: MachineModel) -> np.ndarray:
    """Machine-frame effector position with every slider at its endstop."""
    return model.home_point(np.asarray(profile.drive.home_mm, dtype=float))


@dataclass(frozen=True)
class MarkedMoves:
    """Planned moves with the commands that fall between them: ``(moves before it, command)``.

    Lets a consumer process a large block at once (vectorised) and still place
    every command at its position; :meth:`split` gives the plain ordered form.
    """

    planned: PlannedMoves
    marks: tuple[tuple[int, Any], ...]

    def split(self) -> list[Any]:
        return split_at_marks(self.planned, self.marks)


def split_at_marks(block: Any, marks: tuple[tuple[int, Any], ...]) -> list[Any]:
    """``block`` (anything with ``len`` and ``take(slice)``) cut at ``marks`` = (rows before it,
    command), the commands placed between the pieces: the plain program order."""
    out: list[Any] = []
    lo = 0
    for at, cmd in marks:
        if at > lo:
            out.append(block.take(slice(lo, at)))
            lo = at
        out.append(cmd)
    if lo < len(block):
        out.append(block.take(slice(lo, None)) if lo else block)
    return out


class ProgramPlanner:
    """Feeds reader items through the planner; outputs planned moves and commands in order.

    With ``marked=True`` planned blocks come whole, as :class:`MarkedMoves`.
    """

    def __init__(
        self,
        profile: MachineProfile,
        model: MachineModel,
        *,
        module_limits: bool = True,
        min_cruise_ratio: float = DEFAULT_MIN_CRUISE_RATIO,
        batch_moves: int = 8192,
        chord: bool = True,
        marked: bool = False,
    ):
        self.origin = np.asarray(profile.build_volume.bed_origin, dtype=float)
        self.home = home_position(profile, model)
        caps = Caps.from_profile(
            profile.motion,
            profile.extruder,
            profile.statics.a_max_mm_s2,
            module_limits=module_limits,
        )
        self.planner = Planner(
            caps,
            model.geometry.outlets,
            min_cruise_ratio=min_cruise_ratio,
            batch_moves=batch_moves,
            chord=chord,
        )
        self.marked = marked
        self.position = self.home.copy()
        self._pushed = 0  # moves handed to the planner
        self._emitted = 0  # planned moves handed out
        self._waiting: deque[tuple[int, Any]] = deque()  # (moves before it, command)

    @property
    def time(self) -> float:
        """Planned time of everything committed so far (s), dwells included."""
        return self.planner.time

    def moves(self, chunk: MoveChunk | MoveBlock) -> tuple[MoveBlock, list[PlannedMoves | Any]]:
        """Add a chunk; returns the machine-frame block (continuous from the current point) and outputs."""
        raw = chunk if isinstance(chunk, MoveBlock) else block_from_chunk(chunk, self.origin)
        block = drop_noops(chain_from(raw, self.position))
        if not len(block):
            return block, []
        self.position = block.end[-1].copy()
        self._pushed += len(block)
        return block, self._emit(self.planner.push(block))

    def command(self, item: Any) -> list[PlannedMoves | Any]:
        if not flushes_motion(item):
            if self._emitted == self._pushed:
                return [item]
            self._waiting.append((self._pushed, item))
            return []
        out = self._emit(self.planner.flush())
        out.append(item)
        if isinstance(item, Dwell):
            self.planner.add_time(item.seconds)
        elif isinstance(item, Home):
            self.position = self.home.copy()
        return out

    def finish(self) -> list[PlannedMoves | Any]:
        return self._emit(self.planner.flush())

    def _emit(self, planned: list[PlannedMoves]) -> list[Any]:
        out: list[Any] = []
        for block in planned:
            end = self._emitted + len(block)
            marks = []
            while self._waiting and self._waiting[0][0] <= end:
                at, cmd = self._waiting.popleft()
                marks.append((max(at - self._emitted, 0), cmd))
            self._emitted = end
            mm = MarkedMoves(block, tuple(marks))
            if self.marked:
                out.append(mm)
            else:
                out.extend(mm.split())
        while self._waiting and self._waiting[0][0] <= self._emitted:
            out.append(self._waiting.popleft()[1])
        return out


def read_items(
    source: Any, profile: MachineProfile, model: MachineModel, **reader_options: Any
) -> Iterator[Any]:
    """``read_program`` with the reader's idea of "home" set to this machine's home point."""
    from cdprhost.gcode import read_program

    home = home_position(profile, model) - np.asarray(profile.build_volume.bed_origin, dtype=float)
    return read_program(
        source, home_position=(float(home[0]), float(home[1]), float(home[2])), **reader_options
    )


def plan_program(
    items: Iterable[Any], profile: MachineProfile, model: MachineModel, **options: Any
) -> Iterator[Any]:
    """Planned moves (:class:`PlannedMoves`) and commands of a program, in order."""
    pp = ProgramPlanner(profile, model, **options)
    for item in items:
        if isinstance(item, MoveChunk):
            yield from pp.moves(item)[1]
        else:
            yield from pp.command(item)
    yield from pp.finish()
