"""Small helpers for the G-code reader tests."""

from __future__ import annotations

import numpy as np

from cdprhost.gcode import MoveChunk, read_program


def read(text: str, **kw) -> list:
    """All items of G-code ``text`` (a string of lines)."""
    return list(read_program(text.splitlines(), **kw))


def commands(items: list) -> list:
    return [i for i in items if not isinstance(i, MoveChunk)]


def moves(items: list) -> dict[str, np.ndarray]:
    """All move chunks of ``items`` joined field by field."""
    chunks = [i for i in items if isinstance(i, MoveChunk)]
    fields = ("start", "end", "e_start", "e_end", "feedrate", "line", "layer", "kind", "rapid")
    if not chunks:
        return {f: np.empty((0, 3) if f in ("start", "end") else 0) for f in fields}
    return {f: np.concatenate([getattr(c, f) for c in chunks]) for f in fields}
