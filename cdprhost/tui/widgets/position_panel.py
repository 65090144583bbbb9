"""Effector position, slider displacements and motor steps."""

from __future__ import annotations

from collections.abc import Sequence

from rich.text import Text
from textual.widgets import Static

Vec3 = tuple[float, float, float]


def position_rows(position: Vec3 | None, sliders: Vec3 | None, steps: Sequence[int] | None) -> Text:
    """Three aligned rows: effector x y z, sliders s1 s2 s3, steps n1 n2 n3 (e)."""
    rows = []
    for label, values, fmt, unit in (
        ("xyz", position, "8.2f", " mm"),
        ("sliders", sliders, "8.3f", " mm"),
        ("steps", None if steps is None else steps[:3], "8d", ""),
    ):
        row = Text(f"{label:<8}", style="bold")
        if values is None:
            row.append("      --", style="dim")
        else:
            row.append("".join(format(v, fmt) for v in values))
            row.append(unit, style="dim")
        if label == "steps" and steps is not None and len(steps) > 3:
            row.append(f" e {steps[3]}", style="dim")
        rows.append(row)
    return Text("\n").join(rows)


class PositionPanel(Static):
    def show(
        self, position: Vec3 | None, sliders: Vec3 | None, steps: Sequence[int] | None = None
    ) -> None:
        self.update(position_rows(position, sliders, steps))
