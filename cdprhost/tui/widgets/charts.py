"""Text charts drawn with block characters (pure functions, no widget state)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

BLOCKS = " ▁▂▃▄▅▆▇█"
HBLOCKS = " ▏▎▍▌▋▊▉█"


def latest(values: Sequence[float], width: int) -> np.ndarray:
    """The last ``width`` values (fewer when there are fewer)."""
    v = np.asarray(values, dtype=float)
    return v[-width:] if width > 0 else v[:0]


def block_chart(
    values: Sequence[float],
    width: int,
    height: int,
    lo: float,
    hi: float,
    marker: float | None = None,
) -> list[str]:
    """Rows (top first) of a column chart of the last ``width`` values scaled to
    [lo, hi], right-aligned (the newest value in the last column).

    Each row resolves eight levels; ``marker`` draws a dotted line at that level
    in the empty cells (a target temperature, a limit).
    """
    cols = latest(values, width)
    height = max(height, 1)
    span = hi - lo if hi > lo else 1.0
    eighths = np.clip(np.rint((cols - lo) / span * height * 8), 0, height * 8).astype(int)
    mark_row = None
    if marker is not None and lo <= marker <= hi:
        mark_row = min(int((marker - lo) / span * height), height - 1)
    rows = []
    for r in range(height - 1, -1, -1):  # top row first
        level = np.clip(eighths - r * 8, 0, 8)
        chars = [BLOCKS[k] for k in level]
        if r == mark_row:
            chars = ["┈" if c == " " else c for c in chars]
        rows.append("".join(chars).rjust(width, "┈" if r == mark_row else " "))
    return rows


def hbar(value: float, hi: float, width: int) -> str:
    """A horizontal bar of ``width`` cells filled to value/hi, eighth-cell resolution."""
    if width <= 0:
        return ""
    frac = 0.0 if hi <= 0 else min(max(value / hi, 0.0), 1.0)
    eighths = int(round(frac * width * 8))
    full, part = divmod(eighths, 8)
    text = "█" * full + (HBLOCKS[part] if part and full < width else "")
    return text.ljust(width)


def tension_level(value: float, t_min: float, t_max: float) -> str:
    """ "bad" outside [t_min, t_max]; "near" within 2 % of the span above t_min
    (close to slack) or 10 % below t_max; else "ok"."""
    if not np.isfinite(value) or value < t_min or value > t_max:
        return "bad"
    span = t_max - t_min
    if value < t_min + 0.02 * span or value > t_max - 0.1 * span:
        return "near"
    return "ok"
