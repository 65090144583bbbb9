"""A G-code program's items -> planned moves and commands, in program order.

The G-code frame is the machine frame shifted by the profile's ``bed_origin``.
Homing (G28) drives the three slider modules to their endstops, which puts the
effector at ``model.home_point(drive.home_mm)``; the program starts there too, so
the first move (and the first move after any G28) starts at the home point.

Commands that need the machine at rest flush the lookahead: dwell (G4), waits for
temperature (M109/M190), M400, homing, motors off, the filament change (M600).
Other commands (fan, heater targets without wait, layer changes, messages, the
file's motion limits) keep their place between the moves without stopping the
motion; the file's limits (M201-M205) apply to the moves after them.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdprhost.gcode.items import (
    DwellCommand,
    FilamentChange,
    HomeCommand,
    MotorsOff,
    MoveChunk,
    PidAutotune,
    ProgramItem,
    SetMotionLimits,
    SetTemperature,
    WaitMoves,
)
from cdprhost.gcode.settings import FirmwareRetraction, ParkPoint
from cdprhost.kinematics.machine import MachineModel
from cdprhost.motion.file_limits import FileLimits, apply_file_limits
from cdprhost.motion.limits import Caps
from cdprhost.motion.moves import MoveBlock, block_from_chunk, chain_from, drop_noops
from cdprhost.motion.planner import DEFAULT_MIN_CRUISE_RATIO, Planner
from cdprhost.motion.trapezoid import PlannedMoves
from cdprhost.profile.models import MachineProfile


@dataclass(frozen=True, slots=True)
class ExtruderAt:
    """Not from a file: the extruder stands at the program's E ``e_mm`` (a restart part-way
    keeps the file's absolute E, so every later segment's extruder steps round as the
    whole print's do: ``round(e * spm)`` of the same ``e``). At rest; moves nothing."""

    e_mm: float
    line: int = 0


def flushes_motion(item: ProgramItem | ExtruderAt) -> bool:
    """True for commands that must wait until the machine is at rest."""
    match item:
        case (
            DwellCommand()
            | HomeCommand()
            | MotorsOff()
            | WaitMoves()
            | FilamentChange()
            | PidAutotune()
            | ExtruderAt()
        ):
            return True
        case SetTemperature(wait=wait):
            return wait
        case _:
            return False


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
        caps = Caps.for_profile(profile, module_limits=module_limits)
        self.profile_accel = caps.max_accel
        self.file_limits = FileLimits()
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
        if self.file_limits.active:
            block = apply_file_limits(block, self.file_limits)
        if not len(block):
            return block, []
        self.position = block.end[-1].copy()
        self._pushed += len(block)
        return block, self._emit(self.planner.push(block))

    def command(self, item: Any) -> list[PlannedMoves | Any]:
        match item:
            case SetMotionLimits():
                self.file_limits = self.file_limits.updated(item, self.profile_accel)
            case _:
                pass
        if not flushes_motion(item):
            if self._emitted == self._pushed:
                return [item]
            self._waiting.append((self._pushed, item))
            return []
        out = self._emit(self.planner.flush())
        out.append(item)
        match item:
            case DwellCommand(seconds=seconds):
                self.planner.add_time(seconds)
            case HomeCommand():
                self.position = self.home.copy()
            case _:
                pass
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


def reader_settings(profile: MachineProfile, model: MachineModel) -> dict[str, Any]:
    """The reader's machine settings from a profile, in the G-code frame: the home
    point (where G28 puts the effector), firmware retraction (G10/G11), the M600 park."""
    origin = np.asarray(profile.build_volume.bed_origin, dtype=float)
    home = home_position(profile, model) - origin
    ex, gc = profile.extruder, profile.gcode
    return {
        "home_position": (float(home[0]), float(home[1]), float(home[2])),
        "filament_diameter_mm": ex.filament_diameter_mm,
        "retraction": FirmwareRetraction(
            ex.retract_mm, ex.retract_speed_mm_s, ex.unretract_extra_mm, ex.unretract_speed_mm_s
        ),
        "park": ParkPoint(
            xy=(gc.park_xy_mm[0] - float(origin[0]), gc.park_xy_mm[1] - float(origin[1])),
            z_max=profile.build_volume.z_max_mm - float(origin[2]),
            lift_mm=gc.park_lift_mm,
            retract_mm=gc.park_retract_mm,
            speed_mm_s=gc.travel_speed_mm_s,
            retract_speed_mm_s=ex.retract_speed_mm_s,
        ),
    }


def read_items(
    source: Any, profile: MachineProfile, model: MachineModel, **reader_options: Any
) -> Iterator[ProgramItem]:
    """``read_program`` with this machine's settings (home point, retraction, park).

    ``reader_options`` go to ``read_program`` (e.g. ``placement``).
    """
    from cdprhost.gcode import read_program

    return read_program(source, **{**reader_settings(profile, model), **reader_options})


def plan_program(
    items: Iterable[Any], profile: MachineProfile, model: MachineModel, **options: Any
) -> Iterator[Any]:
    """Planned moves (:class:`PlannedMoves`) and commands of a program, in order."""
    pp = ProgramPlanner(profile, model, **options)
    for item in items:
        match item:
            case MoveChunk():
                yield from pp.moves(item)[1]
            case _:
                yield from pp.command(item)
    yield from pp.finish()
