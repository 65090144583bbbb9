"""Linear moves in the machine frame: the planner's input records.

A :class:`MoveBlock` holds a run of consecutive moves as arrays. It is built from
the reader's ``MoveChunk`` (G-code frame) by adding the profile's ``bed_origin``.
Every later stage keeps the source ``line`` and ``layer`` so an error can name them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

#: moves shorter than this (mm of path, Cartesian or filament) are no-ops
MIN_MOVE_MM = 1e-6


@dataclass(frozen=True)
class MoveBlock:
    """Consecutive linear moves; the machine frame, mm, absolute positions."""

    start: np.ndarray  # (n, 3) float64
    end: np.ndarray  # (n, 3) float64
    e_start: np.ndarray  # (n,) filament position, mm
    e_end: np.ndarray  # (n,)
    feedrate: np.ndarray  # (n,) mm/s requested
    line: np.ndarray  # (n,) int64, 1-based source line
    layer: np.ndarray  # (n,) int32
    # limits the program asks for (M201/M204/M205), below the profile's; None: none
    accel_limit: np.ndarray | None = None  # (n,) mm/s^2
    junction_limit: np.ndarray | None = None  # (n,) junction deviation, mm

    def __len__(self) -> int:
        return int(self.line.shape[0])

    @property
    def delta(self) -> np.ndarray:
        return self.end - self.start

    @property
    def distance(self) -> np.ndarray:
        """Cartesian length of every move (mm)."""
        d = self.delta
        return np.sqrt(np.einsum("ij,ij->i", d, d))

    @property
    def extrusion(self) -> np.ndarray:
        return self.e_end - self.e_start

    def take(self, index: Any) -> MoveBlock:
        """Rows selected by a slice, a boolean mask or an index array."""
        return MoveBlock(
            self.start[index],
            self.end[index],
            self.e_start[index],
            self.e_end[index],
            self.feedrate[index],
            self.line[index],
            self.layer[index],
            None if self.accel_limit is None else self.accel_limit[index],
            None if self.junction_limit is None else self.junction_limit[index],
        )

    @classmethod
    def empty(cls) -> MoveBlock:
        z3, z = np.zeros((0, 3)), np.zeros(0)
        return cls(z3, z3, z, z, z, np.zeros(0, np.int64), np.zeros(0, np.int32))

    @classmethod
    def concat(cls, blocks: list[MoveBlock]) -> MoveBlock:
        blocks = [b for b in blocks if len(b)]
        if not blocks:
            return cls.empty()
        if len(blocks) == 1:
            return blocks[0]
        fields = [np.concatenate([getattr(b, f) for b in blocks]) for f in _FIELDS]
        limits = [
            np.concatenate([_limit(b, f) for b in blocks])
            if any(getattr(b, f) is not None for b in blocks)
            else None
            for f in _LIMIT_FIELDS
        ]
        return cls(*fields, *limits)

    @classmethod
    def from_arrays(
        cls,
        start: Any,
        end: Any,
        e_start: Any = None,
        e_end: Any = None,
        feedrate: Any = 50.0,
        line: Any = None,
        layer: Any = 0,
    ) -> MoveBlock:
        """Convenience constructor (tests, tools): broadcasts scalars."""
        s = np.atleast_2d(np.asarray(start, dtype=float))
        e = np.atleast_2d(np.asarray(end, dtype=float))
        n = s.shape[0]
        es = (
            np.zeros(n)
            if e_start is None
            else np.broadcast_to(np.asarray(e_start, float), (n,)).copy()
        )
        ee = es.copy() if e_end is None else np.broadcast_to(np.asarray(e_end, float), (n,)).copy()
        ln = (
            np.arange(1, n + 1, dtype=np.int64)
            if line is None
            else np.broadcast_to(np.asarray(line, np.int64), (n,)).copy()
        )
        return cls(
            s,
            e,
            es,
            ee,
            np.broadcast_to(np.asarray(feedrate, float), (n,)).copy(),
            ln,
            np.broadcast_to(np.asarray(layer, np.int32), (n,)).copy(),
        )


_FIELDS = ("start", "end", "e_start", "e_end", "feedrate", "line", "layer")
_LIMIT_FIELDS = ("accel_limit", "junction_limit")


def _limit(block: MoveBlock, name: str) -> np.ndarray:
    v = getattr(block, name)
    return np.full(len(block), np.inf) if v is None else v


def block_from_chunk(chunk: Any, bed_origin: np.ndarray) -> MoveBlock:
    """The reader's ``MoveChunk`` (G-code frame) -> a machine-frame :class:`MoveBlock`."""
    origin = np.asarray(bed_origin, dtype=float)
    return MoveBlock(
        np.asarray(chunk.start, dtype=float) + origin,
        np.asarray(chunk.end, dtype=float) + origin,
        np.asarray(chunk.e_start, dtype=float),
        np.asarray(chunk.e_end, dtype=float),
        np.asarray(chunk.feedrate, dtype=float),
        np.asarray(chunk.line, dtype=np.int64),
        np.asarray(chunk.layer, dtype=np.int32),
    )


def chain_from(block: MoveBlock, position: np.ndarray) -> MoveBlock:
    """The block with each move starting where the previous one ended.

    The first move starts at ``position`` (the machine's current point, e.g. the
    home point after G28), so the path is continuous whatever the reader assumed.
    """
    if not len(block):
        return block
    start = np.empty_like(block.end)
    start[0] = position
    start[1:] = block.end[:-1]
    return MoveBlock(
        start,
        block.end,
        block.e_start,
        block.e_end,
        block.feedrate,
        block.line,
        block.layer,
        block.accel_limit,
        block.junction_limit,
    )


def drop_noops(block: MoveBlock) -> MoveBlock:
    """Moves that go nowhere (neither the effector nor the filament) removed."""
    keep = (block.distance > MIN_MOVE_MM) | (np.abs(block.extrusion) > MIN_MOVE_MM)
    return block if keep.all() else block.take(keep)
