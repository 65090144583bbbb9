"""Purge lines of a printer's start G-code that no slicer marker sets apart (pure but
for one short scan of the file for extruder resets).

Many start G-codes draw a line or two at the edge of the bed to prime the nozzle (the
Ender-3's: X0.1 and X0.4 from Y20 to Y200) and then reset the extruder (``G92 E0``).
When the file has no layer markers, or the start block sits after the first one, those
lines look like the part's first layer, so the part seems as large as the bed.

An *epoch* is what lies between two extruder resets. The purge is the longest run of
leading epochs (each ended by a reset, all on the part's first layer or below it) whose
boxes each lie to one side of the box of the part's first layer that follows them, at
least ``MARGIN_MM`` apart (a skirt, around the part, is not a purge). `PurgeFinder` keeps the extruding moves of the first epochs while the
program is read, and decides at the end.
"""

from __future__ import annotations

import mmap
import os
import re
from dataclasses import dataclass, field

import numpy as np

from cdprhost.gcode.items import CHUNK_FIELDS, MoveChunk, MoveKind

#: a purge lies at least this far outside the box of the part's first layer (mm)
MARGIN_MM = 5.0
#: resets looked for (a file that resets at every layer has them all in its first layers)
MAX_RESETS = 32
#: layers above the first extruding one whose moves may still be a purge or its reference
_LAYERS = 2


@dataclass(frozen=True)
class PurgeRun:
    """One recognised purge move."""

    line: int
    start_xy: tuple[float, float]
    end_xy: tuple[float, float]
    filament_mm: float

    def text(self) -> str:
        (x0, y0), (x1, y1) = self.start_xy, self.end_xy
        return f"line {self.line}: X{x0:g} Y{y0:g} -> X{x1:g} Y{y1:g}, {self.filament_mm:g} mm"


_RESET = re.compile(rb"^[ \t]*G92(?:\.0)?[ \t][^;\n]*?E", re.M | re.I)


def scan_resets(path: str, limit: int = MAX_RESETS) -> np.ndarray:
    """Line numbers of the first ``limit`` extruder resets (``G92`` with an E word)."""
    found: list[int] = []
    with open(path, "rb") as fh:
        if os.fstat(fh.fileno()).st_size == 0:
            return np.zeros(0, dtype=np.int64)
        with mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as text:
            line, pos = 1, 0
            for m in _RESET.finditer(text):
                line += text[pos : m.start()].count(b"\n")
                pos = m.start()
                found.append(line)
                if len(found) >= limit:
                    break
    return np.asarray(found, dtype=np.int64)


@dataclass
class PurgeFinder:
    """Collects the candidate moves: extruding, from the first layer on, at most
    ``_LAYERS`` above the first extruding layer."""

    resets: np.ndarray
    chunks: list[MoveChunk] = field(default_factory=list)
    travels: list[np.ndarray] = field(default_factory=list)  # lines of X/Y travels
    first_layer: int | None = None

    def take(self, chunk: MoveChunk) -> MoveChunk:
        """Keep the candidates of ``chunk``; return the rest of its part moves."""
        part = (chunk.kind == MoveKind.EXTRUDE) & (chunk.layer >= 0)
        if not len(self.resets):
            return chunk.take(part)
        if self.first_layer is None or int(chunk.layer[0]) <= self.first_layer + _LAYERS:
            self.travels.append(chunk.line[chunk.kind == MoveKind.TRAVEL])
        if not part.any():
            return chunk.take(part)
        if self.first_layer is None:
            self.first_layer = int(chunk.layer[part][0])
        candidate = part & (chunk.layer <= self.first_layer + _LAYERS)
        if candidate.any():
            self.chunks.append(chunk.take(candidate))
        return chunk.take(part & ~candidate)

    def decide(self) -> tuple[int, tuple[PurgeRun, ...], list[MoveChunk]]:
        """(the last line of the start block with the purge or 0, the purge's moves, the
        candidates that are part). The start block ends at the reset after the purge, or
        later: just before the travel to the part's first extrusion."""
        if not self.chunks:
            return 0, (), []
        moves = MoveChunk(
            *(np.concatenate([getattr(c, f) for c in self.chunks]) for f in CHUNK_FIELDS)
        )
        epoch = np.searchsorted(self.resets, moves.line)
        epochs = np.unique(epoch)
        for k in range(len(epochs) - 1, 0, -1):  # the longest prefix that is a purge
            if _is_purge(moves, epoch, epochs[k]):
                purge = epoch < epochs[k]
                runs = tuple(
                    PurgeRun(
                        int(moves.line[i]),
                        (float(moves.start[i, 0]), float(moves.start[i, 1])),
                        (float(moves.end[i, 0]), float(moves.end[i, 1])),
                        round(float(moves.de[i]), 3),
                    )
                    for i in np.flatnonzero(purge)
                )
                end = int(self.resets[int(epochs[k - 1])])
                first_part = int(moves.line[~purge].min())
                travels = np.concatenate(self.travels)
                travels = travels[(travels > end) & (travels < first_part)]
                if travels.size:
                    end = max(end, int(travels.max()) - 1)
                return end, runs, [moves.take(~purge)]
        return 0, (), [moves]


def _is_purge(moves: MoveChunk, epoch: np.ndarray, first_kept: int) -> bool:
    """Does each epoch before ``first_kept`` lie to one side of the first layer after
    them (boxes apart by ``MARGIN_MM``; a skirt around the part surrounds it instead)?"""
    before = epoch < first_kept
    after = ~before
    layer = int(moves.layer[after][0])
    if int(moves.layer[before].max()) > layer:
        return False  # a purge comes before the part's first layer, not above it
    lo, hi = _box(moves, after & (moves.layer == layer))
    for e in np.unique(epoch[before]):
        e_lo, e_hi = _box(moves, epoch == e)
        if not ((e_hi < lo - MARGIN_MM) | (e_lo > hi + MARGIN_MM)).any():
            return False
    return True


def _box(moves: MoveChunk, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pts = np.concatenate([moves.start[rows, :2], moves.end[rows, :2]])
    return pts.min(axis=0), pts.max(axis=0)
