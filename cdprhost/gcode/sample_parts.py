"""Small synthetic G-code programs: a known print for the tests and the benchmarks that run on
the embedded simulated device (no fixture needed)."""

from __future__ import annotations


def square_walls(layers: int, side: float = 30.0, loops: int = 3) -> str:
    """Home, heat the hotend to 200 C, then ``layers`` layers 0.3 mm apart, each ``loops``
    times round a ``side`` mm square from the origin (1 mm of filament an edge, F1800), ending
    with a 1 mm retraction and its undo."""
    lines = ["G28", "M104 S200", "M109 S200", "G92 E0"]
    e = 0.0
    corners = [(side, 0.0), (side, side), (0.0, side), (0.0, 0.0)]
    for n in range(layers):
        lines.append(f"G1 Z{0.3 * (n + 1):.2f} F3000")
        for x, y in corners * loops:
            e += 1.0
            lines.append(f"G1 X{x:g} Y{y:g} E{e:.3f} F1800")
        lines += [f"G1 E{e - 1:.3f} F2400", f"G1 E{e:.3f}"]
    return "\n".join(lines) + "\n"
