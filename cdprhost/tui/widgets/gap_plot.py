"""Held-out error per pose before and after adding the named effect, with the noise floor."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from rich.text import Text
from textual.widget import Widget

from cdprhost.tui.widgets.charts import BLOCKS

BEFORE, AFTER, FLOOR = "red", "green", "bold cyan"


def gap_cells(
    before: Sequence[float], after: Sequence[float], floor: float, width: int, height: int
) -> tuple[list[list[tuple[str, str]]], float, int | None]:
    """Rows (top first) of (char, style) cells, one column per pose; the top of the
    scale (mm); the index (top first) of the row holding the noise floor.

    The lower (green) part of a column is the error after, the red part above it
    the error before; a dotted line marks the noise floor where no bar covers it.
    """
    b = np.asarray(before, dtype=float)
    a = np.asarray(after, dtype=float) if len(after) else np.zeros_like(b)
    n = min(b.size, width)
    if n == 0:
        return [], 0.0, None
    take = np.floor(np.arange(n) * b.size / n).astype(int)
    b, a = b[take], a[take]
    top = float(max(b.max(), a.max(), floor) * 1.1) or 1.0
    eb = np.rint(b / top * height * 8).astype(int)
    ea = np.rint(a / top * height * 8).astype(int)
    floor_row = min(int(floor / top * height), height - 1) if floor > 0 else None
    rows = []
    for r in range(height - 1, -1, -1):
        cells = []
        for j in range(n):
            lb, la = int(np.clip(eb[j] - 8 * r, 0, 8)), int(np.clip(ea[j] - 8 * r, 0, 8))
            if la > 0:
                cells.append((BLOCKS[la], AFTER))
            elif lb > 0:
                cells.append((BLOCKS[lb], BEFORE))
            elif r == floor_row:
                cells.append(("┈", FLOOR))
            else:
                cells.append((" ", ""))
        rows.append(cells)
    return rows, top, None if floor_row is None else height - 1 - floor_row


class GapPlot(Widget):
    def __init__(self, *, id: str | None = None, classes: str | None = None):
        super().__init__(id=id, classes=classes)
        self._data: tuple[tuple[float, ...], tuple[float, ...], float] = ((), (), 0.0)

    def show(self, before: Sequence[float], after: Sequence[float], floor: float) -> None:
        self._data = (tuple(before), tuple(after), float(floor))
        self.refresh()

    def render(self) -> Text:
        before, after, floor = self._data
        out = Text(no_wrap=True, overflow="crop")
        if not before:
            return out.append("held-out error per pose: run a diagnosis", style="dim")
        rows, top, floor_at = gap_cells(
            before, after, floor, max(self.size.width - 8, 4), max(self.size.height - 1, 1)
        )
        for i, cells in enumerate(rows):
            if i == floor_at:
                out.append(f"{floor:6.3f}┈", style=FLOOR)
            else:
                out.append(f"{top * (len(rows) - i) / len(rows):6.3f} ", style="dim")
            for ch, style in cells:
                out.append(ch, style=style)
            out.append("\n")
        out.append("       ")
        out.append("█ before", style=BEFORE)
        out.append("  █ after", style=AFTER)
        out.append(f"  ┈ noise floor {floor:.3f} mm  (held-out, per pose, mm)", style=FLOOR)
        return out
