"""Where the printed part is, and the shift that puts it somewhere else (pure).

`PartExtent` collects the extruding moves from the first layer on (the part, not
the purge lines of a start block): their bounding box and an outline, the convex
hull approximated from outside by ``DIRECTIONS`` support lines (so it is cheap to
build chunk by chunk and never smaller than the part). `centre_offset` is the
X/Y shift that puts the part's box centre on a target point; `parse_offset`
reads ``--offset X,Y``. The TUI calls these too.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from cdprhost.errors import InputError
from cdprhost.gcode.items import MoveChunk, MoveKind, ProgramItem

DIRECTIONS = 64
_ANGLES = np.arange(DIRECTIONS) * (2 * np.pi / DIRECTIONS)
_UNIT = np.column_stack([np.cos(_ANGLES), np.sin(_ANGLES)])  # (k, 2)
#: largest shift accepted (mm): more is a typo, not a placement
MAX_OFFSET_MM = 10000.0


@dataclass
class PartExtent:
    """Extruding moves from the first layer on, in the G-code frame."""

    lo: np.ndarray = field(default_factory=lambda: np.full(3, np.inf))
    hi: np.ndarray = field(default_factory=lambda: np.full(3, -np.inf))
    support: np.ndarray = field(default_factory=lambda: np.full(DIRECTIONS, -np.inf))

    @property
    def empty(self) -> bool:
        return not np.isfinite(self.lo).all()

    def add(self, chunk: MoveChunk, lines: tuple[int, int] | None = None) -> None:
        """Add ``chunk``'s part moves (``lines``: only those within [first, last])."""
        keep = (chunk.kind == MoveKind.EXTRUDE) & (chunk.layer >= 0)
        if lines is not None:
            keep &= (chunk.line >= lines[0]) & (chunk.line <= lines[1])
        if not keep.any():
            return
        pts = np.concatenate([chunk.start[keep], chunk.end[keep]])
        self.lo = np.minimum(self.lo, pts.min(axis=0))
        self.hi = np.maximum(self.hi, pts.max(axis=0))
        self.support = np.maximum(self.support, (pts[:, :2] @ _UNIT.T).max(axis=0))

    @classmethod
    def of(cls, items: Iterable[ProgramItem]) -> PartExtent:
        ext = cls()
        for item in items:
            match item:
                case MoveChunk():
                    ext.add(item)
                case _:
                    pass
        return ext

    @property
    def centre_xy(self) -> tuple[float, float]:
        return (float(self.lo[0] + self.hi[0]) / 2, float(self.lo[1] + self.hi[1]) / 2)

    def outline(self, spacing_mm: float = 1.0, max_points: int = 4096) -> np.ndarray:
        """Points (m, 2) along the outline polygon, at most ``spacing_mm`` apart (or
        ``max_points`` in all, for a part too large for any machine)."""
        if self.empty:
            return np.zeros((0, 2))
        # vertices: intersections of consecutive support lines u_k . p = h_k
        u0, u1 = _UNIT, np.roll(_UNIT, -1, axis=0)
        h0, h1 = self.support, np.roll(self.support, -1)
        det = u0[:, 0] * u1[:, 1] - u0[:, 1] * u1[:, 0]
        vx = (h0 * u1[:, 1] - h1 * u0[:, 1]) / det
        vy = (u0[:, 0] * h1 - u1[:, 0] * h0) / det
        verts = np.column_stack([vx, vy])
        nxt = np.roll(verts, -1, axis=0)
        lengths = np.linalg.norm(nxt - verts, axis=1)
        spacing_mm = max(spacing_mm, float(lengths.sum()) / max_points)
        counts = np.maximum(np.ceil(lengths / spacing_mm).astype(int), 1)
        owner = np.repeat(np.arange(len(verts)), counts)
        t = (np.arange(owner.size) - np.repeat(np.cumsum(counts) - counts, counts)) / counts[owner]
        return verts[owner] + t[:, None] * (nxt - verts)[owner]


def centre_offset(extent: PartExtent, target_xy: tuple[float, float]) -> tuple[float, float]:
    """The X/Y shift that puts the part's box centre on ``target_xy``."""
    cx, cy = extent.centre_xy
    return (target_xy[0] - cx, target_xy[1] - cy)


def parse_offset(text: str, option: str = "--offset") -> tuple[float, float]:
    """``"X,Y"`` in mm -> (x, y); a clear `InputError` naming ``option`` otherwise."""
    parts = text.replace(" ", "").split(",")
    if len(parts) != 2:
        raise InputError(f"{option} {text!r}: expected X,Y in mm (e.g. {option} 10,-5)")
    try:
        x, y = (float(p) for p in parts)
    except ValueError:
        raise InputError(f"{option} {text!r}: X and Y must be numbers (mm)") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise InputError(f"{option} {text!r}: X and Y must be finite")
    if max(abs(x), abs(y)) > MAX_OFFSET_MM:
        raise InputError(
            f"{option} {text!r}: a shift beyond {MAX_OFFSET_MM:g} mm is not a placement"
        )
    return (x, y)
