"""Small pure helpers for stages that drop moves from the item stream.

Dropping moves (a cancelled object, a replaced start block) leaves two gaps the
later stages must not see: the machine E axis would jump (the segmenter turns
absolute E positions into steps), and the next kept move would start where the
dropped ones ended. `Gap` closes both: it shifts E so the axis stays continuous,
and puts a travel to the first kept point when the next kept move would draw.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from cdprhost.gcode.items import CHUNK_FIELDS, MoveChunk, MoveKind

TRAVEL_FEEDRATE_MM_S = 50.0


def shift_e(chunk: MoveChunk, offset: float) -> MoveChunk:
    """``chunk`` with its machine E positions moved by ``-offset``."""
    if offset == 0.0:
        return chunk
    return replace(chunk, e_start=chunk.e_start - offset, e_end=chunk.e_end - offset)


def travel(
    points: np.ndarray, e: float, line: int, layer: int, feedrate: float = TRAVEL_FEEDRATE_MM_S
) -> MoveChunk:
    """Travel moves through ``points`` (k, 3), E still at ``e``."""
    pts = np.asarray(points, dtype=float)
    n = len(pts) - 1
    return MoveChunk(
        start=pts[:-1].copy(),
        end=pts[1:].copy(),
        e_start=np.full(n, e),
        e_end=np.full(n, e),
        feedrate=np.full(n, feedrate),
        line=np.full(n, line, dtype=np.int64),
        layer=np.full(n, layer, dtype=np.int32),
        kind=np.full(n, int(MoveKind.TRAVEL), dtype=np.uint8),
        rapid=np.ones(n, dtype=bool),
    )


def empty_chunk() -> MoveChunk:
    z3, z = np.zeros((0, 3)), np.zeros(0)
    return MoveChunk(
        z3,
        z3,
        z,
        z,
        z,
        np.zeros(0, np.int64),
        np.zeros(0, np.int32),
        np.zeros(0, np.uint8),
        np.zeros(0, bool),
    )


@dataclass
class Gap:
    """Bookkeeping for a stream that drops moves.

    ``drop(rows)`` forgets moves (their filament is taken out of the E axis);
    ``keep(rows)`` returns the kept moves, shifted in E and, after a drop, led by
    a travel from where the machine really is to the first kept point.
    """

    e_offset: float = 0.0
    position: np.ndarray | None = None  # where the kept moves have left the machine
    pending: bool = False  # moves were dropped since the last kept one
    travel_feedrate: float = TRAVEL_FEEDRATE_MM_S
    last_e: float = 0.0  # machine E after the last kept move

    def drop(self, rows: MoveChunk) -> None:
        if len(rows):
            self.e_offset += float(rows.e_end[-1] - rows.e_start[0])
            self.pending = True

    def moved_to(self, point: np.ndarray | None) -> None:
        """The machine is at ``point`` now (None: unknown, e.g. homing)."""
        self.position = None if point is None else np.asarray(point, dtype=float)

    def keep(self, rows: MoveChunk) -> list[MoveChunk]:
        if not len(rows):
            return []
        rows = shift_e(rows, self.e_offset)
        out = []
        if self.pending:
            self.pending = False
            first = rows.start[0]
            if self.position is not None and not np.allclose(self.position, first):
                out.append(
                    travel(
                        np.vstack([self.position, first]),
                        float(rows.e_start[0]),
                        int(rows.line[0]),
                        int(rows.layer[0]),
                        self.travel_feedrate,
                    )
                )
        travels = rows.kind == MoveKind.TRAVEL
        if travels.any():
            self.travel_feedrate = float(rows.feedrate[travels].max())
        self.position = rows.end[-1].copy()
        self.last_e = float(rows.e_end[-1])
        out.append(rows)
        return out


__all__ = ["CHUNK_FIELDS", "Gap", "empty_chunk", "shift_e", "travel"]
