"""Write small G-code programs for preflight tests."""

from __future__ import annotations

from pathlib import Path

START = [
    "M104 S200",
    "M140 S60",
    "G28",
    "M109 S200",
    "G90",
    "M82",
    "G92 E0",
]


def write_program(
    tmp_path: Path, body: list[str], *, start: list[str] | None = None, name: str = "part.gcode"
) -> Path:
    lines = (START if start is None else start) + body
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def line_of(path: Path, text: str) -> int:
    """1-based number of the first line equal to ``text``."""
    for i, line in enumerate(path.read_text().splitlines(), start=1):
        if line == text:
            return i
    raise ValueError(text)


def square_body(
    z: float = 0.3, half: float = 20.0, e_per_mm: float = 0.033, feed: float = 1800.0
) -> list[str]:
    """A printed square at height z (G-code frame), absolute E."""
    pts = [(-half, -half), (half, -half), (half, half), (-half, half), (-half, -half)]
    out = [f"G1 Z{z} F600", f"G1 X{pts[0][0]} Y{pts[0][1]} F6000"]
    e = 0.0
    for (x0, y0), (x1, y1) in zip(pts[:-1], pts[1:]):
        e += e_per_mm * (abs(x1 - x0) + abs(y1 - y0))
        out.append(f"G1 X{x1} Y{y1} E{e:.5f} F{feed}")
    return out
