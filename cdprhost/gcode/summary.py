"""`ProgramSummary`: counts and totals over the reader's items, and line -> layer lookup."""

from __future__ import annotations

import bisect
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from cdprhost.gcode.items import (
    FlowFactor,
    LayerChange,
    MoveChunk,
    MoveKind,
    ProgramItem,
    UnknownCommand,
)


@dataclass
class ProgramSummary:
    """Accumulates over items (``add`` or the pass-through ``observe``).

    ``filament_mm``: filament of the extruding moves from the first layer on, as the
    file programs it (before M221's flow factor): the figure slicers report as
    "filament used" (their start-up purge lines are not counted); ``filament_fed_mm``:
    what the extruder really feeds in extruding moves, purge lines included, after the
    flow factor; ``retracted_mm``: total pulled back by retractions and wipes. ``layer_start_lines[i]`` is the line where layer
    ``i`` starts.
    """

    moves: int = 0
    filament_mm: float = 0.0
    filament_fed_mm: float = 0.0
    flow_factor: float = 1.0
    retracted_mm: float = 0.0
    travel_mm: float = 0.0
    extrude_path_mm: float = 0.0
    last_line: int = 0
    layer_start_lines: list[int] = field(default_factory=list)
    unknown: list[UnknownCommand] = field(default_factory=list)
    extrude_min: np.ndarray | None = None  # (3,) bounds of extruding moves
    extrude_max: np.ndarray | None = None

    @property
    def layers(self) -> int:
        return len(self.layer_start_lines)

    @classmethod
    def of(cls, items: Iterable[ProgramItem]) -> ProgramSummary:
        """Summary of all ``items`` (consumes them)."""
        s = cls()
        for item in items:
            s.add(item)
        return s

    def observe(self, items: Iterable[ProgramItem]) -> Iterator[ProgramItem]:
        """Yield ``items`` unchanged while accumulating them."""
        for item in items:
            self.add(item)
            yield item

    def add(self, item: ProgramItem) -> None:
        match item:
            case MoveChunk():
                self._add_moves(item)
                return
            case LayerChange():
                self.layer_start_lines.append(item.line)
            case UnknownCommand():
                self.unknown.append(item)
            case FlowFactor(factor=factor):
                self.flow_factor = factor
            case _:
                pass
        self.last_line = max(self.last_line, item.line)

    def _add_moves(self, c: MoveChunk) -> None:
        n = len(c)
        if n == 0:
            return
        self.moves += n
        self.last_line = max(self.last_line, int(c.line[-1]))
        de = c.de
        extruding = c.kind == MoveKind.EXTRUDE
        self.filament_fed_mm += float(de[extruding].sum())
        if self.flow_factor > 0:
            printed = extruding & (c.layer >= 0)
            self.filament_mm += float(de[printed].sum()) / self.flow_factor
        self.retracted_mm -= float(de[de < 0].sum())
        length = c.length
        self.extrude_path_mm += float(length[extruding].sum())
        self.travel_mm += float(
            length[(c.kind == MoveKind.TRAVEL) | (c.kind == MoveKind.Z_ONLY)].sum()
        )
        if extruding.any():
            pts = np.concatenate([c.start[extruding], c.end[extruding]])
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            self.extrude_min = lo if self.extrude_min is None else np.minimum(self.extrude_min, lo)
            self.extrude_max = hi if self.extrude_max is None else np.maximum(self.extrude_max, hi)

    def layer_of_line(self, line: int) -> int:
        """Layer that source ``line`` belongs to (-1 before the first layer)."""
        return bisect.bisect_right(self.layer_start_lines, line) - 1
