"""One layer of the job's toolpath for the web page's layer view.

:func:`gather` reads a program's items once and keeps, per move, its start and end in the
plane (the G-code frame), its line, its layer and whether it extrudes; :func:`layer_doc` cuts
one layer out as a compact JSON document: coordinates as integers in units of 1/``SCALE`` mm,
the line of each move (the page colours the moves at or before the device's line as
printed), the layer's height, and the box of the whole part (so the view does not jump as the
layers change). Both are pure; :class:`LayerCache` keeps the last file read.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cdprhost.gcode.items import MoveChunk, MoveKind

SCALE = 20  # coordinates sent as integers of 1/20 mm
MAX_MOVES = 5_000  # a layer with more extrusions is thinned (every n-th kept): <= ~150 kB


@dataclass(frozen=True)
class Moves:
    xy0: np.ndarray  # (n, 2) float32
    xy1: np.ndarray  # (n, 2) float32
    line: np.ndarray  # (n,) int64
    layer: np.ndarray  # (n,) int32
    extrude: np.ndarray  # (n,) bool
    z: np.ndarray  # (n,) float32, end height

    @property
    def layers(self) -> int:
        return int(self.layer.max()) + 1 if len(self.layer) else 0


def gather(items: Iterable[Any]) -> Moves:
    chunks: list[tuple[np.ndarray, ...]] = []
    for item in items:
        if isinstance(item, MoveChunk) and len(item.line):
            chunks.append(
                (
                    item.start[:, :2].astype(np.float32),
                    item.end[:, :2].astype(np.float32),
                    item.line.astype(np.int64),
                    item.layer.astype(np.int32),
                    np.asarray(item.kind == int(MoveKind.EXTRUDE), dtype=bool),
                    item.end[:, 2].astype(np.float32),
                )
            )
    if not chunks:
        e2 = np.zeros((0, 2), np.float32)
        return Moves(e2, e2, np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros(0, bool),
                     np.zeros(0, np.float32))  # fmt: skip
    xy0, xy1, line, layer, extrude, z = (np.concatenate(c) for c in zip(*chunks, strict=True))
    return Moves(xy0, xy1, line, layer, extrude, z)


def part_box(moves: Moves) -> list[float]:
    """[x min, y min, x max, y max] of the extrusions (of every move when none extrudes)."""
    sel = moves.extrude if moves.extrude.any() else np.ones(len(moves.line), bool)
    if not sel.any():
        return [-1.0, -1.0, 1.0, 1.0]
    lo = np.minimum(moves.xy0[sel].min(axis=0), moves.xy1[sel].min(axis=0))
    hi = np.maximum(moves.xy0[sel].max(axis=0), moves.xy1[sel].max(axis=0))
    return [round(float(v), 2) for v in (lo[0], lo[1], hi[0], hi[1])]


def layer_doc(moves: Moves, layer: int, box: list[float] | None = None) -> dict[str, Any]:
    """Layer ``layer`` (0-based, clamped to the file's) as the page draws it."""
    layers = moves.layers
    k = min(max(int(layer), 0), max(layers - 1, 0))
    sel = (moves.layer == k) & moves.extrude
    idx = np.flatnonzero(sel)
    if len(idx) > MAX_MOVES:
        idx = idx[:: -(-len(idx) // MAX_MOVES)]
    seg = np.concatenate((moves.xy0[idx], moves.xy1[idx]), axis=1)
    z = moves.z[idx]
    return {
        "layer": k,
        "layers": layers,
        "z": round(float(z.min()), 3) if len(z) else None,
        "scale": SCALE,
        "box": box if box is not None else part_box(moves),
        "xy": np.rint(seg * SCALE).astype(np.int64).ravel().tolist(),
        "line": moves.line[idx].tolist(),
    }


class LayerCache:
    """The moves of the last file asked for, read again when the file (or its mtime) changes."""

    def __init__(self, read_items: Callable[[Path], Iterable[Any]]):
        self._read = read_items
        self._key: tuple[str, int, int] | None = None
        self._moves: Moves | None = None
        self._box: list[float] = []
        self._lock = threading.Lock()

    def layer(self, path: Path, layer: int) -> dict[str, Any]:
        """Blocking (the first time per file: one read of the program)."""
        st = path.stat()
        key = (str(path), st.st_mtime_ns, st.st_size)
        with self._lock:
            if self._key != key or self._moves is None:
                self._moves = gather(self._read(path))
                self._box = part_box(self._moves)
                self._key = key
            return layer_doc(self._moves, layer, self._box)
