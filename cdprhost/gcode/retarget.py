"""Printing a file sliced for another printer: replace its start and end blocks.

A file sliced for another printer carries that printer's start block (homing and
levelling, purge lines at the edge of its bed, printer checks) and end block
(presenting the bed, parking). `plan_retarget` finds them: the start block is
everything before the first layer (the slicer's layer markers, or else the first
extruding move), the end block everything after the last extruding move. It also
recognises the purge lines of a start G-code that no slicer marker sets apart
(``purge``) and extends the start block over them. It also
notes the temperatures the start block set (M104/M109/M140/M190, or the BED= and
EXTRUDER= parameters of a start macro), which fill the profile's start G-code.

`retarget_items` splices: the profile's start G-code, the file's body, the
profile's end G-code. The body is read with the replaced blocks *muted* (their
modes and positions count, their machine settings do not, see ``read_program``),
so it means what it meant; the filament axis stays continuous and the machine
travels from where the start G-code left it to the first point of the part.
Records of the replaced blocks are dropped, except object labels. Items of the
start G-code carry line 0; those of the end G-code the first replaced end line.
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace

import numpy as np

from cdprhost.gcode.items import (
    CancelObject,
    LayerChange,
    MoveChunk,
    MoveKind,
    ObjectDefine,
    ObjectEnd,
    ObjectStart,
    ProgramItem,
    SetTemperature,
    UnknownCommand,
)
from cdprhost.gcode.placement import PartExtent
from cdprhost.gcode.purge import PurgeFinder, PurgeRun, scan_resets
from cdprhost.gcode.stream import Gap

OPEN_END = 1 << 62
_HOTEND_KEYS = ("EXTRUDER", "EXTRUDER_TEMP", "HOTEND", "HOTEND_TEMP", "NOZZLE", "NOZZLE_TEMP")
_BED_KEYS = ("BED", "BED_TEMP", "BED_TEMPERATURE")
_PARAM = re.compile(r"([A-Za-z_]+)=([0-9.]+)")


@dataclass(frozen=True)
class RetargetPlan:
    """Lines of the blocks to replace, how they were found, what they held."""

    start: tuple[int, int] | None
    end: tuple[int, int] | None
    found_by: str
    hotend_c: float | None
    bed_c: float | None
    purge_mm: float
    replaced: tuple[str, ...]
    extent: PartExtent
    file_lines: int = 0
    purge_lines: tuple[PurgeRun, ...] = ()  # purge moves found inside the first layer

    @property
    def mute(self) -> tuple[tuple[int, int], ...]:
        return tuple(r for r in (self.start, self.end) if r is not None)

    def replaced_line(self, line: int) -> bool:
        return any(a <= line <= b for a, b in self.mute)


def plan_retarget(items: Iterable[ProgramItem], path: str | None = None) -> RetargetPlan:
    """Find the start and end blocks of a program (``path``: to list what they hold)."""
    first_layer: int | None = None
    on_move: bool | None = None  # does layer 0 start on a move (detected by height)?
    last_extrusion = 0
    purge = 0.0
    temps: dict[str, float] = {}
    extent = PartExtent()
    finder = PurgeFinder(scan_resets(path) if path else np.zeros(0, dtype=np.int64))
    for item in items:
        match item:
            case MoveChunk():
                if first_layer is not None and on_move is None:
                    on_move = bool(np.any(item.line == first_layer))
                extruding = item.kind == MoveKind.EXTRUDE
                part = extruding & (item.layer >= 0)
                if part.any():
                    last_extrusion = max(last_extrusion, int(item.line[part][-1]))
                    extent.add(finder.take(item))
                purge += float(item.de[extruding & (item.layer < 0)].sum())
            case LayerChange(index=0, line=line):
                first_layer = line
            case SetTemperature(heater=heater, target_c=target) if first_layer is None:
                if target > 0:
                    temps[heater] = target
            case UnknownCommand(text=text) if first_layer is None and "=" in text:
                for key, value in _PARAM.findall(text):  # a start macro: PRINT_START BED=60 ...
                    if key.upper() in _HOTEND_KEYS:
                        temps.setdefault("hotend", float(value))
                    elif key.upper() in _BED_KEYS:
                        temps.setdefault("bed", float(value))
            case _:
                pass
    purge_end, purge_runs, part_moves = finder.decide()
    for chunk in part_moves:
        extent.add(chunk)
    start = (1, first_layer - 1) if first_layer and first_layer > 1 else None
    end = (last_extrusion + 1, OPEN_END) if last_extrusion else None
    found = "the first and last extruding move" if on_move else "the slicer's layer markers"
    if purge_end:
        start = (1, max(purge_end, start[1] if start else 0))
        purge += sum(run.filament_mm for run in purge_runs)
        found += ", and the purge lines before the part ended by an extruder reset"
    replaced, lines = _replaced(path, start, end) if path else ((), 0)
    return RetargetPlan(
        start,
        end,
        found,
        temps.get("hotend"),
        temps.get("bed"),
        round(purge, 3),
        replaced,
        extent,
        lines,
        purge_runs,
    )


def _replaced(
    path: str, start: tuple[int, int] | None, end: tuple[int, int] | None
) -> tuple[tuple[str, ...], int]:
    """Command words of the replaced blocks, counted ("G1 x7"), in order of appearance,
    and the number of lines of the file."""
    counts: Counter[str] = Counter()
    number = 0
    with open(path, "rb") as fh:
        for number, raw in enumerate(fh, start=1):
            in_start = start is not None and start[0] <= number <= start[1]
            if not (in_start or (end is not None and number >= end[0])):
                continue
            code = raw.split(b";", 1)[0].strip()
            if code:
                counts[code.split()[0].decode("utf-8", "replace").upper()] += 1
    return tuple(f"{word} x{n}" for word, n in counts.items()), number


def retarget_items(
    body: Iterable[ProgramItem],
    plan: RetargetPlan,
    start_code: Iterable[ProgramItem],
    end_code: Callable[[np.ndarray], Iterable[ProgramItem]],
    home: tuple[float, float, float],
) -> Iterator[ProgramItem]:
    """The profile's start G-code, the body of ``body`` (read with ``plan.mute``), the
    profile's end G-code (``end_code(position)`` reads it from the body's last point).

    ``home``: where the program starts (G-code frame). Moves of the body before its
    first X/Y move (a lift, a prime) happen where the start G-code left the effector.
    """
    gap = Gap(position=np.asarray(home, dtype=float))
    for item in start_code:
        match item:
            case MoveChunk():
                gap.moved_to(item.end[-1])
                gap.last_e = float(item.e_end[-1])
                yield replace(item, line=np.zeros(len(item), dtype=np.int64))
            case _:
                yield replace(item, line=0)
    gap.e_offset = -gap.last_e  # the body's E axis continues the start G-code's
    gap.pending = True
    end_line = plan.end[0] if plan.end else OPEN_END
    layer, last_line = 0, 0
    lead = True  # no X/Y move of the body kept yet
    for item in body:
        match item:
            case MoveChunk():
                last_line = int(item.line[-1])
                kept = item.take(item.line < end_line)
                if plan.start is not None:
                    early = kept.line <= plan.start[1]
                    if early.any():
                        gap.drop(kept.take(early))
                        kept = kept.take(~early)
                if len(kept):
                    if lead and gap.position is not None:
                        kept, lead = _from_here(kept, gap.position)
                    layer = max(layer, int(kept.layer.max()))
                    yield from gap.keep(kept)
            case ObjectDefine() | ObjectStart() | ObjectEnd() | CancelObject():
                yield item
            case LayerChange() if plan.purge_lines and item.index >= 0:
                yield item  # the first layer began on a purge line: the part keeps it
            case _ if plan.replaced_line(item.line):
                last_line = item.line
            case _:
                last_line = item.line
                yield item
    line = end_line if plan.end else last_line + 1
    here = gap.position if gap.position is not None else np.zeros(3)
    offset: float | None = None
    for item in end_code(here):
        match item:
            case MoveChunk():
                if offset is None:
                    offset = float(item.e_start[0]) - gap.last_e
                n = len(item)
                yield replace(
                    item,
                    e_start=item.e_start - offset,
                    e_end=item.e_end - offset,
                    line=np.full(n, line, dtype=np.int64),
                    layer=np.full(n, layer, dtype=np.int32),
                )
            case _:
                yield replace(item, line=line)


def _from_here(chunk: MoveChunk, here: np.ndarray) -> tuple[MoveChunk, bool]:
    """The body's first moves re-based to X/Y ``here`` up to (and starting) its first X/Y
    move: the muted start block left the reader's X/Y at the other printer's purge line.
    Returns the chunk and whether no X/Y move came yet."""
    d = chunk.end[:, :2] - chunk.start[:, :2]
    moving = np.flatnonzero(np.abs(d).max(axis=1) > 1e-9)
    stop = int(moving[0]) if moving.size else len(chunk)
    start, end = chunk.start.copy(), chunk.end.copy()
    start[: stop + 1, :2] = here[:2]
    end[:stop, :2] = here[:2]
    return replace(chunk, start=start[: len(chunk)], end=end), not moving.size
