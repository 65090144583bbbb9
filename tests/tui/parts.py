"""Small G-code programs for the UI tests."""

from __future__ import annotations


def small_part(layers: int = 10, side: float = 30.0) -> str:
    """A square tube of 0.2 mm layers with slicer layer annotations; each layer ends with a
    retraction, so the motion comes to rest there (where a pause takes effect)."""
    out = [
        "; generated for the UI tests",
        "G21",
        "G90",
        "M82",
        "M140 S60",
        "M104 S200",
        "G28",
        "G92 E0",
    ]
    e, h = 0.0, side / 2
    corners = [(-h, -h), (h, -h), (h, h), (-h, h), (-h, -h)]
    for k in range(layers):
        z = 0.3 + 0.2 * k
        out += [
            ";LAYER_CHANGE",
            f";Z:{z:.1f}",
            f"G1 Z{z:.2f} F600",
            f"G1 X{-h:.2f} Y{-h:.2f} F6000",
            f"G1 E{e:.4f} F2400",
        ]
        for x, y in corners[1:]:
            e += side * 0.033
            out.append(f"G1 X{x:.2f} Y{y:.2f} E{e:.4f} F1800")
        out.append(f"G1 E{e - 0.8:.4f} F2400")
    out += ["M104 S0", "M140 S0", "G1 Z20 F600"]
    return "\n".join(out) + "\n"
