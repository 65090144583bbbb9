"""One layer of the open file seen from above: planned path, the part already printed, and
the nozzle, drawn in braille dots (no graphics protocol needed)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from rich.text import Text
from textual.geometry import Region
from textual.strip import Strip
from textual.timer import Timer
from textual.widget import Widget

from cdprhost.tui.control.views import Toolpath
from cdprhost.tui.widgets.braille import BRAILLE_BLANK, DotFrame, cell_bits, draw_segments, fit

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


@dataclass
class LayerDots:
    """One layer's dots kept between drawings: planned, and printed up to ``done_line`` (while
    a print advances, only the moves printed since the last drawing are added)."""

    key: tuple[object, ...] = ()
    planned: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=bool))
    printed: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=bool))
    done_line: int = -1


def layer_cells(
    toolpath: Toolpath,
    layer: int,
    done_line: int,
    frame: DotFrame,
    dots: LayerDots | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(bits, printed) per cell: the braille bits of the layer's extrusions, and whether any
    printed extrusion crosses the cell; ``dots`` carries the work over between calls."""
    dots = LayerDots() if dots is None else dots
    key = (id(toolpath), layer, frame)
    sel = (toolpath.layer == layer) & toolpath.extrude
    if dots.key != key or done_line < dots.done_line:  # another layer, or a new job
        if dots.key != key:
            dots.planned = draw_segments(frame, toolpath.xy0[sel], toolpath.xy1[sel])
        dots.key, dots.done_line = key, -1
        dots.printed = np.zeros_like(dots.planned)
    new = sel & (toolpath.line <= done_line) & (toolpath.line > dots.done_line)
    if new.any():
        dots.printed = dots.printed | draw_segments(frame, toolpath.xy0[new], toolpath.xy1[new])
    dots.done_line = done_line
    return cell_bits(dots.planned | dots.printed), cell_bits(dots.printed) > 0


def row_chars(bits: np.ndarray) -> str:
    """One row of braille bit masks as text (vectorised)."""
    return (BRAILLE_BLANK + bits.astype(np.uint32)).astype("<u4").tobytes().decode("utf-32-le")


def preview_text(data: PreviewInput, cols: int, rows: int, dots: LayerDots | None = None) -> Text:
    """The drawing as styled text: a title row, then ``rows - 1`` rows of ``cols`` cells.
    ``dots``: see :func:`layer_cells`."""
    out = Text(no_wrap=True, overflow="crop")
    tp = data.toolpath
    if tp is None or tp.layers == 0:
        return out.append("layer preview: open a G-code file", style="dim")
    layer = min(max(data.layer, 0), tp.layers - 1)
    out.append(f"layer {layer + 1}/{tp.layers}", style="bold")
    # the legend in whole words, long ones where they fit, as much of it as fits
    z = f" z {tp.layer_z[layer]:.2f}"
    for words in ((" planned", " printed", " nozzle"), (" plan", " done", " nozzle")):
        if out.cell_len + sum(2 + len(w) for w in words) <= cols:
            break
    marks = ((" ⣿", PLANNED), (" ⣿", PRINTED), (f" {NOZZLE_MARK}", NOZZLE))
    items = [(m, st, w, "dim") for (m, st), w in zip(marks, words)]
    items.append(("", "", z, "dim"))
    if data.title:
        items.append(("  ", "", data.title, "italic"))
    for mark, style, word, word_style in items:
        if out.cell_len + len(mark) + len(word) > cols:
            break
        out.append(mark, style=style)
        out.append(word, style=word_style)
    body_rows = rows - 1
    if body_rows < 1 or cols < 2:
        return out
    frame = fit(tp.bounds(), cols, body_rows)
    bits, printed = layer_cells(tp, layer, data.done_line, frame, dots)
    kinds = np.where(bits > 0, np.where(printed, 2, 1), 0)
    nozzle = frame.to_cell(*data.nozzle) if data.nozzle is not None else None
    for r in range(body_rows):
        out.append("\n")
        text, row_kind = row_chars(bits[r]), kinds[r]
        cuts = np.flatnonzero(np.diff(row_kind)) + 1
        starts = np.concatenate(([0], cuts))
        ends = np.concatenate((cuts, [len(row_kind)]))
        for a, b in zip(starts.tolist(), ends.tolist()):
            chars = text[a:b]
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
    """Shows :func:`preview_text` for the last :meth:`show` input, line by line: only the
    rows that changed are drawn again (the nozzle moving redraws a row or two).

    While a print advances on the same layer, it is drawn at most every ``FOLLOW_S`` seconds
    (the last input is drawn when that time is up); another layer, file or title shows at
    once. Drawing the preview is most of what the UI costs while it prints."""

    FOLLOW_S = 2.0

    def __init__(self, *, id: str | None = None, classes: str | None = None):
        super().__init__(id=id, classes=classes)
        self._input = PreviewInput(None, 0, 0, None)
        self._drawn_at = float("-inf")
        self._deferred: Timer | None = None
        self._dots = LayerDots()
        self._lines: list[Strip] = []
        self._texts: list[Text] = []
        self._drawn_for: tuple[int, int] = (0, 0)

    @property
    def shown(self) -> PreviewInput:
        return self._input

    def show(self, data: PreviewInput) -> None:
        if data == self._input:
            return
        old, self._input = self._input, data
        follows = (data.toolpath, data.layer, data.title) == (old.toolpath, old.layer, old.title)
        wait = self._drawn_at + self.FOLLOW_S - time.monotonic()
        if follows and wait > 0:  # the same layer, drawn a moment ago: draw the latest later
            if self._deferred is None:
                self._deferred = self.set_timer(wait, self._draw_deferred)
            return
        self._redraw()

    def _draw_deferred(self) -> None:
        self._deferred = None
        self._redraw()

    def on_resize(self) -> None:
        self._redraw(full=True)

    def on_show(self) -> None:
        self._redraw(full=True)

    def _redraw(self, full: bool = False) -> None:
        if self._deferred is not None:
            self._deferred.stop()
            self._deferred = None
        self._drawn_at = time.monotonic()
        w, h = self.content_size
        if w <= 0 or h <= 0 or not self.display:
            self._drawn_for = (0, 0)  # drawn in full when it shows again
            return
        texts = list(preview_text(self._input, w, h, self._dots).split("\n"))
        old = self._texts
        full = full or self._drawn_for != (w, h) or len(old) != len(texts)
        console = self.app.console
        changed = []
        lines = []
        for y, text in enumerate(texts):
            if not full and y < len(old) and old[y] == text:
                lines.append(self._lines[y])
                continue
            text.no_wrap, text.overflow = True, "crop"
            lines.append(Strip(list(text.render(console)), text.cell_len).crop_extend(0, w, None))
            changed.append(y)
        self._texts, self._lines, self._drawn_for = texts, lines, (w, h)
        if full:
            self.refresh()
        elif changed:
            top, left = self.gutter.top, self.gutter.left
            self.refresh(*(Region(left, top + y, w, 1) for y in changed))

    def render_line(self, y: int) -> Strip:
        if 0 <= y < len(self._lines):
            return self._lines[y]
        return Strip.blank(self.content_size.width)
