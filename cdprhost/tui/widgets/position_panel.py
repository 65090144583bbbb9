"""Effector position (machine frame and G-code frame), slider displacements, motor steps."""

from __future__ import annotations

from collections.abc import Sequence

from rich.text import Text
from textual.widgets import Static

from cdprhost.tui.control.views import unsigned_zero
from cdprhost.tui.widgets.show import show_text

Vec3 = tuple[float, float, float]


def _row(label: str, values: Sequence[float] | None, fmt: str, unit: str) -> Text:
    """A label and three columns; each value has a space before it so neighbours never touch
    (-100.000 next to -100.000)."""
    row = Text(f"{label:<8}", style="bold")
    if values is None:
        return row.append("       --", style="dim")
    if fmt.endswith("f"):  # no "-0.00"
        digits = int(fmt.rsplit(".", 1)[1][:-1])
        values = [unsigned_zero(v, digits) for v in values]
    row.append("".join(" " + format(v, fmt) for v in values))
    return row.append(unit, style="dim")


def position_rows(
    position: Vec3 | None,
    sliders: Vec3 | None,
    steps: Sequence[int] | None,
    bed_origin: Vec3 = (0.0, 0.0, 0.0),
) -> Text:
    """Four aligned rows: effector x y z in the machine frame and in the G-code (bed) frame,
    sliders s1 s2 s3, steps n1 n2 n3 (and e)."""
    gcode = None
    if position is not None:
        gcode = tuple(p - o for p, o in zip(position, bed_origin))
    rows = [
        _row("machine", position, "8.2f", " mm"),
        _row("G-code", gcode, "8.2f", " mm"),
        _row("sliders", sliders, "8.3f", " mm"),
        _row("steps", None if steps is None else steps[:3], "8d", ""),
    ]
    if steps is not None and len(steps) > 3:
        rows[-1].append(f" e {steps[3]}", style="dim")
    return Text("\n").join(rows)


class PositionPanel(Static):
    def __init__(
        self,
        bed_origin: Vec3 = (0.0, 0.0, 0.0),
        *,
        id: str | None = None,
        classes: str | None = None,
    ):
        super().__init__(id=id, classes=classes)
        self.bed_origin = bed_origin

    def show(
        self, position: Vec3 | None, sliders: Vec3 | None, steps: Sequence[int] | None = None
    ) -> None:
        show_text(self, position_rows(position, sliders, steps, self.bed_origin))
