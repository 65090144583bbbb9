"""The print pipeline's core: reader items -> planned moves -> joint-space segments.

Two shapes of the same stream:
- ``segment_blocks`` yields :class:`SegmentBlock` (a large batch of segments with
  the commands that fall inside it, ``marks``) and the commands that stop the
  motion. Fast: every planned block is segmented, and optionally encoded, at once.
- ``segment_program`` yields :class:`PlannedSegments` and commands strictly in
  program order (blocks cut at their marks).
An ``encode`` callable (the wire codec plugs in there) is applied to every batch.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from cdprhost.gcode.items import HomeCommand, MoveChunk
from cdprhost.kinematics.machine import MachineModel
from cdprhost.motion.program import ExtruderAt, MarkedMoves, ProgramPlanner, split_at_marks
from cdprhost.motion.segments import (
    DEFAULT_CLOCK_HZ,
    DEFAULT_LIMITS,
    PlannedSegments,
    Segmenter,
    SegmentLimits,
)
from cdprhost.profile.models import MachineProfile


@dataclass
class PipelineTotals:
    """Running totals, readable while (and after) the generator runs."""

    moves: int = 0
    segments: int = 0
    planned_time_s: float = 0.0


@dataclass(frozen=True)
class SegmentBlock:
    """Segments of one planned block; ``marks``: (segments before it, command) for commands inside."""

    batch: PlannedSegments
    marks: tuple[tuple[int, Any], ...]
    encoded: Any = None  # ``encode(batch)`` when an encoder was given

    def split(self) -> list[Any]:
        """Batches and commands in program order."""
        return split_at_marks(self.batch, self.marks)


def segment_blocks(
    items: Iterable[Any],
    profile: MachineProfile,
    model: MachineModel,
    *,
    clock_hz: float = DEFAULT_CLOCK_HZ,
    limits: SegmentLimits = DEFAULT_LIMITS,
    encode: Callable[[PlannedSegments], Any] | None = None,
    totals: PipelineTotals | None = None,
    **planner_options: Any,
) -> Iterator[Any]:
    """:class:`SegmentBlock` items and motion-stopping commands, in program order."""
    pp = ProgramPlanner(profile, model, marked=True, **planner_options)
    seg = Segmenter(
        model,
        profile.drive.home_mm,
        e_steps_per_mm=profile.extruder.steps_per_mm,
        clock_hz=clock_hz,
        limits=limits,
    )
    totals = totals if totals is not None else PipelineTotals()

    def convert(outputs: list[Any]) -> Iterator[Any]:
        for out in outputs:
            if isinstance(out, MarkedMoves):
                batch, move_end = seg.segment_block(out.planned)
                totals.moves += len(out.planned)
                totals.segments += len(batch)
                marks = tuple(
                    (int(move_end[at - 1]) if at > 0 else 0, cmd) for at, cmd in out.marks
                )
                yield SegmentBlock(batch, marks, None if encode is None else encode(batch))
            else:
                match out:
                    case HomeCommand():
                        seg.home()
                    case ExtruderAt(e_mm=e_mm):
                        seg.extruder_at(e_mm)
                        continue  # for the segmenter only: nothing to send
                    case _:
                        pass
                yield out
        totals.planned_time_s = pp.time

    for item in items:
        match item:
            case MoveChunk():
                yield from convert(pp.moves(item)[1])
            case _:
                yield from convert(pp.command(item))
    yield from convert(pp.finish())


def segment_program(
    items: Iterable[Any],
    profile: MachineProfile,
    model: MachineModel,
    *,
    encode: Callable[[PlannedSegments], Any] | None = None,
    **options: Any,
) -> Iterator[Any]:
    """Segment batches (or their encodings) and commands, strictly in program order."""
    for out in segment_blocks(items, profile, model, **options):
        if not isinstance(out, SegmentBlock):
            yield out
            continue
        for part in out.split():
            yield (
                encode(part) if (encode is not None and isinstance(part, PlannedSegments)) else part
            )
