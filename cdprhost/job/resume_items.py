"""Restarting a program part-way: the items that rebuild the machine state, then the rest.

Two ways in: at a layer (:func:`from_layer`, ``--resume-from-layer N``) or exactly at a
point on a move (:func:`from_point`, ``--resume``: the end of the last segment the
device executed). Before the restart, moves are skipped but the state they leave
matters: heater targets and fan are kept (waits included, so the hotend is hot
again), one homing is kept (the effector's position after a failure is unknown),
dwells and messages are dropped. Then the effector lifts straight up to clear the
part, travels above the restart point, and lowers onto it (these inserted moves carry
line 0: they are not in the file). The filament axis keeps the file's absolute E: the
restart first tells the segmenter where the extruder stands (:class:`ExtruderAt`, the
program's E there, :attr:`Restart.e_offset`), so the extruder does not replay what was
skipped and every later segment's extruder steps are the whole print's (each rounds the
same absolute E; re-zeroing E would round other numbers and move a step between
neighbours).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from cdprhost.errors import InputError
from cdprhost.gcode import items as g
from cdprhost.gcode.stream import travel
from cdprhost.motion.program import ExtruderAt

CLEARANCE_MM = 5.0
INSERTED_LINE = 0  # the line of moves the host inserts (not in the file)
#: items before the restart that still hold after it (temperatures, fans, limits, factors...)
_KEPT_SETTINGS = (
    g.SetTemperature,
    g.Fan,
    g.ToolSelect,
    g.FlowFactor,
    g.SpeedFactor,
    g.SetMotionLimits,
    g.ColdExtrusion,
    g.ObjectDefine,
)


def _cut(chunk: g.MoveChunk, i: int, point: np.ndarray | None, e_at: float) -> g.MoveChunk:
    """Moves ``i..`` of ``chunk``, the first starting at ``point`` (if given) with the
    program's E there, ``e_at``."""
    rest = chunk.take(slice(i, None))
    if point is None:
        return rest
    start = rest.start.copy()
    e_start = rest.e_start.copy()
    start[0] = point
    e_start[0] = e_at
    return replace(rest, start=start, e_start=e_start)


def _nearest_move(chunk: g.MoveChunk, line: int, point: np.ndarray) -> tuple[int, float] | None:
    """The move of ``line`` in ``chunk`` nearest to ``point``: (index, fraction along it)."""
    idx = np.flatnonzero(chunk.line == line)
    if not idx.size:
        return None
    a, b = chunk.start[idx], chunk.end[idx]
    ab = b - a
    length2 = (ab * ab).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.clip(((point - a) * ab).sum(axis=1) / length2, 0.0, 1.0)
    frac = np.where(length2 > 0, frac, 1.0)
    dist = np.linalg.norm(a + ab * frac[:, None] - point, axis=1)
    k = int(np.argmin(dist))
    return int(idx[k]), float(frac[k])


