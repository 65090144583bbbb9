"""One layer of the open file seen from above: planned path, the part already printed, and
the nozzle, drawn in braille dots (no graphics protocol needed)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from rich.text import Text
from textual.widget import Widget

from cdprhost.tui.control.views import Toolpath
from cdprhost.tui.widgets.braille import DotFrame, braille_char, cell_bits, draw_segments, fit

PLANNED, PRINTED, NOZZLE = "grey50", "bold green", "bold red"
NOZZLE_MARK = "◆"
_STYLE = ("", PLANNED, PRINTED)


@dataclass(frozen=True)
class PreviewInput:
    toolpath: Toolpath | None
    layer: int  # 0-based
    done_line: int  # moves at or before this line are printed (0: none)
    nozzle: tuple[float, float] | None  # G-code frame
    title: str = ""


def layer_cells(
    toolpath: Toolpath, layer: int, done_line: int, frame: DotFrame
) -> tuple[np.ndarray, np.ndarray]:
    """(bits, printed) per cell: the braille bits of the layer's extrusions, and whether any
    printed extrusion crosses the cell."""
    sel = (toolpath.layer == layer) & toolpath.extrude
    planned = draw_segments(frame, toolpath.xy0[sel], toolpath.xy1[sel])
    done = sel & (toolpath.line <= done_line)
    printed = draw_segments(frame, toolpath.xy0[done], toolpath.xy1[done])
    return cell_bits(planned | printed), cell_bits(printed) > 0


def preview_text(data: PreviewInput, cols: int, rows: int) -> Text:
    """The drawing as styled text: a title row, then ``rows - 1`` rows of ``cols`` cells."""
    out = Text(no_wrap=True, overflow="crop")
    tp = data.toolpath
    if tp is None or tp.layers == 0:
        return out.append("layer preview: open a G-code file", style="dim")
    layer = min(max(data.layer, 0), tp.layers - 1)
    out.append(f"layer {layer + 1}/{tp.layers}", style="bold")
    out.append(f" z {tp.layer_z[layer]:.2f}", style="dim")
    wide = cols >= 60
    for mark, style, word in ((" ⣿", PLANNED, "planned"), (" ⣿", PRINTED, "printed")):
        out.append(mark, style=style)
        out.append(f" {word}" if wide else word[:4], style="dim")
    out.append(f" {NOZZLE_MARK}", style=NOZZLE)
    out.append(" nozzle" if wide else "nozl", style="dim")
    if data.title:
        out.append(f"  {data.title}", style="italic")
    body_rows = rows - 1
    if body_rows < 1 or cols < 2:
        return out
    frame = fit(tp.bounds(), cols, body_rows)
    bits, printed = layer_cells(tp, layer, data.done_line, frame)
    kinds = np.where(bits > 0, np.where(printed, 2, 1), 0)
    nozzle = frame.to_cell(*data.nozzle) if data.nozzle is not None else None
    for r in range(body_rows):
        out.append("\n")
        row_bits, row_kind = bits[r], kinds[r]
        cuts = np.flatnonzero(np.diff(row_kind)) + 1
        starts = np.concatenate(([0], cuts))
        ends = np.concatenate((cuts, [len(row_kind)]))
        for a, b in zip(starts.tolist(), ends.tolist()):
            chars = "".join(braille_char(v) for v in row_bits[a:b])
            style = _STYLE[int(row_kind[a])]
            if nozzle is not None and nozzle[1] == r and a <= nozzle[0] < b:
                k = nozzle[0] - a
                out.append(chars[:k], style=style)
                out.append(NOZZLE_MARK, style=NOZZLE)
                out.append(chars[k + 1 :], style=style)
            else:
                out.append(chars, style=style)
    return out


class LayerPreview(Widget):
    """Shows :func:`preview_text` for the last :meth:`show` input; redraws only on change."""

    def __init__(self, *, id: str | None = None, classes: str | None = None):
        super().__init__(id=id, classes=classes)
        self._input = PreviewInput(None, 0, 0, None)
        self._cache: tuple[tuple[object, ...], Text] | None = None

    @property
    def shown(self) -> PreviewInput:
        return self._input

    def show(self, data: PreviewInput) -> None:
        if data != self._input:
            self._input = data
            self.refresh()

    def render(self) -> Text:
        d, (w, h) = self._input, self.size
        key = (id(d.toolpath), d.layer, d.done_line, d.nozzle, d.title, w, h)
        if self._cache is None or self._cache[0] != key:
            self._cache = (key, preview_text(d, w, h))
        return self._cache[1]