class Restart:
    """Items of a program restarted at a layer or at a point; iterate it once.

    ``layer``: 0-based layer to restart at; or ``line``, ``point`` (G-code frame) and
    ``e_mm`` (the program's E there): the exact place on the move of that line.
    ``z_max`` caps the clearance lift (G-code frame)."""

    def __init__(
        self,
        items: Iterable[Any],
        *,
        layer: int | None = None,
        line: int | None = None,
        point: tuple[float, float, float] | None = None,
        e_mm: float | None = None,
        z_max: float = float("inf"),
        travel_feedrate: float = 50.0,
    ):
        if (layer is None) == (line is None):
            raise ValueError("restart at a layer or at a line, not both")
        self._items = items
        self.layer = layer
        self.line = line
        self.point = None if point is None else np.asarray(point, dtype=float)
        self.e_mm = e_mm
        self.z_max = z_max
        self.travel_feedrate = travel_feedrate
        self.e_offset = 0.0  # the program's E at the restart; set when the restart is found

    def _where(self, item: g.MoveChunk) -> tuple[int, np.ndarray | None] | None:
        """Index of the first kept move in ``item`` and the point it starts from (None: its own
        start); None when the restart is not in this chunk."""
        if self.layer is not None:
            keep = np.flatnonzero(item.layer >= self.layer)
            if not keep.size:
                return None
            i = int(keep[0])
            self.e_offset = float(item.e_start[i])
            return i, None
        assert self.point is not None
        found = _nearest_move(item, int(self.line or 0), self.point)
        if found is None:
            return None
        i, frac = found
        if frac >= 1.0 - 1e-9:  # the move was complete: restart at the next one
            self.e_offset = float(item.e_end[i])
            return (i + 1, None) if i + 1 < len(item) else (len(item), None)
        self.e_offset = float(self.e_mm) if self.e_mm is not None else float(item.e_start[i])
        cut = item.start[i] + (item.end[i] - item.start[i]) * frac
        return i, cut

    def __iter__(self) -> Iterator[Any]:
        skipped_top = -np.inf
        homed = False
        started = False
        pending = False  # the restart move was the last of a chunk: resume at the next move
        last_point: np.ndarray | None = None
        for item in self._items:
            if started:
                yield item
                continue
            if isinstance(item, g.MoveChunk):
                where = (0, None) if pending else self._where(item)
                if where is None or where[0] >= len(item):
                    if where is not None:
                        pending = True
                    if len(item):
                        skipped_top = max(skipped_top, float(item.end[:, 2].max()))
                        last_point = item.end[-1]
                    continue
                i, cut = where
                done = item.end[:i]
                if len(done):
                    skipped_top = max(skipped_top, float(done[:, 2].max()))
                    last_point = done[-1]
                first = item.start[i] if cut is None else cut
                yield ExtruderAt(self.e_offset)
                if last_point is not None:  # something was printed: go over it, not through it
                    layer = int(item.layer[i])
                    safe_z = min(max(skipped_top, float(first[2])) + CLEARANCE_MM, self.z_max)
                    route = [
                        last_point,
                        np.array([last_point[0], last_point[1], safe_z]),
                        np.array([first[0], first[1], safe_z]),
                        first,
                    ]
                    yield travel(
                        np.asarray(route), self.e_offset, INSERTED_LINE, layer, self.travel_feedrate
                    )
                yield _cut(item, i, cut, self.e_offset)
                started = True
            elif isinstance(item, _KEPT_SETTINGS):
                yield item
            elif isinstance(item, g.HomeCommand) and not homed:
                homed = True
                yield item
        if not started:
            target = (
                f"layer {self.layer}" if self.layer is not None else f"line {self.line} or later"
            )
            raise InputError(f"resume: the program has no moves in {target}")


def from_layer(
    items: Iterable[Any], layer: int, *, z_max: float = float("inf"), travel_feedrate: float = 50.0
) -> Iterator[Any]:
    """Items of ``items`` that restart the program at 0-based ``layer``."""
    return iter(Restart(items, layer=layer, z_max=z_max, travel_feedrate=travel_feedrate))


@dataclass(frozen=True)
class PlanSpec:
    """How a job's program was built from the file: from the start, a layer or a point."""

    start: str = "file"  # "file" | "layer" | "point"
    layer: int | None = None
    line: int | None = None
    point: tuple[float, float, float] | None = None  # G-code frame
    e_mm: float | None = None

    def apply(self, items: Iterable[Any], *, z_max: float) -> Iterable[Any]:
        """The items of this plan; a :class:`Restart` (with its ``e_offset``) unless from
        the start."""
        if self.start == "file":
            return items
        if self.start == "layer":
            return Restart(items, layer=self.layer, z_max=z_max)
        return Restart(items, line=self.line, point=self.point, e_mm=self.e_mm, z_max=z_max)

    def to_json(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if v is not None}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> PlanSpec:
        point = data.get("point")
        return cls(
            str(data.get("start", "file")),
            data.get("layer"),
            data.get("line"),
            None if point is None else (float(point[0]), float(point[1]), float(point[2])),
            data.get("e_mm"),
        )
